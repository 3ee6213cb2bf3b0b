// The pipeline stage that drives the body: an adapter that feeds the body tracker
// (fusion/body/body_tracker.h) each sensor's orientation from the fusion stage, asks it for the
// poses the grid has due, hands the filters the body's acceleration it returns, and writes pose
// records, calibration events and metadata. Optionally a calibration in a reference pose at the
// start of the capture (the subject stands still in it while the filters settle).
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "board/board.h"
#include "firmware/runtime/capture.h"
#include "firmware/runtime/fusion_stage.h"
#include "firmware/runtime/latency_window.h"
#include "firmware/runtime/pose_feed.h"
#include "firmware/runtime/record_sink.h"
#include "fusion/body/body_tracker.h"

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
        // The capture heading from the knees' axes (body::KneeHeadingMode: estimated, or
        // corrected live once known), or a correction known from the whole take (reprocess).
        body::KneeHeadingMode kneeHeading = body::KneeHeadingMode::Estimate;
        std::optional<double> knownHeadingErrorRad;
        // The free (gyroscope-only) headings of a one-pose calibration set against their
        // neighbours' from the joints' accelerations while the body moves
        // (body::BodyTrackerOptions::jointHeading).
        bool jointHeading = true;
        // Offline: the feet's stretches recorded, or corrected from a pass before (null live).
        std::shared_ptr<body::FootStretchLogs> footStretches;
    };

    // fusion must be added to the capture before this stage (it reads its latest orientations,
    // and hands it back the body's acceleration: FusionStage::setBodyAcceleration); records may
    // be null.
    BodyStage(const board::Board& board, FusionStage& fusion, RecordSink* records, Clock& clock,
              const Options& options);

    void onSample(const SensorSample& s) override;
    // Lost or silent: the sensor's segment is invalid until it reports again; reset: what was
    // held of it is stale.
    void onEvent(const RuntimeEvent& e) override;

    // Publish every pose solved from now on to the feed (the live consumers); call before the
    // capture starts.
    void publishTo(PoseFeed& feed) { feed_ = &feed; }

    bool calibrated() const { return tracker_.calibrated(); }
    const body::BodyCalibration& calibration() const { return tracker_.calibration(); }
    // Why a requested calibration failed (empty when it did not).
    const std::string& calibrationError() const { return tracker_.calibrationError(); }
    std::uint64_t poses() const { return tracker_.poses(); }
    const body::Pose& pose() const { return tracker_.pose(); }
    // When the latest pose was solved for (its grid point), and the solver (its root tracker).
    Timestamp poseTime() const { return tracker_.latest().t; }
    const body::BodySolver& solver() const { return tracker_.solver(); }
    // The tracker: the latest pose's valid segments, the calibration status, and requests (a
    // calibration, a heading reset) on the pipeline thread.
    body::BodyTracker& tracker() { return tracker_; }
    const body::BodyTracker& tracker() const { return tracker_; }
    // Per pose, the time from the newest sample's data-ready edge to the pose being written, on
    // the capture clock as the pipeline saw it: percentiles (0..1) over the last 65536 poses
    // (18 min at 60 Hz).
    Duration latencyPercentile(double p) const { return latency_.percentile(p); }
    const LatencyWindow& latencyWindow() const { return latency_; }

private:
    void record(Timestamp t, const body::TrackerEvents& events);
    // A calibration re-expressed for a sensor's measured heading: an event and the new
    // calibration's metadata.
    void recordReexpression(Timestamp t, int sensor, double angleRad);
    // The capture heading corrected from the knees' axes: logged, an event and the calibration.
    void recordKneeHeading(Timestamp t, double angleRad);
    void publish(const body::TrackedPose& p, Timestamp newest, std::uint32_t notMeasured);

    FusionStage& fusion_;
    RecordSink* records_;
    PoseFeed* feed_ = nullptr;
    PoseFrame frame_;  // the latest published
    Clock& clock_;
    Options options_;
    body::BodyTracker tracker_;
    bool started_ = false;
    LatencyWindow latency_{1 << 16};
    static constexpr std::uint32_t kAllJoints = (1u << body::kSegmentCount) - 1;
    std::array<Eigen::Quaternionf, body::kSegmentCount> joints_{};
    std::array<bool, body::kSegmentCount> jointSeen_{};  // measured at least once
    std::vector<std::uint32_t> headingSteps_;  // per sensor, FusionStage::HeadingStep::count seen
    std::vector<std::string> sensorNames_;
};

}  // namespace caphub::firmware
