// Scores the body solver against the virtual suit's ground truth: a BVH clip drives the true
// segment trajectories (board/sim), ideal sensor orientations are made from them with the suit
// file's mountings, and the solver's joints and root are compared with the truth.
#pragma once

#include <filesystem>
#include <string>

#include "fusion/body/body_calibration.h"
#include "fusion/body/pose_score.h"
#include "hal/core/error.h"

namespace caphub::body::evaluation {

// The shared scoring (fusion/body/pose_score.h) of one clip, and how it was played.
struct ClipScore : PoseScore {
    std::string clip;
    double rateHz = 0;
    double speed = 1.0;
};

// suit: a board file (its sensors' segments and nominal mountings); rateHz: solver rate;
// speed: the clip played this many times faster (a stand-in for faster gaits than the clip's).
Result<ClipScore> scoreClip(const std::filesystem::path& bvh, const std::filesystem::path& suit,
                            double rateHz, double speed = 1.0);

std::string formatTable(const ClipScore& s);

}  // namespace caphub::body::evaluation
