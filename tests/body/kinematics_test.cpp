// Forward kinematics against hand-computed positions, the spatial Jacobian against finite
// differences of FK, and the rotation paths near 0 and pi.
#include "fusion/body/kinematics.h"

#include <numbers>
#include <random>

#include <gtest/gtest.h>

#include "fusion/body/pose_solver.h"
#include "tests/body/test_poses.h"

namespace caphub::body {
namespace {

using S = Segment;
constexpr double kPi = std::numbers::pi;

Dimensions dims() {
    board::SubjectConfig s;
    s.heightM = 1.75;
    return *dimensionsFromSubject(s);
}

Quatd rot(const Vec3d& axis, double deg) {
    return Quatd(Eigen::AngleAxisd(deg * kPi / 180, axis.normalized()));
}

TEST(ForwardKinematics, ReferencePoseAddsTheOffsets) {
    const Dimensions d = dims();
    Pose p;
    forwardKinematics(d, Vec3d(1, 0, 2), p);
    const double h = 1.75;
    // Left wrist: root + l5 + t12 + clavicle + shoulder + upper arm + forearm, by hand:
    // x = 0.015 + (0.1295 - 0.015) + 0.186 + 0.146 = 0.4615 H; y = 0.818 - 0.530 = 0.288 H
    // above the root (the root is placed at y = 0 here, not at its standing height).
    EXPECT_NEAR(p.position(S::LHand).x(), 1 + 0.4615 * h, 1e-12);
    EXPECT_NEAR(p.position(S::LHand).y(), 0.288 * h, 1e-12);
    EXPECT_NEAR(p.position(S::LHand).z(), 2, 1e-12);
    // Right ankle: 0.039 H above the floor, the root at 0.530 H.
    EXPECT_NEAR(p.position(S::RHindfoot).y(), (0.039 - 0.530) * h, 1e-12);
}

TEST(ForwardKinematics, BentElbowPutsTheWristInFrontOfTheElbow) {
    const Dimensions d = dims();
    Pose p;
    p.qLocal[idx(S::LForearm)] = rot(Vec3d::UnitY(), -90);  // left elbow flexion
    worldFromLocal(p);
    forwardKinematics(d, Vec3d::Zero(), p);
    const Vec3d elbow = p.position(S::LForearm);
    const Vec3d wrist = p.position(S::LHand);
    // The forearm (0.146 H along +X) turns to +Z (forward).
    EXPECT_NEAR((wrist - elbow - Vec3d(0, 0, 0.146 * 1.75)).norm(), 0, 1e-12);
}

TEST(ForwardKinematics, HipFlexedNinetyDegreesPutsTheKneeForwardAtHipHeight) {
    const Dimensions d = dims();
    Pose p;
    p.qLocal[idx(S::RThigh)] = rot(Vec3d::UnitX(), -90);
    p.qLocal[idx(S::RCalf)] = rot(Vec3d::UnitX(), 90);  // shank vertical again
    worldFromLocal(p);
    forwardKinematics(d, Vec3d::Zero(), p);
    const Vec3d hip = p.position(S::RThigh);
    EXPECT_NEAR((p.position(S::RCalf) - hip - Vec3d(0, 0, 0.245 * 1.75)).norm(), 0, 1e-12);
    EXPECT_NEAR(
        (p.position(S::RHindfoot) - p.position(S::RCalf) - Vec3d(0, -0.246 * 1.75, 0)).norm(), 0,
        1e-12);
}

TEST(ForwardKinematics, PelvisTurnCarriesTheWholeBody) {
    const Dimensions d = dims();
    Pose p;
    p.qLocal[0] = rot(Vec3d::UnitY(), 90);  // facing +X (the subject's former left)
    worldFromLocal(p);
    forwardKinematics(d, Vec3d::Zero(), p);
    // The left hand at +X 0.4615 H turns to -Z.
    EXPECT_NEAR(p.position(S::LHand).z(), -0.4615 * 1.75, 1e-12);
    EXPECT_NEAR(p.position(S::LHand).x(), 0, 1e-12);
}

// Moves the joint of column c (after the 3 root translation columns) by a small body-frame
// rotation, or the root by a small translation, and returns the end point.
Vec3d perturbed(const Dimensions& d, const Skeleton& sk, Pose p, const ChainJacobian& jac,
                EndEffector e, int column, double h) {
    Vec3d root = Vec3d::Zero();
    if (column < 3) {
        root[column] = h;
    } else {
        const int k = (column - 3) / 3;
        const auto seg = static_cast<std::size_t>(jac.segments[static_cast<std::size_t>(k)]);
        Vec3d rv = Vec3d::Zero();
        rv[(column - 3) % 3] = h;
        p.qLocal[seg] = p.qLocal[seg] * fromRotationVector<double>(rv);
    }
    worldFromLocal(p);
    forwardKinematics(d, root, p);
    return pointOnSegment(p, idx(endEffectorSegment(e)), sk.endSiteM(e));
}

TEST(SpatialJacobian, MatchesFiniteDifferencesOfForwardKinematicsOnRandomPoses) {
    const Dimensions d = dims();
    const Skeleton sk(d);
    std::mt19937 rng(7);
    for (int trial = 0; trial < 20; ++trial) {
        Pose p = testing::randomPose(rng, kPi);
        forwardKinematics(d, Vec3d::Zero(), p);
        for (int e = 0; e < kEndEffectorCount; ++e) {
            const auto ee = static_cast<EndEffector>(e);
            ChainJacobian jac;
            spatialJacobian(sk, p, ee, jac);
            const int columns = 3 + 3 * jac.jointCount;
            for (int c = 0; c < columns; ++c) {
                // Central difference with h = 1e-6: truncation O(h^2 |p|) ~ 1e-12 m, rounding
                // ~ 1e-16 / 1e-6 = 1e-10; 1e-7 leaves margin and still catches a wrong sign,
                // axis or lever arm (those are O(0.1-1)).
                const double h = 1e-6;
                const Vec3d fd =
                    (perturbed(d, sk, p, jac, ee, c, h) - perturbed(d, sk, p, jac, ee, c, -h)) /
                    (2 * h);
                EXPECT_LT((fd - jac.j.block<3, 1>(0, c)).norm(), 1e-7)
                    << "trial " << trial << " end " << endEffectorName(ee) << " column " << c;
            }
        }
    }
}

TEST(SpatialJacobian, TwistEqualsTheRateOfChangeOfTheEndPoint) {
    const Dimensions d = dims();
    const Skeleton sk(d);
    std::mt19937 rng(11);
    std::normal_distribution<double> n(0, 2.0);
    const Pose base = testing::randomPose(rng, 1.5);
    JointRates rates;
    for (auto& r : rates) {
        r = Vec3d(n(rng), n(rng), n(rng));
    }
    const Vec3d rootVel(0.3, -0.1, 1.2);
    auto at = [&](double t, Pose& p) {
        p = base;
        for (int i = 0; i < kSegmentCount; ++i) {
            const auto u = static_cast<std::size_t>(i);
            p.qLocal[u] = base.qLocal[u] * fromRotationVector<double>(rates[u] * t);
        }
        worldFromLocal(p);
        forwardKinematics(d, rootVel * t, p);
    };
    Pose p0;
    at(0, p0);
    for (int e = 0; e < kEndEffectorCount; ++e) {
        const auto ee = static_cast<EndEffector>(e);
        ChainJacobian jac;
        spatialJacobian(sk, p0, ee, jac);
        const Twist tw = endEffectorTwist(jac, rootVel, rates);
        const double h = 1e-6;
        Pose pp;
        Pose pm;
        at(h, pp);
        at(-h, pm);
        const int s = idx(endEffectorSegment(ee));
        const Vec3d v =
            (pointOnSegment(pp, s, sk.endSiteM(ee)) - pointOnSegment(pm, s, sk.endSiteM(ee))) /
            (2 * h);
        // Same error budget as above, scaled by rates of a few rad/s: 1e-6 m/s.
        EXPECT_LT((v - tw.head<3>()).norm(), 1e-6) << endEffectorName(ee);
        // Angular part: the end segment's world angular velocity.
        const Quatd dq = pm.qWorld[static_cast<std::size_t>(s)].conjugate() *
                         pp.qWorld[static_cast<std::size_t>(s)];
        const Vec3d wWorld =
            p0.qWorld[static_cast<std::size_t>(s)] * (toRotationVector(dq) / (2 * h));
        EXPECT_LT((wWorld - tw.tail<3>()).norm(), 1e-6) << endEffectorName(ee);
    }
}

TEST(JointRates, TinyRotationsKeepFullRelativePrecision) {
    Pose a;
    Pose b;
    const Vec3d w(1e-9, -2e-9, 3e-9);  // rad/s over 1 s: far below acos precision
    b.qLocal[idx(S::LForearm)] = fromRotationVector<double>(w);
    JointRates r;
    jointRates(a, b, 1.0, r);
    EXPECT_LT((r[idx(S::LForearm)] - w).norm(), 1e-12 * w.norm());
    EXPECT_EQ(r[idx(S::RForearm)].norm(), 0.0);
}

TEST(JointRates, RotationsNearHalfATurnStayFiniteAndOnTheShortPath) {
    Pose a;
    Pose b;
    const double angle = kPi - 1e-9;
    b.qLocal[idx(S::LThigh)] = fromAxisAngle<double>(Vec3d::UnitZ(), angle);
    JointRates r;
    jointRates(a, b, 0.5, r);
    // 1e-8 relative: the atan2 path keeps full precision; acos would lose ~1e-8 here.
    EXPECT_NEAR(r[idx(S::LThigh)].norm(), angle / 0.5, 1e-8);
    EXPECT_NEAR(std::abs(r[idx(S::LThigh)].normalized().z()), 1.0, 1e-12);
}

TEST(JointLimits, RotationNearHalfATurnIsReportedAndClampedToAUnitQuaternion) {
    Quatd q = fromAxisAngle<double>(Vec3d::UnitY(), kPi - 1e-7);
    const double excess = applyJointLimits(jointInfo(S::LCalf).limits, q, true);
    // Knee Y range is +-30 deg: the excess is 180 - 30 deg up to the 1e-7 rad offset.
    EXPECT_NEAR(excess, 150.0, 1e-4);
    EXPECT_NEAR(q.norm(), 1.0, 1e-12);
    EXPECT_NEAR(angleBetween(q, fromAxisAngle<double>(Vec3d::UnitY(), 30 * kPi / 180)), 0, 1e-9);
}

// The excess straight from the rotation vector, as the limits define it.
double exactExcessDeg(const JointLimits& limits, const Quatd& q) {
    const Vec3d rvDeg = toRotationVector(q) * (180 / kPi);
    return (rvDeg - rvDeg.cwiseMax(limits.minDeg).cwiseMin(limits.maxDeg)).norm();
}

TEST(JointLimits, TheQuickInsideTestAgreesWithTheRotationVectorEverywhere) {
    // applyJointLimits skips the logarithm when a bound of the rotation vector lies inside the
    // limits. Random rotations of every size on every joint, and rotations placed on each
    // limit and 1e-6 deg either side of it: the excess is the exact one, zero exactly when the
    // rotation vector is inside.
    std::mt19937 rng(71);
    std::normal_distribution<double> n(0, 1);
    std::uniform_real_distribution<double> angle(0, kPi);
    int inside = 0;
    int outside = 0;
    for (const auto& j : joints()) {
        for (int k = 0; k < 2000; ++k) {
            const Vec3d axis = Vec3d(n(rng), n(rng), n(rng)).normalized();
            Quatd q = fromAxisAngle<double>(axis, k % 2 == 0 ? angle(rng) : 0.3 * angle(rng));
            const double exact = exactExcessDeg(j.limits, q);
            EXPECT_NEAR(applyJointLimits(j.limits, q, false), exact, 1e-9) << j.name;
            (exact == 0 ? inside : outside) += 1;
        }
        for (int axis = 0; axis < 3; ++axis) {
            for (double edge : {j.limits.minDeg[axis], j.limits.maxDeg[axis]}) {
                for (double off : {-1e-6, 0.0, 1e-6}) {
                    if (std::abs(edge) >= 180) {
                        continue;
                    }
                    Vec3d rvDeg = 0.5 * (j.limits.minDeg + j.limits.maxDeg);
                    rvDeg[axis] = edge + off;
                    Quatd q = fromRotationVector<double>(rvDeg * (kPi / 180));
                    const double exact = exactExcessDeg(j.limits, q);
                    const double got = applyJointLimits(j.limits, q, false);
                    EXPECT_NEAR(got, exact, 1e-9) << j.name << ' ' << axis << ' ' << edge;
                    if (off != 0.0) {  // on the edge itself rounding may put it either side
                        EXPECT_EQ(got == 0, exact == 0) << j.name << ' ' << axis << ' ' << edge;
                    }
                }
            }
        }
    }
    EXPECT_GT(inside, 1000);  // both paths were taken many times
    EXPECT_GT(outside, 1000);
}

TEST(JointLimits, IdentityIsInsideEveryLimit) {
    for (const auto& j : joints()) {
        Quatd q = Quatd::Identity();
        EXPECT_EQ(applyJointLimits(j.limits, q, false), 0.0) << j.name;
    }
}

}  // namespace
}  // namespace caphub::body
