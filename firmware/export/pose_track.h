// A recording's pose records turned into evenly spaced frames for the exporters: damaged and
// malformed records skipped and counted, a time window cut out, the rate changed by slerp of the
// joint rotations and linear interpolation of the root, and the subject's segment dimensions
// taken from the board file the recording carries.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "firmware/recording/reader.h"
#include "fusion/body/body_calibration.h"
#include "fusion/body/skeleton.h"
#include "hal/core/error.h"
#include "hal/core/quaternion.h"

namespace caphub::firmware::exporter {

struct PoseFrame {
    double tS = 0;                // seconds from the recording's first pose record
    Vec3d rootM = Vec3d::Zero();  // pelvis origin, skeleton world frame
    std::array<Quatd, body::kSegmentCount> qLocal;  // segment -> parent (pelvis: -> world)
    // Bit s set: segment s had no sensor reading (its sensor, or the one it follows, out): the
    // capture held its last measured rotation. An interpolated frame has the bits of both sides.
    std::uint32_t notMeasured = 0;
};

// A span of exported frames in which a segment was not measured (held), in seconds from the
// recording's first pose record, first and last frame inclusive.
struct NotMeasuredSpan {
    board::Segment segment = board::Segment::Pelvis;
    double fromS = 0;
    double toS = 0;
};

struct TrackOptions {
    std::optional<double> fromS;   // seconds from the first pose record; default: the first
    std::optional<double> toS;     // inclusive; default: the last
    std::optional<double> rateHz;  // default: the recording's pose rate
};

// A sensor of the recording's board: its name and the segment it is strapped to.
struct TrackSensor {
    std::string name;
    board::Segment segment = board::Segment::Pelvis;
};

// The mountings (q_segment_sensor, sensor frame -> segment frame) in effect from a time on: a
// body calibration recorded in the file ([body_calibration] metadata records).
struct MountingChange {
    double tS = 0;  // seconds from the first pose record
    body::SegmentMask mask = 0;
    std::array<Quatd, body::kSegmentCount> mounting;
};

struct PoseTrack {
    std::vector<PoseFrame> frames;  // at t = frames[0].tS + k / rateHz
    double rateHz = 0;
    double recordedRateHz = 0;     // the pose records' rate (from the median interval)
    board::SubjectConfig subject;  // the recording's board's, or the default subject
    body::Dimensions dimensions;   // the subject's
    std::string subjectSource;     // where the subject came from, for people
    // The board's sensors (empty when the recording carries no usable board file), their nominal
    // mountings, and the body calibrations the capture recorded, in time order.
    std::vector<TrackSensor> sensors;
    std::array<Quatd, body::kSegmentCount> nominalMounting;
    std::vector<MountingChange> calibrations;
    // What the reading met.
    std::uint64_t poseRecords = 0;      // valid pose records read
    std::uint64_t malformedPoses = 0;   // a valid record whose pose could not be used
    std::uint64_t outOfOrderPoses = 0;  // not later than the previous pose: dropped
    std::uint64_t damagedBytes = 0;     // skipped by the reader (bad CRC, broken framing)
    std::uint64_t damageRanges = 0;
    std::uint64_t tornTailBytes = 0;
    double recordingDurationS = 0;  // first to last pose record
};

// Progress while reading, as a fraction of the file in [0, 1].
using ProgressFn = std::function<void(double)>;

// The subject and its dimensions from a recording's metadata ([board] text); the default
// subject (1.75 m) when the metadata has no usable board file, with the reason in `source`.
body::Dimensions dimensionsFromMetadata(const std::string& metadataToml, std::string& source,
                                        board::SubjectConfig& subject);

// Reads every pose record. Errors: a read error, no usable pose record ("no pose records: was
// the body stage on?"), a bad window or rate, or no frame in the window.
Result<PoseTrack> readPoseTrack(RecordingReader& reader, const TrackOptions& options,
                                std::uint64_t fileBytes = 0, const ProgressFn& progress = {});

// Euler-free pose interpolation: slerp of every joint rotation, linear for the root.
PoseFrame interpolate(const PoseFrame& a, const PoseFrame& b, double alpha);

// The spans of the track's frames with a segment not measured, by segment, then time.
std::vector<NotMeasuredSpan> notMeasuredSpans(const PoseTrack& track);

// The mounting (q_segment_sensor) of the sensor on `segment` at time tS: the latest body
// calibration at or before tS that calibrated it (the first one, before any), else the board's
// nominal mounting.
Quatd mountingAt(const PoseTrack& track, board::Segment segment, double tS);

}  // namespace caphub::firmware::exporter
