// The pipeline stage that drives the body: optionally a calibration in a reference pose at the
// start of the capture (the subject stands still in it while the filters settle), then the body
// solver at the output rate on the latest sensor orientations, one pose record per frame.
#pragma once

#include <array>
#include <optional>
#include <vector>

#include "board/board.h"
#include "firmware/runtime/capture.h"
#include "firmware/runtime/fusion_stage.h"
#include "firmware/runtime/latency_window.h"
#include "firmware/runtime/record_sink.h"
#include "fusion/body/body_calibration.h"
#include "fusion/body/body_solver.h"
#include "fusion/body/foot_inertial.h"

namespace caphub::firmware {

class BodyStage final : public PipelineStage {
public:
    struct Options {
        double rateHz = 60;  // poses per second
        // Calibrate in this pose: the subject holds it from the start; the orientations are
        // averaged over [settle, settle + average] after the first sample. None: the board's
        // nominal mountings, the subject facing north.
        std::optional<body::ReferencePoseKind> calibrate;
        Duration settle = std::chrono::milliseconds(2500);
        Duration average = std::chrono::milliseconds(1000);
        // The subject's skeleton; default: from the board's [subject].
        std::optional<body::Dimensions> dimensions;
        // Hand the filters the body's horizontal acceleration from the root's tracked motion
        // (FusionStage::setBodyAcceleration), so that starting and stopping do not tilt them.
        bool aidFilters = true;
        // Track each foot sensor's velocity from the foot's latest still instant
        // (body::FootInertial), so that the root follows a planted foot that slips as it rolls
        // off the floor; false: the foot contacts alone.
        bool footInertial = true;
        body::FootInertialOptions footInertialOptions;
    };

    // fusion must be added to the capture before this stage (it reads its latest orientations,
    // and hands it back the body's acceleration: FusionStage::setBodyAcceleration); records
    // may be null.
    BodyStage(const board::Board& board, FusionStage& fusion, RecordSink* records, Clock& clock,
              const Options& options);

    void onSample(const SensorSample& s) override;
    void onEvent(const RuntimeEvent& e) override;

    bool calibrated() const { return calibrated_; }
    const body::BodyCalibration& calibration() const { return calibration_; }
    // Why a requested calibration failed (empty when it did not).
    const std::string& calibrationError() const { return calibrationError_; }
    std::uint64_t poses() const { return poses_; }
    const body::Pose& pose() const { return solver_.pose(); }
    // When the latest pose was solved for (its grid point), and the solver (its root tracker).
    Timestamp poseTime() const { return lastFrame_; }
    const body::BodySolver& solver() const { return solver_; }
    // Per pose, the time from the newest sample's data-ready edge to the pose being written, on
    // the capture clock as the pipeline saw it: percentiles (0..1) over the last 65536 poses
    // (18 min at 60 Hz).
    Duration latencyPercentile(double p) const { return latency_.percentile(p); }

private:
    void calibrate(Timestamp t);
    void solveFrame(Timestamp t, Timestamp newestSample);
    // A sensor's orientation at t: between its two latest samples, or carried on past the latest
    // at its gyroscope's rate for at most one sample interval. False when it has none.
    bool orientationAt(int sensor, Timestamp t, Eigen::Quaternionf& q) const;
    // The body's horizontal acceleration from the root's tracked velocity, to the filters.
    void feedBackAcceleration(double dtS);

    const board::Board& board_;
    FusionStage& fusion_;
    RecordSink* records_;
    Clock& clock_;
    Options options_;
    Duration period_;
    body::BodySolver solver_;
    body::SegmentMask mask_ = 0;
    std::array<Quatd, body::kSegmentCount> nominal_;
    std::vector<int> sensorOfSegment_;  // segment -> board sensor, -1 when none
    // Per sensor its two latest orientations and their sample times. Poses are solved on a fixed
    // grid that the sensors' samples do not fall on (60 Hz poses from 100 Hz sensors): taken as
    // they are, the orientations would be 0-10 ms old in a repeating pattern, and the joint
    // rates (the foot contacts' velocities) would swing by tens of percent from pose to pose.
    struct HeldOrientation {
        Eigen::Quaternionf previous = Eigen::Quaternionf::Identity();
        Eigen::Quaternionf latest = Eigen::Quaternionf::Identity();
        Eigen::Vector3f rateRadS = Eigen::Vector3f::Zero();  // the latest gyro, sensor frame
        Timestamp previousT{};
        Timestamp latestT{};
        int count = 0;  // orientations held: 0, 1 or 2
    };
    std::vector<HeldOrientation> held_;
    int pelvisSensor_ = -1;
    // The feet's sensors (board indices, -1 when none) and their dead reckoning.
    std::array<int, 2> footSensor_{-1, -1};
    std::array<body::FootInertial, 2> footInertial_;
    // The pelvis accelerometer's readings since the last pose, each turned into ENU (m/s^2);
    // their mean goes to the skeleton world frame once per pose.
    Vec3d pelvisForceSumEnu_ = Vec3d::Zero();
    int pelvisForceCount_ = 0;
    body::BodyCalibration calibration_;
    bool calibrated_ = false;
    std::string calibrationError_;
    std::optional<Timestamp> first_;
    Timestamp nextFrame_{};
    Timestamp lastFrame_{};
    // The calibration average: per sensor the sum of sign-aligned quaternions.
    std::vector<Eigen::Vector4d> sum_;
    std::vector<int> count_;
    std::uint64_t poses_ = 0;
    Vec3d rootVelocityLp_ = Vec3d::Zero();  // m/s, skeleton world, horizontal
    bool rootVelocityValid_ = false;
    LatencyWindow latency_{1 << 16};
    std::array<Eigen::Quaternionf, body::kSegmentCount> joints_{};
};

}  // namespace caphub::firmware
