// The suit's vote on its first raw magnetometer readings: sensors reading one earth field are
// trusted, offsets that happen to give a field of the earth's size are not, a suit with no
// majority trusts none, and late or missing sensors are handled by the window.
#include "fusion/calibration/field_vote.h"

#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <vector>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

namespace caphub::fusion {
namespace {

constexpr double kDeg = 0.017453292519943295;

// The earth's field in ENU (uT): 50 uT, 60 deg dip.
Eigen::Vector3d earthField() {
    return {0.0, 50.0 * std::cos(60 * kDeg), -50.0 * std::sin(60 * kDeg)};
}

struct Reading {
    double normUt;
    double angleToUpRad;
};

// A first reading of a sensor in a random orientation with offset h (sensor frame, uT), soft
// iron of about softIron per element and noise: its magnitude and angle to the sensor's up.
Reading firstReading(std::mt19937& rng, const Eigen::Vector3d& h, double softIron) {
    std::normal_distribution<double> n(0.0, 1.0);
    const Eigen::Quaterniond q = Eigen::Quaterniond(n(rng), n(rng), n(rng), n(rng)).normalized();
    Eigen::Matrix3d s = Eigen::Matrix3d::Identity();
    for (int r = 0; r < 3; ++r) {
        for (int c = r; c < 3; ++c) {
            s(r, c) += softIron * n(rng);
            s(c, r) = s(r, c);
        }
    }
    const Eigen::Vector3d up = q.conjugate() * Eigen::Vector3d::UnitZ();
    const Eigen::Vector3d m =
        s * (q.conjugate() * earthField()) + h + 0.3 * Eigen::Vector3d(n(rng), n(rng), n(rng));
    return {m.norm(), std::acos(m.dot(up) / m.norm())};
}

Eigen::Vector3d randomDirection(std::mt19937& rng) {
    std::normal_distribution<double> n(0.0, 1.0);
    return Eigen::Vector3d(n(rng), n(rng), n(rng)).normalized();
}

// An offset up to maxUt in a random direction, its size uniform.
Eigen::Vector3d randomOffset(std::mt19937& rng, double maxUt) {
    std::uniform_real_distribution<double> size(0.0, maxUt);
    return randomDirection(rng) * size(rng);
}

TEST(FieldVote, SensorsReadingOneEarthFieldAreAllTrusted) {
    std::mt19937 rng(3);
    FieldVote vote(17, 17);
    for (std::size_t i = 0; i < 17; ++i) {
        EXPECT_FALSE(vote.counted()) << "before sensor " << i;
        EXPECT_FALSE(vote.trusted(i).has_value());
        const Reading r = firstReading(rng, randomOffset(rng, 2.0), 0.02);
        vote.add(i, r.normUt, r.angleToUpRad, 0.01 * static_cast<double>(i));
    }
    ASSERT_TRUE(vote.counted()) << "every expected sensor is in";
    for (std::size_t i = 0; i < 17; ++i) {
        EXPECT_EQ(vote.trusted(i), true) << "sensor " << i;
    }
    ASSERT_TRUE(vote.fieldUt().has_value());
    EXPECT_NEAR(*vote.fieldUt(), 50.0, 2.5);
    EXPECT_NEAR(*vote.angleToUpRad(), 150 * kDeg, 2 * kDeg);
}

// The virtual suit's typical magnetometers: offsets up to 300 uT. The earth's size alone (the rule
// before the vote) trusts a share of them; the vote trusts none, over many suits.
TEST(FieldVote, OffsetsThatGiveAFieldOfTheEarthsSizeByChanceAreNotTrusted) {
    std::mt19937 rng(11);
    int earthSized = 0;
    int trusted = 0;
    for (int suit = 0; suit < 300; ++suit) {
        FieldVote vote(17, 17);
        for (std::size_t i = 0; i < 17; ++i) {
            const Reading r = firstReading(rng, randomOffset(rng, 300.0), 0.02);
            earthSized += r.normUt >= 22.0 && r.normUt <= 67.0 ? 1 : 0;
            vote.add(i, r.normUt, r.angleToUpRad, 0.0);
        }
        ASSERT_TRUE(vote.counted());
        for (std::size_t i = 0; i < 17; ++i) {
            trusted += vote.trusted(i).value() ? 1 : 0;
        }
    }
    std::printf(
        "300 suits of 17 sensors with offsets up to 300 uT: %d first readings of the "
        "earth's size, %d trusted by the vote\n",
        earthSized, trusted);
    EXPECT_GT(earthSized, 100);
    EXPECT_EQ(trusted, 0);
}

TEST(FieldVote, AMajorityReadingTheEarthsFieldOutvotesTheOffsetOnes) {
    std::mt19937 rng(5);
    FieldVote vote(17, 17);
    std::vector<bool> offset(17, false);
    for (std::size_t i = 0; i < 17; ++i) {
        offset[i] = i % 3 == 0;  // 6 of 17
        Eigen::Vector3d h = randomOffset(rng, 2.0);
        if (offset[i]) {
            // An offset of 25-60 uT: the sum may well be of the earth's size, but not the earth's.
            h = randomDirection(rng) * (25.0 + 5.0 * static_cast<double>(i / 3));
        }
        const Reading r = firstReading(rng, h, 0.02);
        vote.add(i, r.normUt, r.angleToUpRad, 0.0);
    }
    for (std::size_t i = 0; i < 17; ++i) {
        EXPECT_EQ(vote.trusted(i), !offset[i]) << "sensor " << i;
    }
}

TEST(FieldVote, WithoutAMajorityNoSensorIsTrusted) {
    std::mt19937 rng(9);
    FieldVote vote(17, 17);
    for (std::size_t i = 0; i < 17; ++i) {
        // 6 right, 11 with large offsets: the medians are no field.
        const Eigen::Vector3d h = i < 6 ? randomOffset(rng, 2.0) : randomOffset(rng, 300.0);
        const Reading r = firstReading(rng, h, 0.02);
        vote.add(i, r.normUt, r.angleToUpRad, 0.0);
    }
    ASSERT_TRUE(vote.counted());
    EXPECT_FALSE(vote.fieldUt().has_value());
    for (std::size_t i = 0; i < 17; ++i) {
        EXPECT_EQ(vote.trusted(i), false) << "sensor " << i;
    }
}

TEST(FieldVote, TheWindowCountsWithoutASilentSensorAndALateOneIsHeldToTheMedians) {
    std::mt19937 rng(13);
    FieldVote vote(6, 6);
    for (std::size_t i = 0; i < 4; ++i) {
        const Reading r = firstReading(rng, randomOffset(rng, 2.0), 0.0);
        vote.add(i, r.normUt, r.angleToUpRad, 10.0 + 0.01 * static_cast<double>(i));
    }
    vote.close(10.3);
    EXPECT_FALSE(vote.counted()) << "two sensors missing, window not over";
    vote.close(10.5);
    ASSERT_TRUE(vote.counted());
    EXPECT_EQ(vote.trusted(0), true);
    EXPECT_FALSE(vote.trusted(4).has_value()) << "no reading yet";
    // Late: one reading the same field, one with an offset that keeps it of the earth's size.
    const Reading right = firstReading(rng, randomOffset(rng, 2.0), 0.0);
    vote.add(4, right.normUt, right.angleToUpRad, 11.0);
    EXPECT_EQ(vote.trusted(4), true);
    vote.add(5, 38.0, 100 * kDeg, 11.0);
    EXPECT_EQ(vote.trusted(5), false);
    // A second reading of a sensor does not replace its first.
    vote.add(5, right.normUt, right.angleToUpRad, 12.0);
    EXPECT_EQ(vote.trusted(5), false);
}

TEST(FieldVote, OneSensorIsTrustedWhenItsFieldIsOfTheEarthsSize) {
    FieldVote alone(1, 1);
    alone.add(0, 48.0, 150 * kDeg, 0.0);
    EXPECT_EQ(alone.trusted(0), true);
    FieldVote offset(1, 1);
    offset.add(0, 140.0, 150 * kDeg, 0.0);
    EXPECT_EQ(offset.trusted(0), false);
}

TEST(FieldVote, NonFiniteReadingsAndUnknownSensorsAreIgnored) {
    FieldVote vote(2, 2);
    vote.add(0, std::nan(""), 1.0, 0.0);
    vote.add(1, 50.0, std::numeric_limits<double>::infinity(), 0.0);
    vote.add(7, 50.0, 2.6, 0.0);
    EXPECT_FALSE(vote.counted());
    vote.add(0, 50.0, 2.6, 0.1);
    vote.add(1, 51.0, 2.61, 0.1);
    ASSERT_TRUE(vote.counted());
    EXPECT_EQ(vote.trusted(0), true);
    EXPECT_EQ(vote.trusted(1), true);
    EXPECT_FALSE(vote.trusted(7).has_value());
}

}  // namespace
}  // namespace caphub::fusion
