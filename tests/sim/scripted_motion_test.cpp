// The calibration scripts of the virtual suit: the six positions put each axis up in turn, the
// fourteen each face and corner, and every script's angular rate and acceleration are the
// derivatives of its orientation, so that the IMU model's gyro and accelerometer readings are
// physical.
#include "board/sim/scripted_motion.h"

#include <cmath>
#include <cstdlib>
#include <vector>

#include <gtest/gtest.h>

namespace caphub::board::sim {
namespace {

constexpr std::int64_t kMs = 1'000'000;

SegmentState at(const ScriptedMotion& m, std::int64_t tNs) {
    SegmentState s;
    m.evaluate(Segment::Pelvis, tNs, s);
    return s;
}

// Body rate from two orientations dt apart: log(q(t)^-1 q(t + dt)) / dt.
Vec3d numericRate(const ScriptedMotion& m, std::int64_t tNs, std::int64_t dtNs) {
    const Quatd a = at(m, tNs - dtNs / 2).qWorldSegment;
    const Quatd b = at(m, tNs + dtNs / 2).qWorldSegment;
    const Eigen::AngleAxisd d(a.conjugate() * b);
    return d.axis() * d.angle() / (static_cast<double>(dtNs) * 1e-9);
}

TEST(ScriptedMotion, SixPositionsHoldEachAxisUpAndDown) {
    const ScriptedMotion m(Script::SixPositions, ScriptTiming{});
    const Vec3d up(0, 1, 0);
    const Vec3d axes[6] = {Vec3d::UnitZ(),  -Vec3d::UnitZ(), Vec3d::UnitX(),
                           -Vec3d::UnitX(), Vec3d::UnitY(),  -Vec3d::UnitY()};
    for (int k = 0; k < 6; ++k) {
        // The middle of each hold: still, with the k-th sensor axis pointing up.
        const auto t = static_cast<std::int64_t>((k * 4.5 + 1.5) * 1e9);
        const SegmentState s = at(m, t);
        EXPECT_LT((s.qWorldSegment * axes[k] - up).norm(), 1e-12) << "position " << k;
        EXPECT_EQ(s.omegaRadS.norm(), 0.0);
    }
    EXPECT_NEAR(static_cast<double>(m.durationNs()) * 1e-9, 6 * 3.0 + 5 * 1.5, 1e-9);
}

TEST(ScriptedMotion, FourteenPositionsHoldEachFaceAndCornerUpOnce) {
    const ScriptedMotion m(Script::FourteenPositions, ScriptTiming{});
    const Vec3d up(0, 1, 0);
    std::vector<Vec3d> seen;
    for (int k = 0; k < ScriptedMotion::kFourteen; ++k) {
        const auto t = static_cast<std::int64_t>((k * 4.5 + 1.5) * 1e9);
        const SegmentState s = at(m, t);
        const Vec3d u = ScriptedMotion::fourteenUp(k);
        EXPECT_LT((s.qWorldSegment * u - up).norm(), 1e-12) << "position " << k;
        EXPECT_EQ(s.omegaRadS.norm(), 0.0);
        // Up in the sensor frame: a face (one non-zero axis) or a corner (three equal ones).
        const Vec3d sensorUp = s.qWorldSegment.conjugate() * up;
        const Vec3d a = sensorUp.cwiseAbs();
        const bool face = std::abs(a.maxCoeff() - 1.0) < 1e-9;
        const bool corner = (a.array() - 1.0 / std::sqrt(3.0)).abs().maxCoeff() < 1e-9;
        EXPECT_TRUE(face || corner) << "position " << k;
        for (const Vec3d& v : seen) {
            EXPECT_GT((v - sensorUp).norm(), 0.5) << "position " << k << " repeats one";
        }
        seen.push_back(sensorUp);
    }
    EXPECT_NEAR(static_cast<double>(m.durationNs()) * 1e-9, 14 * 3.0 + 13 * 1.5, 1e-9);
}

TEST(ScriptedMotion, RatesAreTheDerivativesOfTheOrientation) {
    for (Script script : {Script::SixPositions, Script::FourteenPositions, Script::Tumble}) {
        const ScriptedMotion m(script, ScriptTiming{});
        for (std::int64_t t = 100 * kMs; t < m.durationNs() - 100 * kMs; t += 37 * kMs) {
            const SegmentState s = at(m, t);
            // Central difference over 0.2 ms: error ~ alpha' dt^2 / 24, far below 1e-6 rad/s.
            EXPECT_LT((numericRate(m, t, 200'000) - s.omegaRadS).norm(), 1e-6)
                << toString(script) << " at " << t;
            // The angular acceleration is continuous but the jerk steps where a hold meets a
            // turn (at 3.0 s and 4.5 s of each 4.5 s cycle): a central difference across such a
            // step is off by up to h * step / 2, so those instants are left out of this check.
            const std::int64_t inCycle = t % 4'500'000'000;
            const bool nearStep =
                std::abs(inCycle - 3'000'000'000) < kMs || inCycle < kMs || inCycle > 4'499 * kMs;
            if (script != Script::Tumble && nearStep) {
                continue;
            }
            const Vec3d dOmega =
                (at(m, t + 100'000).omegaRadS - at(m, t - 100'000).omegaRadS) / 2e-4;
            EXPECT_LT((dOmega - s.alphaRadS2).norm(), 1e-5) << toString(script) << " at " << t;
        }
    }
}

TEST(ScriptedMotion, RestStaysStillAndLevel) {
    const ScriptedMotion m(Script::Rest, ScriptTiming{});
    const SegmentState s = at(m, 5'000 * kMs);
    EXPECT_LT((s.qWorldSegment * Vec3d::UnitZ() - Vec3d(0, 1, 0)).norm(), 1e-12);
    EXPECT_EQ(s.omegaRadS.norm(), 0.0);
    EXPECT_EQ(s.accelerationMps2.norm(), 0.0);
}

}  // namespace
}  // namespace caphub::board::sim
