// Reprocessing a recording: its raw samples and lifecycle events go again through the stages of
// `caphub run` (FusionStage, BodyStage) in the order they were recorded, with choices made after
// the fact (the body calibration and when, the sensor calibration, the pose rate), and optionally
// a non-causal pass over the whole take (--smooth: fusion/smoother.h). What comes out goes to a
// RecordSink: new orientations and poses, the carried-over samples, events and markers. For
// `caphub reprocess` and `caphub evaluate --reprocess-smooth`. Deterministic: the same input gives
// the same records.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "board/board.h"
#include "firmware/recording/format.h"
#include "firmware/recording/reader.h"
#include "firmware/recording/writer.h"
#include "firmware/runtime/fusion_stage.h"
#include "firmware/runtime/pipeline.h"
#include "firmware/runtime/pose_feed.h"
#include "firmware/runtime/record_sink.h"
#include "fusion/body/body_calibration.h"
#include "fusion/body/skeleton.h"
#include "fusion/smoother.h"
#include "hal/core/error.h"
#include "hal/imu_sample.h"

namespace caphub::firmware {

// A recording in memory: what reprocessing reads (the raw samples, events, markers and metadata
// records, in file order); the recorded orientations and poses are not kept.
struct SourceRecording {
    struct Item {
        cap::RecordType type = cap::RecordType::RawSample;
        Timestamp t{};
        int sensor = -1;
        hal::ImuSample sample;                               // RawSample
        cap::EventKind kind = cap::EventKind::SensorOnline;  // Event
        int error = 0;                                       // Event
        std::string text;  // Event text, marker label, metadata TOML
    };
    std::string metadata;  // the header's
    std::vector<Item> items;
    std::uint64_t samples = 0;
    std::uint64_t damagedBytes = 0;
    std::uint64_t malformed = 0;  // records whose payload did not decode (skipped)
    // Raw samples at or before their sensor's previous one (skipped): two recordings joined,
    // a damaged time. Fed to a filter they would turn it backwards.
    std::uint64_t outOfOrder = 0;
};

// Reads every record of a recording (a damaged one: what the reader recovers).
Result<SourceRecording> readSourceRecording(RecordingReader& reader);

// Where a reprocess puts its records: the stages' (orientations, poses, calibration events and
// metadata) and the carried-over raw samples, events and markers, in time order.
class ReprocessSink : public RecordSink {
public:
    virtual void rawSample(int sensor, const hal::ImuSample& s) = 0;
};

// A sink that writes the records straight into a recording (`caphub reprocess`, the import of
// BROAD-layout streams); the first write error is kept.
class RecordingWriterSink final : public ReprocessSink {
public:
    explicit RecordingWriterSink(RecordingWriter& w) : w_(w) {}
    void rawSample(int sensor, const hal::ImuSample& s) override {
        check(w_.writeRawSample(sensor, s));
    }
    void orientation(int sensor, Timestamp t, const Eigen::Quaternionf& q) override {
        check(w_.writeOrientation(sensor, t, q));
    }
    void pose(Timestamp t, const Eigen::Vector3f& rootM, std::span<const Eigen::Quaternionf> joints,
              std::uint32_t notMeasured) override {
        check(w_.writePose(t, rootM, joints, notMeasured));
    }
    void event(Timestamp t, cap::EventKind kind, int sensor, int error,
               std::string_view text) override {
        check(w_.writeEvent(t, kind, sensor, error, text));
    }
    void metadata(Timestamp t, std::string_view toml) override { check(w_.writeMetadata(t, toml)); }
    void marker(Timestamp t, std::string_view label) override { check(w_.writeMarker(t, label)); }
    int firstError = 0;

private:
    void check(int r) {
        if (r != 0 && firstError == 0) {
            firstError = r;
        }
    }
    RecordingWriter& w_;
};

// The body calibration to apply.
struct CalibrationChoice {
    enum class Kind { FromRecording, TPose, NPose, TPlusN, None };
    Kind kind = Kind::FromRecording;
    // When the subject held the pose: seconds from the recording's first sample (TPose, NPose:
    // one; TPlusN: the T-pose's, then the N-pose's). The orientations are averaged from there
    // over the body's window (1 s).
    std::vector<double> atS;
};

struct ReprocessOptions {
    CalibrationChoice calibration;
    // Per board sensor; empty: the recording's own [calibration] (none when it has none).
    std::optional<FusionStage::Calibrations> sensorCalibrations;
    double poseRateHz = 60;
    // The non-causal pass: orientations from a forward and a backward run of each sensor's
    // filter over the whole take, combined.
    bool smooth = false;
    fusion::SmootherOptions smoothing;
    // With smooth: the capture heading corrected from the knees' axes over the whole take, from
    // the calibration on (docs/body-calibration.md, "The capture heading from the knees").
    bool kneeHeading = true;
    // The body's skeleton (default: the board's [subject]); the evaluation gives the clip's.
    std::optional<body::Dimensions> dimensions;
    // Receives the poses solved (the evaluation scores them from a queue); may be null.
    PoseFeed* feed = nullptr;
    // Run after the body on every sample (and at the end); not owned.
    std::vector<PipelineStage*> stages;
    // Called now and then with the fraction done (0..1) and what is being done.
    std::function<void(std::string_view stage, double fraction)> progress;
};

struct ReprocessSummary {
    std::uint64_t samples = 0;
    std::uint64_t poses = 0;
    std::uint64_t orientations = 0;
    std::string calibration;  // what was applied ("T-pose at 2.50 s", "none: nominal mountings")
    std::string calibrationError;
    double durationS = 0;  // of the recording's samples
    // With --smooth: the capture heading's error the knees' axes showed over the whole take
    // (deg), corrected from the calibration on; none when they could not say (too little
    // walking, free headings, several calibrations, T+N).
    std::optional<double> kneeHeadingDeg;
};

// Runs the recording's samples through fusion and body; everything goes to `out` in time order.
// Errors (EINVAL): no samples, a calibration time outside the recording, a calibration that
// cannot be redone from the file.
Result<ReprocessSummary> reprocess(const board::Board& board, const SourceRecording& source,
                                   const ReprocessOptions& options, ReprocessSink& out);

}  // namespace caphub::firmware
