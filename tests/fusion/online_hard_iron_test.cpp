// The online hard- and soft-iron estimator: the offset, the soft iron and the field's magnitude
// from the readings of a turning sensor, the alignment of its axes to the up direction, its
// spread figure when the turns do not tell the offset or the shape, its residual when the field
// does not fit, and its state carried to a later run (as text too).
#include "fusion/calibration/online_hard_iron.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

namespace caphub::fusion {
namespace {

constexpr double kDeg = 0.017453292519943295;
constexpr double kRateHz = 50.0;

// The earth's field (ENU, uT): 50 uT, 60 deg dip, north along +y.
Vec3d earthField() {
    return Vec3d(0.0, 50.0 * std::cos(60 * kDeg), -50.0 * std::sin(60 * kDeg));
}

Quatd randomOrientation(std::mt19937& rng) {
    std::normal_distribution<double> n(0.0, 1.0);
    Quatd q(n(rng), n(rng), n(rng), n(rng));
    return q.normalized();
}

// A reading of the field in orientation q (sensor -> earth) with offset h and noise sigma.
Vec3d reading(const Quatd& q, const Vec3d& h, double sigma, std::mt19937& rng) {
    std::normal_distribution<double> n(0.0, sigma);
    return q.conjugate() * earthField() + h + Vec3d(n(rng), n(rng), n(rng));
}

TEST(OnlineHardIron, RecoversALargeOffsetFromTurnsOverTheSphere) {
    std::mt19937 rng(7);
    OnlineHardIron est(kRateHz);
    const Vec3d h(250.0, -120.0, 80.0);
    // 60 s of orientations spread over the sphere.
    for (int i = 0; i < 3000; ++i) {
        est.add(reading(randomOrientation(rng), h, 0.5, rng));
    }
    const HardIronEstimate e = est.estimate();
    ASSERT_TRUE(e.valid);
    EXPECT_TRUE(e.good);
    EXPECT_LT((e.offsetUt - h).norm(), 0.2);
    EXPECT_NEAR(e.fieldNormUt, 50.0, 0.2);
    EXPECT_LT(e.residualPct, 2.0);  // 0.5 uT noise per axis: 0.5 uT radially, 1 %
    EXPECT_GT(e.spread, 0.9);
}

TEST(OnlineHardIron, GivesNoGoodEstimateBeforeEnoughDataOrWithoutTurns) {
    std::mt19937 rng(8);
    OnlineHardIron est(kRateHz);
    const Vec3d h(-200.0, 60.0, 150.0);
    const Quatd still = randomOrientation(rng);
    for (int i = 0; i < 100; ++i) {
        est.add(reading(still, h, 0.5, rng));
    }
    EXPECT_FALSE(est.estimate().valid);  // 2 s: below minWeightS
    for (int i = 0; i < 3000; ++i) {
        est.add(reading(still, h, 0.5, rng));
    }
    // Held still: the offset cannot be told from the field.
    EXPECT_FALSE(est.estimate().good);
    EXPECT_LT(est.estimate().spread, 0.01);

    // Turning about one axis only (vertical): h along it stays unobservable.
    OnlineHardIron yawOnly(kRateHz);
    for (int i = 0; i < 3000; ++i) {
        const Quatd q(Eigen::AngleAxisd(i * 0.01, Vec3d::UnitZ()));
        yawOnly.add(reading(q, h, 0.5, rng));
    }
    const HardIronEstimate e = yawOnly.estimate();
    EXPECT_FALSE(e.good);
    EXPECT_LT(e.spread, 0.01);
}

TEST(OnlineHardIron, AFieldThatDoesNotFitIsNotTrusted) {
    std::mt19937 rng(9);
    OnlineHardIron est(kRateHz);
    const Vec3d h(100.0, 100.0, -50.0);
    // A magnet next to the path: the field changes with position, not with orientation.
    std::uniform_real_distribution<double> u(-40.0, 40.0);
    for (int i = 0; i < 3000; ++i) {
        const Quatd q = randomOrientation(rng);
        const Vec3d disturbance(u(rng), u(rng), u(rng));
        est.add(reading(q, h, 0.5, rng) + q.conjugate() * disturbance);
    }
    const HardIronEstimate e = est.estimate();
    ASSERT_TRUE(e.valid);
    EXPECT_GT(e.residualPct, 20.0);
    EXPECT_FALSE(e.good);
}

TEST(OnlineHardIron, ForgetsAnOldOffsetAndCarriesItsStateToTheNextRun) {
    std::mt19937 rng(10);
    OnlineHardIronParams p;
    p.memoryS = 20.0;
    OnlineHardIron est(kRateHz, p);
    const Vec3d h1(150.0, 0.0, 0.0);
    const Vec3d h2(-80.0, 40.0, 200.0);
    for (int i = 0; i < 3000; ++i) {
        const Quatd q = randomOrientation(rng);
        est.add(reading(q, h1, 0.5, rng));
    }
    EXPECT_LT((est.estimate().offsetUt - h1).norm(), 0.5);
    // The part was re-magnetised: right after it the old data make the fit residual large (not
    // trusted: the algebraic fit weighs far readings heavily); fifteen memory time constants later
    // the new offset is all that is left.
    for (int i = 0; i < 500; ++i) {
        const Quatd q = randomOrientation(rng);
        est.add(reading(q, h2, 0.5, rng));
    }
    EXPECT_FALSE(est.estimate().good);
    for (int i = 0; i < 14500; ++i) {
        const Quatd q = randomOrientation(rng);
        est.add(reading(q, h2, 0.5, rng));
    }
    const HardIronEstimate e = est.estimate();
    EXPECT_TRUE(e.good) << e.residualPct;
    EXPECT_LT((e.offsetUt - h2).norm(), 0.5);

    OnlineHardIron next(kRateHz, p);
    ASSERT_TRUE(next.setState(est.state()));
    const HardIronEstimate restored = next.estimate();
    EXPECT_TRUE(restored.good);
    EXPECT_EQ(restored.offsetUt, e.offsetUt);

    // Through its text line, exactly.
    const auto parsed = parseHardIronState(formatHardIronState(est.state()));
    ASSERT_TRUE(parsed);
    OnlineHardIron fromText(kRateHz, p);
    ASSERT_TRUE(fromText.setState(*parsed));
    EXPECT_EQ(fromText.estimate().offsetUt, e.offsetUt);
    EXPECT_FALSE(parseHardIronState("1 2 3"));
    // A line of the hard-iron-only estimator of before (19 numbers) is not a state now.
    EXPECT_FALSE(parseHardIronState("1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16 17 18 19"));
    EXPECT_FALSE(parseHardIronState(formatHardIronState(est.state()) + " 5"));
    EXPECT_FALSE(parseHardIronState("nan " + formatHardIronState(est.state()).substr(2)));
    // A damaged state: a sum of squares below zero, a count read as 2^64 - 5.
    OnlineHardIronState negative = est.state();
    negative.moments(3, 3) = -1e10;
    EXPECT_FALSE(parseHardIronState(formatHardIronState(negative)));
    negative = est.state();
    negative.alignMoments(2, 2) = -1.0;
    EXPECT_FALSE(parseHardIronState(formatHardIronState(negative)));
    std::string counted = formatHardIronState(est.state());
    counted = counted.substr(0, counted.find_last_of(' ')) + " -5";
    EXPECT_FALSE(parseHardIronState(counted));
    EXPECT_FALSE(parseHardIronState(counted.substr(0, counted.size() - 3) + " 5.5"));

    OnlineHardIronState bad = est.state();
    bad.moments(5, 8) = std::nan("");
    EXPECT_FALSE(next.setState(bad));
    EXPECT_FALSE(next.estimate().valid);  // started empty
}

// A glitched reading (5000 uT, or 1000 uT within the chip's range) must not spoil a good
// estimate: the algebraic fit would weigh it by its distance to the fourth power.
TEST(OnlineHardIron, AGlitchedReadingDoesNotSpoilAGoodEstimate) {
    std::mt19937 rng(12);
    OnlineHardIron est(kRateHz);
    const Vec3d h(120.0, -200.0, 40.0);
    for (int i = 0; i < 3000; ++i) {
        est.add(reading(randomOrientation(rng), h, 0.5, rng));
    }
    ASSERT_TRUE(est.refresh().good);
    const Vec3d before = est.estimate().offsetUt;
    est.add(Vec3d(5000.0, 0.0, 0.0));
    est.add(Vec3d(1000.0, 0.0, 0.0));
    EXPECT_EQ(est.outliers(), 2U);
    const HardIronEstimate e = est.estimate();
    EXPECT_TRUE(e.good);
    EXPECT_LT((e.offsetUt - before).norm(), 0.01);
    EXPECT_EQ(est.resets(), 0U);
}

// An offset that changes for good (a re-magnetised part) is off the old sphere for longer than
// gateResetS: the estimator starts over and learns the new one.
TEST(OnlineHardIron, StartsOverWhenTheOffsetHasChangedForGood) {
    std::mt19937 rng(13);
    OnlineHardIron est(kRateHz);
    const Vec3d h1(120.0, -200.0, 40.0);
    const Vec3d h2(-60.0, 30.0, 250.0);
    for (int i = 0; i < 3000; ++i) {
        est.add(reading(randomOrientation(rng), h1, 0.5, rng));
    }
    ASSERT_TRUE(est.refresh().good);
    for (int i = 0; i < 6000; ++i) {
        est.add(reading(randomOrientation(rng), h2, 0.5, rng));
        if (i % 50 == 0) {
            est.refresh();
        }
    }
    EXPECT_EQ(est.resets(), 1U);
    const HardIronEstimate e = est.refresh();
    EXPECT_TRUE(e.good);
    EXPECT_LT((e.offsetUt - h2).norm(), 0.5);
}

// The field as a distorted chip reads it: m = D Q (the true field in the sensor frame) + h,
// D a symmetric soft iron and Q the magnetometer's axes turned against the accelerometer's.
struct Distortion {
    Eigen::Matrix3d soft = Eigen::Matrix3d::Identity();
    Eigen::Matrix3d axes = Eigen::Matrix3d::Identity();
    Vec3d h = Vec3d::Zero();
};
Vec3d distorted(const Quatd& q, const Distortion& d, double sigma, std::mt19937& rng) {
    std::normal_distribution<double> n(0.0, sigma);
    return d.soft * (d.axes * (q.conjugate() * earthField())) + d.h + Vec3d(n(rng), n(rng), n(rng));
}

// The largest angle (deg) between the corrected reading and the true field direction over
// orientations spread over the sphere (noise-free readings).
double worstDirectionErrorDeg(const HardIronEstimate& e, const Distortion& d) {
    std::mt19937 rng(99);
    double worst = 0.0;
    for (int i = 0; i < 200; ++i) {
        const Quatd q = randomOrientation(rng);
        const Vec3d c = e.corrected(distorted(q, d, 0.0, rng));
        const Vec3d t = q.conjugate() * earthField();
        worst = std::max(
            worst, std::acos(std::clamp(c.normalized().dot(t.normalized()), -1.0, 1.0)) / kDeg);
    }
    return worst;
}

TEST(OnlineHardIron, FitsTheSoftIronWhenTheTurnsExploreEveryAxis) {
    Distortion d;
    d.soft << 1.04, 0.03, -0.05, 0.03, 0.97, 0.04, -0.05, 0.04, 1.02;
    d.h = Vec3d(-140.0, 90.0, 210.0);
    for (const bool soft : {true, false}) {
        std::mt19937 rng(21);
        OnlineHardIronParams p;
        p.fitSoftIron = soft;
        OnlineHardIron est(kRateHz, p);
        for (int i = 0; i < 3000; ++i) {
            est.add(distorted(randomOrientation(rng), d, 0.5, rng));
        }
        const HardIronEstimate e = est.estimate();
        ASSERT_TRUE(e.valid);
        EXPECT_EQ(e.ellipsoid, soft);
        if (soft) {
            EXPECT_TRUE(e.good) << e.residualPct;
            EXPECT_LT((e.offsetUt - d.h).norm(), 0.3);
            EXPECT_LT(worstDirectionErrorDeg(e, d), 0.3);
            EXPECT_LT(e.residualPct, 1.5);
        } else {
            // A sphere cannot take a soft iron of a few per cent out: its readings are 4 % of
            // the field off it (not trusted) and their directions off by degrees.
            EXPECT_FALSE(e.good);
            EXPECT_GT(e.residualPct, 4.0);
            EXPECT_GT(worstDirectionErrorDeg(e, d), 2.0);
        }
    }
}

TEST(OnlineHardIron, KeepsTheSphereWhereTheTurnsLeaveTheReadingsNearAPlane) {
    // A leg swinging about one axis with a little wobble: the quadric is not determined, and
    // the algebraic fit would take the noise for shape.
    Distortion d;
    d.soft << 1.04, 0.03, -0.05, 0.03, 0.97, 0.04, -0.05, 0.04, 1.02;
    d.h = Vec3d(60.0, -30.0, 120.0);
    std::mt19937 rng(22);
    OnlineHardIron est(kRateHz);
    for (int i = 0; i < 6000; ++i) {
        const double t = i / kRateHz;
        const Quatd q = Quatd(Eigen::AngleAxisd(1.2 * std::sin(0.7 * t), Vec3d::UnitX())) *
                        Quatd(Eigen::AngleAxisd(0.3 * std::sin(1.9 * t), Vec3d::UnitY()));
        est.add(distorted(q, d, 0.5, rng));
    }
    const HardIronEstimate e = est.estimate();
    ASSERT_TRUE(e.valid);
    EXPECT_LT(e.spread, 0.15);
    EXPECT_FALSE(e.ellipsoid);
    EXPECT_EQ(e.softIron, Eigen::Matrix3d::Identity());
}

TEST(OnlineHardIron, AlignsTheMagnetometersAxesToTheUpDirection) {
    Distortion d;
    d.soft << 1.02, -0.02, 0.01, -0.02, 0.99, 0.02, 0.01, 0.02, 1.01;
    d.axes = Eigen::AngleAxisd(3.0 * kDeg, Vec3d(0.3, -0.8, 0.5).normalized()).toRotationMatrix();
    d.h = Vec3d(80.0, -160.0, 40.0);
    for (const bool align : {true, false}) {
        std::mt19937 rng(23);
        OnlineHardIronParams p;
        p.fitAlignment = align;
        OnlineHardIron est(kRateHz, p);
        std::normal_distribution<double> tilt(0.0, 0.5 * kDeg);  // the filter's tilt error
        for (int i = 0; i < 6000; ++i) {
            const Quatd q = randomOrientation(rng);
            const Vec3d m = distorted(q, d, 0.5, rng);
            est.add(m);
            const Vec3d up =
                (Eigen::AngleAxisd(tilt(rng), Vec3d::UnitX()) * (q.conjugate() * Vec3d::UnitZ()))
                    .normalized();
            est.addAlignment(m, up);
            if (i % 50 == 0) {
                est.refresh();
            }
        }
        const HardIronEstimate e = est.refresh();
        ASSERT_TRUE(e.good && e.ellipsoid);
        EXPECT_EQ(e.aligned, align);
        if (align) {
            EXPECT_LT(worstDirectionErrorDeg(e, d), 0.4);
        } else {
            EXPECT_GT(worstDirectionErrorDeg(e, d), 2.5);
        }
    }
    // Nothing is learnt before a good estimate with a soft iron: up alone says nothing.
    OnlineHardIron fresh(kRateHz);
    fresh.addAlignment(Vec3d(10.0, 20.0, 30.0), Vec3d::UnitZ());
    EXPECT_EQ(fresh.state().alignWeight(), 0.0);
}

TEST(OnlineHardIron, IgnoresNonFiniteInput) {
    OnlineHardIron est(kRateHz);
    est.add(Vec3d(std::nan(""), 0.0, 0.0));
    est.add(Vec3d(1.0, std::numeric_limits<double>::infinity(), 3.0));
    EXPECT_EQ(est.state().samples, 0U);
    EXPECT_EQ(est.state().weight(), 0.0);
}

}  // namespace
}  // namespace caphub::fusion
