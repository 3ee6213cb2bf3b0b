// The relative heading of two sensors from their joint's acceleration: the angle between the two
// sides' horizontal accelerations once the joint has moved enough, nothing while it is still or
// the two sides disagree, sides sampled at different instants, and turns carried into the sums.
#include "fusion/body/joint_heading.h"

#include <cmath>
#include <limits>
#include <numbers>

#include <gtest/gtest.h>

namespace caphub::body {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;
constexpr double kG = 9.81;

Vec3d turnedAboutUp(const Vec3d& v, double angleRad) {
    return Quatd(Eigen::AngleAxisd(angleRad, Vec3d::UnitZ())) * v;
}

// A joint swinging in a horizontal ellipse at 1.8 Hz (as a walking elbow's path turns), plus
// gravity's specific force: the joint's specific force at tS (ENU).
Vec3d jointForce(double tS) {
    const double w = 2 * std::numbers::pi * 1.8;
    return Vec3d(2.5 * std::cos(w * tS), 1.2 * std::sin(w * tS), kG + 0.8 * std::sin(2 * w * tS));
}

// Both sides at 100 Hz for seconds from startS, the child's orientations turned by
// childTurnRad about up against the parent's, the child sampled lagS after the parent.
void feed(JointHeading& j, double startS, double seconds, double childTurnRad, double lagS = 0.0) {
    for (int k = 0; k < static_cast<int>(seconds * 100); ++k) {
        const double t = startS + k * 0.01;
        j.add(JointHeading::Parent, t, jointForce(t));
        j.add(JointHeading::Child, t + lagS, turnedAboutUp(jointForce(t + lagS), childTurnRad));
    }
}

TEST(JointHeading, FindsTheChildsHeadingAgainstTheParentsOnceTheJointHasMoved) {
    JointHeading j;
    feed(j, 0.0, 0.2, 7.0 * kDeg);
    EXPECT_FALSE(j.angleRad().has_value()) << "too little motion: energy " << j.energy();
    feed(j, 0.2, 1.0, 7.0 * kDeg);
    ASSERT_TRUE(j.angleRad().has_value()) << "energy " << j.energy();
    EXPECT_NEAR(*j.angleRad() / kDeg, 7.0, 0.05);
    EXPECT_GT(j.consistency(), 0.999);
    EXPECT_EQ(j.mismatched(), 0);
}

TEST(JointHeading, AStillJointTellsNothing) {
    JointHeading j;
    for (int k = 0; k < 1000; ++k) {
        const double t = k * 0.01;
        j.add(JointHeading::Parent, t, Vec3d(0.01, -0.02, kG));
        j.add(JointHeading::Child, t, Vec3d(-0.02, 0.01, kG));
    }
    EXPECT_FALSE(j.angleRad().has_value()) << "energy " << j.energy();
}

// Two buses sample at instants of their own: the child 6 ms after the parent. The path turns by
// about 4 deg in 6 ms, which the parent's latest would read as a turn of the heading.
TEST(JointHeading, SidesSampledAtDifferentInstantsAreComparedAtOneTime) {
    JointHeading j;
    feed(j, 0.0, 3.0, -4.0 * kDeg, 0.006);
    ASSERT_TRUE(j.angleRad().has_value());
    EXPECT_NEAR(*j.angleRad() / kDeg, -4.0, 0.3);
}

// The two sides are not one acceleration (a vertical part 3 m/s^2 apart): left out, counted.
TEST(JointHeading, PairsThatAreNotOneAccelerationAreLeftOut) {
    JointHeading j;
    for (int k = 0; k < 300; ++k) {
        const double t = k * 0.01;
        j.add(JointHeading::Parent, t, jointForce(t));
        j.add(JointHeading::Child, t, jointForce(t) + Vec3d(0, 0, 3.0));
    }
    EXPECT_FALSE(j.angleRad().has_value());
    EXPECT_EQ(j.pairs(), 0);
    EXPECT_GT(j.mismatched(), 250);
    // An impact's spike (beyond 30 m/s^2) is left out too.
    JointHeading k;
    k.add(JointHeading::Parent, 0.0, Vec3d(40, 0, kG));
    k.add(JointHeading::Child, 0.0, Vec3d(40, 0, kG));
    EXPECT_EQ(k.mismatched(), 1);
}

// A side turned (its heading corrected): the sums turn with it, and what comes after agrees.
TEST(JointHeading, ATurnedSideTurnsTheAngle) {
    JointHeading j;
    feed(j, 0.0, 2.0, 7.0 * kDeg);
    ASSERT_TRUE(j.angleRad().has_value());
    j.turn(JointHeading::Child, -7.0 * kDeg);  // the child corrected onto the parent
    ASSERT_TRUE(j.angleRad().has_value());
    EXPECT_NEAR(*j.angleRad() / kDeg, 0.0, 0.05);
    feed(j, 2.0, 2.0, 0.0);  // ... and its orientations come turned from now on
    EXPECT_NEAR(*j.angleRad() / kDeg, 0.0, 0.05);
    j.turn(JointHeading::Parent, 3.0 * kDeg);
    EXPECT_NEAR(*j.angleRad() / kDeg, -3.0, 0.05);
    j.reset();
    EXPECT_FALSE(j.angleRad().has_value());
    EXPECT_EQ(j.energy(), 0.0);
}

TEST(JointHeading, NonFiniteSamplesAreIgnored) {
    JointHeading j;
    const double nan = std::numeric_limits<double>::quiet_NaN();
    j.add(JointHeading::Parent, 0.0, Vec3d(nan, 0, kG));
    j.add(JointHeading::Child, nan, Vec3d(1, 0, kG));
    feed(j, 0.0, 2.0, 5.0 * kDeg);
    ASSERT_TRUE(j.angleRad().has_value());
    EXPECT_TRUE(std::isfinite(*j.angleRad()));
    EXPECT_NEAR(*j.angleRad() / kDeg, 5.0, 0.05);
}

}  // namespace
}  // namespace caphub::body
