// Pose solving: sensor-driven segments, the rules for segments without a sensor, the 10-sensor
// upper body, and soft joint limits.
#include "fusion/body/pose_solver.h"

#include <numbers>
#include <random>

#include <gtest/gtest.h>

#include "tests/body/test_poses.h"

namespace caphub::body {
namespace {

using S = Segment;
constexpr double kPi = std::numbers::pi;
constexpr double kDeg = kPi / 180;

struct Rig {
    std::array<Quatd, kSegmentCount> mounting;
    PoseSolver solver;
};

Rig calibrated(SegmentMask mask, std::mt19937& rng, PoseSolverOptions options = {}) {
    Rig s{{}, PoseSolver(mask, options)};
    for (auto& q : s.mounting) {
        q = testing::randomRotation(rng, kPi);
    }
    CalibrationOptions o;
    o.headingRad = 0.7;
    auto cal = calibrateOnePose(
        ReferencePoseKind::T,
        testing::sensorsFor(testing::referencePose(ReferencePoseKind::T), s.mounting, mask, 0.7),
        o);
    EXPECT_TRUE(cal.ok());
    s.solver.setCalibration(*cal);
    return s;
}

TEST(PoseSolver, SensorDrivenSegmentsTakeTheirTrueOrientation) {
    std::mt19937 rng(31);
    Rig s = calibrated(testing::kAll, rng);
    const Pose truth = testing::randomPose(rng, 1.0);
    Pose out;
    s.solver.solve(testing::sensorsFor(truth, s.mounting, testing::kAll, 0.7), out);
    for (int i = 0; i < kSegmentCount; ++i) {
        // Exact maths on exact inputs: rounding only.
        EXPECT_LT(angleBetween(out.qWorld[static_cast<std::size_t>(i)],
                               truth.qWorld[static_cast<std::size_t>(i)]),
                  1e-9);
        EXPECT_LT(angleBetween(out.qLocal[static_cast<std::size_t>(i)],
                               truth.qLocal[static_cast<std::size_t>(i)]),
                  1e-9);
    }
}

TEST(PoseSolver, LumbarAndCervicalSegmentsSplitTheSpineRotationEvenly) {
    std::mt19937 rng(37);
    Rig s = calibrated(testing::kFullSuit, rng);
    EXPECT_EQ(s.solver.rule(S::L5), SegmentRule::SpineShare);
    EXPECT_EQ(s.solver.rule(S::C7), SegmentRule::SpineShare);
    Pose truth;
    truth.qLocal[idx(S::L5)] = Quatd(Eigen::AngleAxisd(20 * kDeg, Vec3d::UnitX()));
    truth.qLocal[idx(S::T12)] = Quatd(Eigen::AngleAxisd(20 * kDeg, Vec3d::UnitX()));
    truth.qLocal[idx(S::C7)] = Quatd(Eigen::AngleAxisd(-30 * kDeg, Vec3d::UnitY()));
    worldFromLocal(truth);
    Pose out;
    s.solver.solve(testing::sensorsFor(truth, s.mounting, testing::kFullSuit, 0.7), out);
    EXPECT_LT(angleBetween(out.qLocal[idx(S::L5)], truth.qLocal[idx(S::L5)]), 1e-9);
    EXPECT_LT(angleBetween(out.qLocal[idx(S::T12)], truth.qLocal[idx(S::T12)]), 1e-9);
    // The neck: -30 deg at vc7 and none at skullbase share as -15/-15.
    EXPECT_NEAR(angleBetween(out.qLocal[idx(S::C7)], Quatd::Identity()), 15 * kDeg, 1e-9);
    EXPECT_NEAR(angleBetween(out.qLocal[idx(S::Skull)], Quatd::Identity()), 15 * kDeg, 1e-9);
    EXPECT_LT(angleBetween(out.qWorld[idx(S::Skull)], truth.qWorld[idx(S::Skull)]), 1e-9);
}

TEST(PoseSolver, ToesFollowTheFeet) {
    std::mt19937 rng(41);
    Rig s = calibrated(testing::kFullSuit, rng);
    const Pose truth = testing::randomPose(rng, 1.0);
    Pose out;
    s.solver.solve(testing::sensorsFor(truth, s.mounting, testing::kFullSuit, 0.7), out);
    EXPECT_EQ(s.solver.rule(S::LMiddistal), SegmentRule::FollowParent);
    EXPECT_LT(angleBetween(out.qWorld[idx(S::LMiddistal)], out.qWorld[idx(S::LHindfoot)]), 1e-12);
    EXPECT_LT(angleBetween(out.qWorld[idx(S::RMiddistal)], truth.qWorld[idx(S::RHindfoot)]), 1e-9);
}

TEST(PoseSolver, UpperBodyWithTenSensorsHoldsTheLegsInTheReferencePose) {
    std::mt19937 rng(43);
    Rig s = calibrated(testing::kUpper10, rng);
    const Pose truth = testing::randomPose(rng, 1.0);
    Pose out;
    s.solver.solve(testing::sensorsFor(truth, s.mounting, testing::kUpper10, 0.7), out);
    for (S seg : {S::LThigh, S::LCalf, S::RHindfoot, S::RMiddistal, S::LClavicle}) {
        EXPECT_LT(angleBetween(out.qLocal[idx(seg)], Quatd::Identity()), 1e-12);
    }
    for (S seg : {S::Pelvis, S::L5, S::T12, S::LForearm, S::RHand}) {
        EXPECT_LT(angleBetween(out.qWorld[idx(seg)], truth.qWorld[idx(seg)]), 1e-9);
    }
    // The neck shares the rotation between the chest and the head.
    EXPECT_EQ(s.solver.rule(S::C7), SegmentRule::SpineShare);
}

// The 7-sensor lower body (pelvis, thighs, shanks, feet).
constexpr SegmentMask kLower7 = bit(S::Pelvis) | bit(S::LThigh) | bit(S::LCalf) |
                                bit(S::LHindfoot) | bit(S::RThigh) | bit(S::RCalf) |
                                bit(S::RHindfoot);

SegmentMask maskOf(std::initializer_list<S> segments) {
    SegmentMask m = 0;
    for (S s : segments) {
        m |= bit(s);
    }
    return m;
}

TEST(PoseSolver, LowerBodyWithSevenSensorsHoldsTheUpperBodyOnThePelvis) {
    std::mt19937 rng(47);
    Rig s = calibrated(kLower7, rng);
    const Pose truth = testing::randomPose(rng, 1.0);
    Pose out;
    s.solver.solve(testing::sensorsFor(truth, s.mounting, kLower7, 0.7), out);
    // The trunk, head and arms follow the pelvis in the neutral standing pose: the trunk and
    // head straight over it (each joint the identity), the arms hanging (the N-pose's arms).
    for (S seg : {S::L5, S::T12, S::C7, S::Skull, S::LClavicle, S::RClavicle}) {
        EXPECT_EQ(s.solver.rule(seg), SegmentRule::FollowParent);
        EXPECT_LT(angleBetween(out.qLocal[idx(seg)], Quatd::Identity()), 1e-12);
    }
    for (S seg : {S::LUpperarm, S::LForearm, S::RHand}) {
        EXPECT_EQ(s.solver.rule(seg), SegmentRule::FollowParent);
        const Quatd hanging =
            truth.qWorld[idx(S::Pelvis)] * referenceOrientation(ReferencePoseKind::N, seg);
        EXPECT_LT(angleBetween(out.qWorld[idx(seg)], hanging), 1e-9);
    }
    // Hanging: the upper arm's long axis (+-X in the T-pose) points down the pelvis' -Y.
    const Vec3d down = truth.qWorld[idx(S::Pelvis)] * Vec3d(0, -1, 0);
    EXPECT_NEAR((out.qWorld[idx(S::LUpperarm)] * Vec3d::UnitX()).dot(down), 1.0, 1e-9);
    EXPECT_LT(angleBetween(out.qWorld[idx(S::T12)], truth.qWorld[idx(S::Pelvis)]), 1e-9);
    for (S seg : {S::Pelvis, S::LThigh, S::LCalf, S::RHindfoot}) {
        EXPECT_LT(angleBetween(out.qWorld[idx(seg)], truth.qWorld[idx(seg)]), 1e-9);
    }
}

TEST(PoseSolver, SegmentsOfALimbOrTrunkWithoutSensorsAreNotMeasured) {
    // The full suit measures everything: the lumbar and cervical segments share the spine's
    // rotation between sensors, the toes follow their foot.
    EXPECT_EQ(PoseSolver(testing::kFullSuit).coveredSegments(), testing::kAll);
    // The upper body: the legs are held, not measured; the clavicles (under an upper-arm
    // sensor) and the neck (between the chest and the head) are.
    const SegmentMask legs = maskOf({S::LThigh, S::LCalf, S::LHindfoot, S::LMiddistal, S::RThigh,
                                     S::RCalf, S::RHindfoot, S::RMiddistal});
    EXPECT_EQ(PoseSolver(testing::kUpper10).coveredSegments(), testing::kAll & ~legs);
    // The lower body: the trunk above the pelvis, the head and the arms are held.
    const SegmentMask upper =
        maskOf({S::L5, S::T12, S::C7, S::Skull, S::LClavicle, S::LUpperarm, S::LForearm, S::LHand,
                S::RClavicle, S::RUpperarm, S::RForearm, S::RHand});
    EXPECT_EQ(PoseSolver(kLower7).coveredSegments(), testing::kAll & ~upper);
    // A hand without a sensor follows a forearm that has one (an end segment, as the toes); an
    // arm whose only sensor is on the hand is not measured above it (three links missing).
    const SegmentMask noHands = testing::kFullSuit & ~maskOf({S::LHand, S::RHand});
    EXPECT_EQ(PoseSolver(noHands).coveredSegments(), testing::kAll);
    const SegmentMask handOnly = kLower7 | bit(S::T12) | bit(S::LHand);
    const SegmentMask covered = PoseSolver(handOnly).coveredSegments();
    EXPECT_TRUE(has(covered, idx(S::LHand)));
    EXPECT_FALSE(has(covered, idx(S::LForearm)));
    EXPECT_FALSE(has(covered, idx(S::LUpperarm)));
    EXPECT_FALSE(has(covered, idx(S::LClavicle)));
    EXPECT_TRUE(has(covered, idx(S::L5)));  // between the pelvis and the chest
    // What is valid in a pose is never more than what is covered, even with every sensor there.
    EXPECT_EQ(PoseSolver(kLower7).validSegments(kLower7), PoseSolver(kLower7).coveredSegments());
    EXPECT_EQ(PoseSolver(testing::kUpper10).validSegments(testing::kUpper10),
              testing::kAll & ~legs);
    // A sensor out takes its followers with it, as before.
    const SegmentMask noLeftThigh = PoseSolver(kLower7).validSegments(kLower7 & ~bit(S::LThigh));
    EXPECT_FALSE(has(noLeftThigh, idx(S::LThigh)));
    EXPECT_TRUE(has(noLeftThigh, idx(S::LCalf)));
}

TEST(PoseSolver, LimitViolationsAreReportedButNotAppliedByDefault) {
    std::mt19937 rng(47);
    Rig s = calibrated(testing::kAll, rng);
    Pose truth;
    truth.qLocal[idx(S::LCalf)] = Quatd(Eigen::AngleAxisd(-40 * kDeg, Vec3d::UnitX()));  // knee
    worldFromLocal(truth);  // hyperextended
    Pose out;
    JointLimitReport rep;
    s.solver.solve(testing::sensorsFor(truth, s.mounting, testing::kAll, 0.7), out, &rep);
    EXPECT_EQ(rep.violations, 1);
    EXPECT_NEAR(rep.excessDeg[idx(S::LCalf)], 35.0, 1e-6);  // limit -5 deg
    EXPECT_LT(angleBetween(out.qLocal[idx(S::LCalf)], truth.qLocal[idx(S::LCalf)]), 1e-9);
}

TEST(PoseSolver, ClampingPutsTheJointOnItsLimit) {
    std::mt19937 rng(53);
    PoseSolverOptions opt;
    opt.clampToLimits = true;
    Rig s = calibrated(testing::kAll, rng, opt);
    Pose truth;
    truth.qLocal[idx(S::LCalf)] = Quatd(Eigen::AngleAxisd(-40 * kDeg, Vec3d::UnitX()));
    worldFromLocal(truth);
    Pose out;
    JointLimitReport rep;
    s.solver.solve(testing::sensorsFor(truth, s.mounting, testing::kAll, 0.7), out, &rep);
    EXPECT_NEAR(angleBetween(out.qLocal[idx(S::LCalf)], Quatd::Identity()), 5 * kDeg, 1e-9);
    EXPECT_LT(angleBetween(out.qWorld[idx(S::LCalf)],
                           out.qWorld[idx(S::LThigh)] * out.qLocal[idx(S::LCalf)]),
              1e-12);
}

}  // namespace
}  // namespace caphub::body
