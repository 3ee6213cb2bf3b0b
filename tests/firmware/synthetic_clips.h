// Motion written as CMU clips for the evaluation tests: cmu_12_01's hierarchy and its T-pose
// frame 0, 120 Hz, the legs moved by two-link inverse kinematics in the sagittal plane so that
// each foot stays flat and where it is while it stands on something.
#pragma once

#include <filesystem>
#include <string>

namespace caphub::testing {

// A standing vertical jump: stand 1 s, crouch 0.25 m, push off at constant acceleration to
// kJumpTakeoffMps, 0.29 s of flight (apex 0.10 m above take-off) with the legs held, land with
// the push-off mirrored, stand up, stand 1 s.
inline constexpr double kJumpTakeoffMps = 1.4;
inline constexpr double kGravityMps2 = 9.81;
std::string jumpClip(const std::filesystem::path& walkClip);

// A stair of kStairSteps treads (riseM up, or down when negative, and kStairGoingM ahead each):
// stand 1 s; per step the right foot swings onto the next tread (going down it reaches it as the
// body lowers), the body moves over it, the left foot leaves its tread (going up once the heel,
// risen about the ball, no longer lets it reach) and swings beside the right one; stand 1 s.
inline constexpr int kStairSteps = 3;
inline constexpr double kStairRiseM = 0.17;
inline constexpr double kStairGoingM = 0.30;
std::string stairsClip(const std::filesystem::path& walkClip, double riseM = kStairRiseM);

}  // namespace caphub::testing
