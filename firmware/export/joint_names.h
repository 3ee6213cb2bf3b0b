// The names an export gives the 21 segments and their joints: H-Anim, the CMU (MotionBuilder)
// and Unity humanoid conventions, or a user's TOML map file (docs/exports.md, "Joint names").
#pragma once

#include <array>
#include <string>
#include <string_view>

#include "board/segment.h"
#include "hal/core/error.h"

namespace caphub::firmware::exporter {

struct JointNames {
    std::string setName;  // "hanim", "cmu", "unity" or the map file's path
    // Per segment (board/segment.h order): the name of the joint at its proximal end, for the
    // skeletal formats (BVH, glTF), and the name of the segment, for the per-segment tables
    // (CSV, .sto). They differ only for H-Anim, which names joints and segments separately.
    std::array<std::string, board::kSegmentCount> joint;
    std::array<std::string, board::kSegmentCount> segment;
    // Whether the segment has a column in a .sto table (the opensim set leaves out the segments
    // OpenSim's full-body models have no body for), and whether the set names anything but .sto
    // columns (the opensim set names model bodies, not a skeleton's joints).
    std::array<bool, board::kSegmentCount> stoColumn;
    bool stoOnly = false;
    JointNames() { stoColumn.fill(true); }
};

// The OpenSim body of each segment in OpenSim's common full-body models (Rajagopal 2015, as in
// the OpenSense tutorials; gait2392 and Hamner 2010 use the same leg and torso names), empty
// where they have none (l5, c7, skull, the clavicles: the torso body carries them).
std::string_view openSimBody(board::Segment s);

// "hanim", "cmu", "unity", "opensim", or else the path of a map file.
Result<JointNames> jointNamesFor(std::string_view spec);

// A map file: "segment = \"name\"" lines (TOML), segment names as in board files; segments not
// listed keep their H-Anim names. Names must be unique, non-empty, printable and free of
// whitespace and of the characters {}"# (BVH tokens). Errors read "<source>:<line>: <what>".
Result<JointNames> parseJointNames(std::string_view text, const std::string& sourceName);

}  // namespace caphub::firmware::exporter
