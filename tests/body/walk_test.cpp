// End to end on the virtual suit (ideal orientations from the simulation's ground truth, T-pose
// calibration): walking moves the root by the clip's true distance, and the per-joint errors
// meet the targets. The same scoring prints the tables of docs/skeleton.md
// (caphub_body_evaluate).
#include <filesystem>

#include <gtest/gtest.h>

#include "tests/body/body_evaluation.h"

namespace caphub::body {
namespace {

const std::filesystem::path kSuit =
    std::filesystem::path(CAPHUB_SOURCE_DIR) / "board" / "sim-suit.toml";

// Ideal orientations (the simulation's truth, no filter) through the T-pose calibration and the
// solver: the paper's 17 independent joints come out exact, their centres within the targets'
// 2 cm of the truth (1.69 cm: the skeleton's proportions against the clip's), and the root walks.
// The root's drift is not asserted here: this path has no sensor data, so the planted foot's slip
// (measured by its sensor, docs/skeleton.md) is not seen and the contacts alone drift 6.3 %; the
// drift target (<= 3 %) and the joints' targets through the whole path (chips, filters,
// calibration) are asserted by EvaluateThroughTheFilter in tests/firmware/evaluate_test.cpp.
// (Two DISABLED tests stood here for targets this path cannot meet; they are gone.)
TEST(VirtualSuitWalk, IdealOrientationsSolveThePapersJointsExactly) {
    auto s = evaluation::scoreClip(
        std::filesystem::path(CAPHUB_TEST_DATA_DIR) / "bvh" / "cmu_12_01_walk.bvh", kSuit, 100);
    ASSERT_TRUE(s.ok()) << s.error().message;
    ASSERT_GT(s->walkedM, 3.0);  // the clip walks 3.9 m
    EXPECT_LT(s->independentMeanAngleDeg, 0.01) << evaluation::formatTable(*s);
    EXPECT_LE(s->independentMeanPositionM, 0.02) << evaluation::formatTable(*s);
    EXPECT_EQ(s->stanceChanges, 7) << evaluation::formatTable(*s);  // the clip's true steps
}

}  // namespace
}  // namespace caphub::body
