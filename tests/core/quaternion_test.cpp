// The paper's quaternion -> axis-angle conversion (eqs. 1-6) and the helpers around it,
// including the edge cases the paper's formulas get wrong: theta = 0, w near +-1, q vs -q.
#include "hal/core/quaternion.h"

#include <cmath>
#include <limits>
#include <random>

#include <gtest/gtest.h>

namespace caphub {
namespace {

constexpr double kPi = 3.14159265358979323846;

TEST(QuaternionNorm, IsEquationOne) {
    const Quatd q(1, 2, 3, 4);
    EXPECT_DOUBLE_EQ(quatNorm(q), std::sqrt(30.0));
}

TEST(QuaternionNorm, NormalizingAZeroQuaternionGivesIdentity) {
    const Quatd q = normalizedOrIdentity(Quatd(0, 0, 0, 0));
    EXPECT_EQ(q.coeffs(), Quatd::Identity().coeffs());
}

TEST(QuaternionNorm, NormalizingANonFiniteQuaternionGivesIdentity) {
    const double nan = std::numeric_limits<double>::quiet_NaN();
    EXPECT_EQ(normalizedOrIdentity(Quatd(nan, 0, 0, 1)).coeffs(), Quatd::Identity().coeffs());
}

TEST(AxisAngle, RecoversAKnownRotation) {
    const Vec3d axis = Vec3d(1, -2, 0.5).normalized();
    const auto aa = toAxisAngle(fromAxisAngle(axis, 1.2));
    EXPECT_NEAR(aa.angle, 1.2, 1e-15);
    EXPECT_LT((aa.axis - axis).norm(), 1e-15);
}

TEST(AxisAngle, NormalizesItsInputFirst) {
    const Vec3d axis = Vec3d(0, 1, 0);
    Quatd q = fromAxisAngle(axis, 0.7);
    q.coeffs() *= 3.5;
    const auto aa = toAxisAngle(q);
    EXPECT_NEAR(aa.angle, 0.7, 1e-15);
    EXPECT_LT((aa.axis - axis).norm(), 1e-15);
}

TEST(AxisAngle, IdentityIsZeroAngleWithAFiniteUnitAxis) {
    const auto aa = toAxisAngle(Quatd::Identity());
    EXPECT_EQ(aa.angle, 0.0);
    EXPECT_TRUE(aa.axis.allFinite());
    EXPECT_DOUBLE_EQ(aa.axis.norm(), 1.0);
}

TEST(AxisAngle, MinusIdentityIsAlsoZeroAngle) {
    const auto aa = toAxisAngle(Quatd(-1, 0, 0, 0));
    EXPECT_EQ(aa.angle, 0.0);
    EXPECT_TRUE(aa.axis.allFinite());
}

// Near w = 1 acos(w) has lost all information: for theta = 1e-9, w rounds to exactly 1 and
// the paper's eq. (3) gives 0. The atan2 form keeps full relative precision.
TEST(AxisAngle, TinyAnglesKeepFullRelativePrecision) {
    for (double theta : {1e-3, 1e-6, 1e-9, 1e-12, 1e-200}) {
        const Vec3d axis = Vec3d(0.3, 0.4, -0.5).normalized();
        const auto aa = toAxisAngle(fromAxisAngle(axis, theta));
        EXPECT_NEAR(aa.angle / theta, 1.0, 1e-14) << "theta " << theta;
        EXPECT_LT((aa.axis - axis).norm(), 1e-14) << "theta " << theta;
    }
}

TEST(AxisAngle, PaperFormulaWouldLosePrecisionWhereThisDoesNot) {
    const double theta = 1e-9;
    const Quatd q = fromAxisAngle(Vec3d(0, 0, 1), theta);
    ASSERT_EQ(q.w(), 1.0);  // w has rounded to 1: acos(w) = 0
    EXPECT_EQ(2 * std::acos(q.w()), 0.0);
    EXPECT_NEAR(toAxisAngle(q).angle, theta, 1e-24);
}

// Near theta = pi (w near 0) and for angles in (pi, 2pi) the canonical form keeps the angle in
// [0, pi] and flips the axis instead.
TEST(AxisAngle, AnglesAbovePiComeBackAsTheShorterRotation) {
    const Vec3d axis = Vec3d(1, 1, 0).normalized();
    const auto aa = toAxisAngle(fromAxisAngle(axis, 1.5 * kPi));
    EXPECT_NEAR(aa.angle, 0.5 * kPi, 1e-14);
    EXPECT_LT((aa.axis + axis).norm(), 1e-14);
}

TEST(AxisAngle, HalfTurnIsPi) {
    const auto aa = toAxisAngle(Quatd(0, 0, 1, 0));
    EXPECT_DOUBLE_EQ(aa.angle, kPi);
    EXPECT_LT((aa.axis - Vec3d::UnitY()).norm(), 1e-15);
}

TEST(AxisAngle, QAndMinusQGiveTheSameRotation) {
    std::mt19937 rng(7);
    std::normal_distribution<double> n;
    for (int i = 0; i < 1000; ++i) {
        const Quatd q = Quatd(n(rng), n(rng), n(rng), n(rng)).normalized();
        const Quatd mq(-q.coeffs());
        const auto a = toAxisAngle(q);
        const auto b = toAxisAngle(mq);
        EXPECT_NEAR(a.angle, b.angle, 1e-15);
        EXPECT_LT((a.axis - b.axis).norm(), 1e-12);
        // And it is the rotation q describes.
        const Vec3d v(0.2, -1, 3);
        const Vec3d rotated = Eigen::AngleAxisd(a.angle, a.axis) * v;
        EXPECT_LT((rotated - q * v).norm(), 1e-12);
    }
}

TEST(RotationVector, RoundTripsOverTheWholeRange) {
    std::mt19937 rng(11);
    std::uniform_real_distribution<double> u(-1, 1);
    for (int i = 0; i < 1000; ++i) {
        Vec3d rv(u(rng), u(rng), u(rng));
        rv *= (kPi - 1e-6) * std::abs(u(rng)) / rv.norm();
        const Vec3d back = toRotationVector(fromRotationVector(rv));
        EXPECT_LT((back - rv).norm(), 1e-12 * std::max(1.0, rv.norm())) << rv.transpose();
    }
}

TEST(RotationVector, TinyVectorsRoundTripWithRelativePrecision) {
    for (double s : {1e-5, 1e-8, 1e-12, 1e-300}) {
        const Vec3d rv = Vec3d(1, -2, 3).normalized() * s;
        const Vec3d back = toRotationVector(fromRotationVector(rv));
        EXPECT_LT((back - rv).norm() / s, 1e-14) << s;
    }
}

TEST(RotationVector, BothSidesOfTheSeriesSwitchAreExact) {
    // Either side of the 1e-4 switch, sin(theta/2)/theta must match its Taylor series
    // 1/2 - theta^2/48 + theta^4/3840 to rounding (the next term is ~1e-24 here).
    for (double theta : {0.99999e-4, 1.00001e-4}) {
        const Quatd q = fromRotationVector(Vec3d(0, 0, theta));
        const double k = 0.5 - theta * theta / 48 + theta * theta * theta * theta / 3840;
        EXPECT_NEAR(q.z() / theta, k, 2e-16) << theta;
        EXPECT_DOUBLE_EQ(toRotationVector(q).z(), theta) << theta;
    }
}

TEST(Canonical, PicksNonNegativeW) {
    EXPECT_GE(canonical(Quatd(-0.5, 0.5, 0.5, 0.5)).w(), 0.0);
    // At w = 0 the first non-zero vector component decides.
    const Quatd c = canonical(Quatd(0, 0, -1, 0));
    EXPECT_EQ(c.y(), 1.0);
}

TEST(AngleBetween, TreatsQAndMinusQAsEqual) {
    const Quatd q = fromAxisAngle(Vec3d(0, 1, 0), 0.3);
    EXPECT_NEAR(angleBetween(q, Quatd(-q.coeffs())), 0.0, 1e-15);
    EXPECT_NEAR(angleBetween(Quatd::Identity(), q), 0.3, 1e-15);
}

TEST(IntegrateBodyRate, ConstantRateForOneSecondTurnsByTheRate) {
    Quatd q = Quatd::Identity();
    const Vec3d omega(0, 0, 0.5);  // rad/s about z
    for (int i = 0; i < 1000; ++i) {
        q = integrateBodyRate(q, omega, 1e-3);
    }
    const auto aa = toAxisAngle(q);
    EXPECT_NEAR(aa.angle, 0.5, 1e-12);
    EXPECT_LT((aa.axis - Vec3d::UnitZ()).norm(), 1e-12);
}

TEST(Wxyz, IsWFirst) {
    const Quatd q = fromWxyz<double>({0.5, 0.1, 0.2, 0.3});
    EXPECT_EQ(q.w(), 0.5);
    EXPECT_EQ(q.x(), 0.1);
    const auto a = toWxyz(q);
    EXPECT_EQ(a[0], 0.5);
    EXPECT_EQ(a[3], 0.3);
}

TEST(EulerIntrinsic, ComposesInTheGivenOrder) {
    Quatd q;
    ASSERT_TRUE(fromEulerIntrinsic("ZXY", Vec3d(0.1, 0.2, 0.3), q));
    const Quatd expected = Quatd(Eigen::AngleAxisd(0.1, Vec3d::UnitZ())) *
                           Quatd(Eigen::AngleAxisd(0.2, Vec3d::UnitX())) *
                           Quatd(Eigen::AngleAxisd(0.3, Vec3d::UnitY()));
    EXPECT_NEAR(angleBetween(q, expected), 0.0, 1e-15);
}

TEST(EulerIntrinsic, RejectsBadAxes) {
    Quatd q;
    EXPECT_FALSE(fromEulerIntrinsic("ZQY", Vec3d::Zero(), q));
    EXPECT_FALSE(fromEulerIntrinsic("ZX", Vec3d::Zero(), q));
}

}  // namespace
}  // namespace caphub
