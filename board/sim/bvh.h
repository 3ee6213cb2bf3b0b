// A BVH (Biovision Hierarchy) motion file as plain data: the joint tree with offsets and channels,
// and the frames of channel values. Read by the virtual suit and by tests of the BVH exporter.
#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "hal/core/angles.h"
#include "hal/core/error.h"
#include "hal/core/quaternion.h"

namespace caphub::board::sim {

enum class BvhChannel : std::uint8_t {
    Xposition,
    Yposition,
    Zposition,
    Xrotation,
    Yrotation,
    Zrotation,
};

std::string_view toString(BvhChannel c);

struct BvhJoint {
    std::string name;
    int parent = -1;                   // index into BvhClip::joints; -1 for a ROOT
    Vec3d offset = Vec3d::Zero();      // from the parent's origin, parent frame, file units
    std::vector<BvhChannel> channels;  // in file order; rotations apply in this order
    int firstChannel = 0;              // index of channels[0] within a frame's values
    std::optional<Vec3d> endSite;      // the End Site offset, when the joint has one
    int line = 0;                      // where the joint was declared
};

struct BvhClip {
    std::vector<BvhJoint> joints;  // in file order: every parent comes before its children
    int channelCount = 0;          // values per frame
    int frameCount = 0;
    double frameTimeS = 0;
    std::vector<double> values;  // frameCount rows of channelCount values, as in the file

    std::span<const double> frame(int f) const;

    // The first joint with this name, or -1.
    int findJoint(std::string_view name) const;

    // A joint's transform relative to its parent at one frame: v_parent = t + q * v_joint, t in
    // file units. Position channels replace the OFFSET on the axes they name (the root's
    // translation is its position channels); rotation channels are intrinsic rotations in the
    // order they are listed, in degrees.
    void localPose(int joint, std::span<const double> frameValues, Vec3d& translation,
                   Quatd& rotation) const;
};

// A joint the clip turns faster than a body can: relative to its parent, by more than
// `maxRateRadS` times the frame time between two consecutive frames. Motion capture does this
// when its solver flips a limb about its long axis for a frame or a few (cmu_05_06's right leg:
// 171-180 deg in 1/120 s); no segment of a body turns beyond about 10,000 deg/s (a pitcher's
// upper arm, the fastest measured, reaches 7,000-9,000).
struct ImplausibleTurns {
    std::string joint;
    int frames = 0;         // frame-to-frame steps beyond the rate
    double maxTurnRad = 0;  // the largest of them
};
inline constexpr double kBodyMaxRateRadS = 10000.0 * hal::kDegToRad;

// Per joint with such steps, in file order; empty for a clip a body could have made.
std::vector<ImplausibleTurns> implausibleTurns(const BvhClip& clip,
                                               double maxRateRadS = kBodyMaxRateRadS);

// Parses BVH text. Accepts the whole grammar: HIERARCHY, one or more ROOTs, JOINT, End Site,
// OFFSET, CHANNELS with 0-6 channels in any order on any joint, MOTION, Frames, Frame Time; any
// whitespace layout (tokens may be split over lines at will; CRLF is fine). Keywords and channel
// names are case-insensitive. On malformed input the error reads
// "<sourceName>: line N: expected ..., found ...".
Result<BvhClip> parseBvh(std::string_view text, std::string_view sourceName);

Result<BvhClip> loadBvh(const std::filesystem::path& path);

}  // namespace caphub::board::sim
