// The BROAD error metric: q_err = q_est * inverse(q_opt), split into heading and inclination,
// RMSE over movement samples with finite ground truth.
#include "fusion/evaluation.h"

#include <cmath>

#include <gtest/gtest.h>

namespace caphub::fusion {
namespace {

TEST(BroadMetric, SeparatesHeadingFromInclination) {
    // A pure rotation about earth z is all heading; one about earth x all inclination.
    const Quatd truth = fromAxisAngle<double>(Vec3d(0.3, 0.2, 0.9), 0.7);
    const Quatd yaw = fromAxisAngle<double>(Vec3d::UnitZ(), 0.1) * truth;
    const Quatd tilt = fromAxisAngle<double>(Vec3d::UnitX(), 0.1) * truth;
    const SampleErrors h = broadSampleErrors(yaw, truth);
    const SampleErrors i = broadSampleErrors(tilt, truth);
    EXPECT_NEAR(h.headingRad, 0.1, 1e-12);
    EXPECT_NEAR(h.inclinationRad, 0.0, 1e-7);  // acos near 1: 1e-8 rounding becomes 1e-7 rad
    EXPECT_NEAR(i.inclinationRad, 0.1, 1e-12);
    EXPECT_NEAR(i.headingRad, 0.0, 1e-12);
    EXPECT_NEAR(i.totalRad, 0.1, 1e-12);
}

TEST(BroadMetric, CountsOnlyMovementSamplesWithFiniteTruth) {
    const std::vector<Quatd> est(4, Quatd::Identity());
    const Quatd off = fromAxisAngle<double>(Vec3d::UnitZ(), 0.2);
    const std::vector<Quatd> truth = {off, Quatd(NAN, NAN, NAN, NAN), off, Quatd::Identity()};
    const std::vector<bool> movement = {true, true, false, true};
    const BroadErrors e = broadMetric(est, truth, movement);
    EXPECT_EQ(e.samples, 2u);
    // Errors 0.2 rad and 0: RMSE sqrt(0.04 / 2) rad.
    EXPECT_NEAR(e.totalDeg, std::sqrt(0.02) * 57.29577951308232, 1e-9);
}

}  // namespace
}  // namespace caphub::fusion
