// The pipeline stage that fuses: one orientation filter per sensor, fed each sample at the
// sensor's own rates (the magnetometer only when its reading is fresh) after the sensor's
// calibration, recording every sensor's orientation next to its raw samples. A sensor that is
// lost, whose data-ready line falls silent or whose chip resets has no orientation until it is
// back, and its filter starts again from the first sample after (docs/runtime.md, "Sensor
// lifecycle").
#pragma once

#include <functional>
#include <memory>
#include <optional>
#include <utility>
#include <vector>

#include "board/board.h"
#include "firmware/runtime/capture.h"
#include "firmware/runtime/record_sink.h"
#include "fusion/calibration/field_vote.h"
#include "fusion/calibration/online_hard_iron.h"
#include "fusion/calibration/sensor_calibration.h"
#include "fusion/orientation_filter.h"

namespace caphub::firmware {

// Where a sensor's heading comes from (docs/fusion.md, "No magnetometer calibration").
enum class MagMode {
    Calibrated,  // the calibration file corrects the magnetometer: magnetic heading
    Raw,         // no correction, but the raw field agreed with the suit's (fusion::FieldVote):
                 // magnetic heading
    Estimating,  // the field cannot be trusted yet (or any more): gyroscope-only heading while
                 // the online hard-iron estimate gathers turns
    Online,      // magnetic heading with the online hard-iron estimate subtracted
};
const char* toString(MagMode m);
// A short name for documents (the status JSON): "calibrated", "uncorrected", "gyro-only",
// "online-hard-iron".
const char* key(MagMode m);

class FusionStage final : public PipelineStage {
public:
    using Filter = fusion::OrientationFilter<fusion::FloatTypes>;

    // Per board sensor, the calibration applied to its samples before its filter (none: raw).
    using Calibrations = std::vector<std::optional<fusion::SensorCalibration>>;

    // records may be null (no recording); calibrations may be empty.
    FusionStage(const board::Board& board, RecordSink* records, Calibrations calibrations = {});

    void onSample(const SensorSample& s) override;
    void onEvent(const RuntimeEvent& e) override;

    // What a sensor's latest sample gave: its orientation (sensor -> ENU) and its calibrated
    // readings (sensor frame).
    struct Latest {
        Eigen::Quaternionf orientation = Eigen::Quaternionf::Identity();
        Eigen::Vector3f specificForceMps2 = Eigen::Vector3f::Zero();
        Eigen::Vector3f rateRadS = Eigen::Vector3f::Zero();
    };
    // A sensor's latest, or null when it has none (no sample yet, or none since it was lost).
    const Latest* latest(int sensor) const;
    std::uint64_t updates() const { return updates_; }
    // Gyroscope clipping episodes of a sensor so far (samples the driver flagged saturated).
    std::uint32_t clipEvents(int sensor) const;
    // How often a sensor's filter was reset because the sensor was lost, its data-ready line went
    // silent or its chip reset itself (once per outage).
    std::uint32_t resets(int sensor) const;
    // What a sensor's filter refused so far: samples not finite or beyond the chips' range, and
    // restarts from a non-finite state (docs/fusion.md, "Input validation"). Zero for no sensor.
    fusion::FilterRejections rejections(int sensor) const;
    // The body's acceleration (ENU, m/s^2) as the body solver tracks it, handed to every filter
    // as its sensor's known linear acceleration (fusion::OrientationFilter::updateAcc) until the
    // next call. Zero (the default): unknown.
    void setBodyAcceleration(const Eigen::Vector3d& enuMps2);
    // What the filters are told now (the latest setBodyAcceleration).
    Eigen::Vector3d bodyAcceleration() const {
        return Eigen::Vector3d(bodyAccEnu_.x, bodyAccEnu_.y, bodyAccEnu_.z);
    }
    // Offline only (`caphub reprocess --smooth`): the orientation each sample gets in place of
    // its filter's (given the sample and the filter's output), e.g. a smoother's over the whole
    // take. The filters still run (their lifecycle and counters stay the same). Empty: none.
    using OrientationOverride =
        std::function<Eigen::Quaternionf(const SensorSample&, const Eigen::Quaternionf&)>;
    void overrideOrientations(OrientationOverride fn) { override_ = std::move(fn); }

    // A sensor's heading source, and its online hard-iron estimate (invalid for a sensor whose
    // magnetometer the calibration file corrects, and for no sensor).
    MagMode magMode(int sensor) const;
    fusion::HardIronEstimate magEstimate(int sensor) const;
    // The estimator's sums, to start a later run from (setMagEstimatorState before the first
    // sample; false: no such sensor, a calibrated one, or a state with non-finite sums).
    std::optional<fusion::OnlineHardIronState> magEstimatorState(int sensor) const;
    bool setMagEstimatorState(int sensor, const fusion::OnlineHardIronState& state);

