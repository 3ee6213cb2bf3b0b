// Recordings for the export tests: pose records taken from the virtual suit's walk
// (tests/data/bvh/cmu_12_01_walk.bvh), written with RecordingWriter, as `caphub run` will.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "board/segment.h"

namespace caphub::firmware::testing {

// A pose as written to the recording (single precision, like the file).
struct RecordedPose {
    std::int64_t tNs = 0;
    Eigen::Vector3f rootM;
    std::array<Eigen::Quaternionf, board::kSegmentCount> qLocal;
    std::array<Eigen::Quaterniond, board::kSegmentCount> qWorld;  // the walk's, double
};

struct WalkRecordingOptions {
    double seconds = 3;
    double rateHz = 100;
    std::int64_t startNs = 5'000'000'000;  // the capture clock does not start at 0
    double heightM = 1.75;                 // written into the embedded board file
    bool withPoses = true;                 // false: raw samples only (no body stage)
    // Written as a [body_calibration] metadata record at startNs + calibrationAtS, as the
    // capture does (docs/body-calibration.md, "In recordings"); empty: none.
    std::string bodyCalibrationText;
    double calibrationAtS = 0;
    // Poses from heldFromS to heldToS (seconds from the first, inclusive) flag these segments
    // as not measured, as the capture does while their sensor is out.
    std::uint32_t heldSegments = 0;
    double heldFromS = 0;
    double heldToS = -1;
    // One more pose (a copy of the last) this long after the first: a record whose time is far
    // off the others, as a damaged file can hold; none when not set.
    std::optional<double> extraPoseAtS;
    // That pose's joint rotations all zero quaternions (no rotation at all), its checksum intact.
    bool extraPoseZero = false;
};

// Writes the recording (replacing any file at path) and returns the poses it holds.
std::vector<RecordedPose> writeWalkRecording(const std::string& path,
                                             const WalkRecordingOptions& options = {});

// The metadata `caphub run` writes, with the virtual suit's board file at the given height.
std::string walkMetadata(double heightM);

}  // namespace caphub::firmware::testing
