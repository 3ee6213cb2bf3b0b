// Scores the body solver against the virtual suit's ground truth: a BVH clip drives the true
// segment trajectories (board/sim), ideal sensor orientations are made from them with the suit
// file's mountings, and the solver's joints and root are compared with the truth.
#pragma once

#include <array>
#include <filesystem>
#include <string>

#include "fusion/body/body_calibration.h"
#include "hal/core/error.h"

namespace caphub::body::evaluation {

struct ClipScore {
    std::string clip;
    int frames = 0;
    double rateHz = 0;
    double speed = 1.0;
    // Per joint (segment index): mean angle error of the joint rotation (the pelvis: of its
    // world orientation), deg; mean position error of the joint centre relative to the root, m.
    std::array<double, kSegmentCount> angleDeg{};
    std::array<double, kSegmentCount> positionM{};
    double meanAngleDeg = 0;   // over the 21 joints
    double meanPositionM = 0;  // over the 20 joints below the root
    double walkedM = 0;        // horizontal path length of the true root
    double finalDriftM = 0;    // horizontal distance between solved and true root at the end
    double maxDriftM = 0;
    int stanceChanges = 0;
};

// suit: a board file (its sensors' segments and nominal mountings); rateHz: solver rate;
// speed: the clip played this many times faster (a stand-in for faster gaits than the clip's).
Result<ClipScore> scoreClip(const std::filesystem::path& bvh, const std::filesystem::path& suit,
                            double rateHz, double speed = 1.0);

std::string formatTable(const ClipScore& s);

}  // namespace caphub::body::evaluation