    // A sensor's heading is free: the gyroscope's alone (mode Estimating), steady but off north
    // by an angle of its own. False while orientations are overridden (they are not the
    // filter's).
    bool headingFree(int sensor) const;
    // Each time a free heading became magnetic (the online estimate turned good and the heading
    // error, averaged over alignReadings() undisturbed readings, was measured), the filter's
    // heading was turned by that error in one step: q_new = Rz(angleRad) q_old (ENU, about up).
    // The stages after this one take the count's change as their cue (BodyStage re-expresses
    // the body calibration). Not counted while orientations are overridden.
    struct HeadingStep {
        std::uint32_t count = 0;  // steps so far
        double angleRad = 0;      // the latest step
        Timestamp t{};            // the sample it was taken at
    };
    const HeadingStep& headingStep(int sensor) const;
    // Readings averaged for a step (about 2 s of the magnetometer's).
    std::uint32_t alignReadings(int sensor) const;
    // How far a gyroscope-only heading (mode Estimating) has come towards its step, for a person
    // who must move before a body calibration (the status document, the page): the online
    // estimate's readings against the seconds it needs, its spread against the spread it needs,
    // its residual and field; `measuring` once the estimate is good and the heading error is
    // being averaged. None for a sensor in any other mode.
    struct MagLearning {
        double readingsS = 0;
        double neededS = 0;
        double spread = 0;
        double neededSpread = 0;
        double residualPct = 0;
        double maxResidualPct = 0;
        double fieldUt = 0;
        bool solved = false;     // the readings gave an estimate (its figures below are set)
        bool measuring = false;  // good: the heading error is being averaged for the step
        // What it waits for: "readings", "turns", "a steadier field" or "the heading measured".
        const char* waitingFor = "readings";
    };
    std::optional<MagLearning> magLearning(int sensor) const;

private:
    struct OnlineMag {
        explicit OnlineMag(fusion::OnlineHardIron e) : estimator(std::move(e)) {}
        fusion::OnlineHardIron estimator;
        fusion::HardIronEstimate estimate;
        MagMode mode = MagMode::Estimating;
        bool decided = false;          // the first readings chose Raw or Estimating
        std::uint32_t sinceSolve = 0;  // readings since the last estimate()
        std::uint32_t solveEvery = 1;  // readings per estimate() (about 1 s)
        // Estimating with a good estimate: the heading error being averaged before the step.
        bool aligning = false;
        double sumSin = 0;  // sum of the heading errors' unit vectors
        double sumCos = 0;
        std::uint32_t alignCount = 0;
        std::uint32_t alignEvery = 1;  // readings averaged (about 2 s)
    };
    // The sensor's online estimator, null for no such sensor or one whose magnetometer the
    // calibration file corrects.
    const OnlineMag* onlineMagOf(int sensor) const;
    OnlineMag* onlineMagOf(int sensor) {
        return const_cast<OnlineMag*>(std::as_const(*this).onlineMagOf(sensor));
    }
    // Feeds a calibrated (or raw) field reading to the sensor's filter as its mode says.
    void magUpdate(std::size_t sensor, Filter& f, const Eigen::Vector3d& magUt, Timestamp t);
    // While aligning: one reading (less the offset) into the heading error's average; at its
    // end the step and the switch to Online.
    // Before a sensor's mode is decided: a saved good estimate, or the suit's vote on its first
    // reading (Raw or Estimating); gyroscope-only until the vote is counted.
    void decideMode(std::size_t sensor, OnlineMag& o, const Filter& f, const Eigen::Vector3d& magUt,
                    Timestamp t);
    void alignHeading(std::size_t sensor, OnlineMag& o, Filter& f, const Eigen::Vector3d& magUt,
                      Timestamp t);

    std::vector<std::unique_ptr<Filter>> filters_;
    std::vector<Latest> latest_;
    std::vector<bool> valid_;
    std::vector<bool> resetPending_;  // reset while out, no sample since
    std::vector<std::uint32_t> resets_;
    Calibrations calibrations_;
    std::vector<std::optional<OnlineMag>> onlineMag_;  // sensors without a magnetometer calibration
    std::vector<HeadingStep> headingSteps_;
    // The first raw readings of the suit, to tell a raw field that can be taken as it is.
    fusion::FieldVote firstFields_;
    fusion::Vec3<float> bodyAccEnu_{};
    RecordSink* records_;
    OrientationOverride override_;
    std::uint64_t updates_ = 0;
};

}  // namespace caphub::firmware
