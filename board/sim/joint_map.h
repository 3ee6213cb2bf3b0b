// Which joints of a BVH skeleton drive which of caphub's 21 segments: built-in presets for the
// CMU clips' two naming styles, and user map files (TOML, docs/virtual-suit.md) for other rigs.
#pragma once

#include <array>
#include <filesystem>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "board/segment.h"
#include "board/sim/bvh.h"
#include "hal/core/error.h"

namespace caphub::board::sim {

// The pose in which segment frames are aligned with the world frame (the T-pose): a frame of the
// clip; the rest pose (every channel zero, the OFFSETs alone); or a T-pose synthesised from the
// rest pose by turning each mapped segment's bone onto its T-pose direction (docs/virtual-suit.md).
struct ReferencePose {
    enum class Kind { Frame, Rest, TPose };
    Kind kind = Kind::Frame;
    int frame = 0;
};

// One metre per BVH unit for CMU clips: their unit is 1/0.45 inch.
inline constexpr double kCmuUnitM = 0.056444;

struct JointMap {
    std::string name;
    std::optional<double> unitM;             // metres per BVH unit, when the map knows it
    std::optional<ReferencePose> reference;  // when the rig needs a particular one
    // The first frame of real motion, when frames before it are not motion (a T-pose frame).
    std::optional<int> firstFrame;
    // Per segment, the BVH joints that make it up (in any order; they must form one chain).
    // Empty: the segment is missing from the rig.
    std::array<std::vector<std::string>, board::kSegmentCount> joints;
};

// The built-in maps: "cmu-motionbuilder" (Hips, LeftUpLeg, LeftLeg, ...), "cmu-3dsmax"
// (Hips, LeftHip, LeftKnee, lowerback, Chest, ...), "cmu-daz" (hip, abdomen, lThigh, lShin, ...).
std::span<const JointMap> builtInJointMaps();
const JointMap* findBuiltInJointMap(std::string_view name);

// The built-in map whose every joint the clip has, or nullptr.
const JointMap* detectJointMap(const BvhClip& clip);

// A user map file. Errors read "<file>:<line>:<column>: <key>: <what was expected>".
Result<JointMap> parseJointMap(std::string_view text, std::string_view sourceName);
Result<JointMap> loadJointMap(const std::filesystem::path& path);

// caphub's segment tree (H-Anim): the segment each segment hangs from; none for the pelvis.
std::optional<board::Segment> parentSegment(board::Segment s);

// A map resolved against one clip. A segment made of several joints takes its orientation from
// the most distal of them and its position (its proximal joint) from the most proximal. A
// segment the rig lacks takes the whole pose of its nearest mapped ancestor segment.
struct SegmentBinding {
    std::array<int, board::kSegmentCount> orientationJoint{};  // BVH joint index, -1: unmapped
    std::array<int, board::kSegmentCount> positionJoint{};
    std::array<board::Segment, board::kSegmentCount> poseSource{};  // itself when mapped
    bool mapped(board::Segment s) const { return orientationJoint[static_cast<int>(s)] >= 0; }
};

// Checks the map against the clip: every named joint exists once, joints of one segment form a
// chain, no joint serves two segments, the pelvis is mapped. All problems in one message.
Result<SegmentBinding> bindJointMap(const JointMap& map, const BvhClip& clip);

}  // namespace caphub::board::sim
