// The capture heading from the knees' hinge axes: a knee turning about the segment's left axis
// as a capture heading off by d shows it, (cos d, 0, -sin d), gives d back; too little motion,
// motion about no single axis, or two knees that disagree give nothing.
#include "fusion/body/knee_heading.h"

#include <cmath>
#include <numbers>
#include <random>

#include <gtest/gtest.h>

namespace caphub::body {
namespace {

constexpr double kDeg = std::numbers::pi / 180;

// A walk's knee: the shank bending about `axis` at up to 5 rad/s, with the noise of a gyroscope
// pair (0.02 rad/s) and a little turning about the other axes (the hinge is not perfect).
void bend(KneeHeading& k, int knee, const Vec3d& axis, int samples, std::mt19937& rng,
          double wobbleRadS = 0.1) {
    std::normal_distribution<double> noise(0, 0.02);
    std::normal_distribution<double> wobble(0, wobbleRadS);
    const Vec3d other = axis.unitOrthogonal();
    for (int i = 0; i < samples; ++i) {
        const double rate = 5 * std::sin(2 * std::numbers::pi * i / 100.0);
        const Vec3d w =
            rate * axis + wobble(rng) * other + Vec3d(noise(rng), noise(rng), noise(rng));
        k.add(knee, w);
    }
}

Vec3d turnedLeftAxis(double d) {
    return {std::cos(d), 0, -std::sin(d)};
}

TEST(KneeHeading, BothKneesTurnedByTheHeadingsErrorGiveItBack) {
    std::mt19937 rng(3);
    for (const double d : {-4.0, -1.5, 0.0, 0.7, 2.5}) {
        KneeHeading k;
        bend(k, 0, turnedLeftAxis(d * kDeg), 300, rng);
        bend(k, 1, -turnedLeftAxis(d * kDeg), 300, rng);  // the sense of a turn does not matter
        ASSERT_TRUE(k.headingErrorRad()) << d;
        EXPECT_NEAR(*k.headingErrorRad(), d * kDeg, 0.05 * kDeg) << d;
    }
}

TEST(KneeHeading, NothingBeforeBothKneesHaveBentEnough) {
    std::mt19937 rng(4);
    KneeHeading k;
    bend(k, 0, turnedLeftAxis(kDeg), 300, rng);
    EXPECT_TRUE(k.kneeErrorRad(0));
    EXPECT_FALSE(k.headingErrorRad());  // the right knee has not moved
    // Standing: rates below 1 rad/s do not count, however many.
    for (int i = 0; i < 10000; ++i) {
        k.add(1, Vec3d(0.5, 0.1, 0));
    }
    EXPECT_FALSE(k.kneeErrorRad(1));
    EXPECT_FALSE(k.headingErrorRad());
    // A non-finite rate is not taken.
    k.add(1, Vec3d(std::nan(""), 3, 0));
    EXPECT_FALSE(k.kneeErrorRad(1));
    bend(k, 1, turnedLeftAxis(kDeg), 300, rng);
    ASSERT_TRUE(k.headingErrorRad());
    EXPECT_NEAR(*k.headingErrorRad(), kDeg, 0.05 * kDeg);
    k.reset();
    EXPECT_FALSE(k.headingErrorRad());
}

TEST(KneeHeading, NoSingleAxisOrKneesThatDisagreeGiveNothing) {
    std::mt19937 rng(5);
    // Turning about every axis alike (a sensor shaken, not a knee).
    KneeHeading shaken;
    std::normal_distribution<double> big(0, 3);
    for (int knee = 0; knee < 2; ++knee) {
        for (int i = 0; i < 500; ++i) {
            shaken.add(knee, Vec3d(big(rng), big(rng), big(rng)));
        }
    }
    EXPECT_FALSE(shaken.kneeErrorRad(0));
    EXPECT_FALSE(shaken.headingErrorRad());
    // Knees 6 deg apart: a strap of its own turns one of them, not the capture heading.
    KneeHeading apart;
    bend(apart, 0, turnedLeftAxis(-3 * kDeg), 300, rng);
    bend(apart, 1, turnedLeftAxis(3 * kDeg), 300, rng);
    EXPECT_TRUE(apart.kneeErrorRad(0));
    EXPECT_TRUE(apart.kneeErrorRad(1));
    EXPECT_FALSE(apart.headingErrorRad());
    // Beyond what straps' mean could turn the capture heading by.
    KneeHeading far;
    bend(far, 0, turnedLeftAxis(15 * kDeg), 300, rng);
    bend(far, 1, turnedLeftAxis(15 * kDeg), 300, rng);
    EXPECT_FALSE(far.headingErrorRad());
}

}  // namespace
}  // namespace caphub::body
