// The non-causal orientation estimate (fusion/smoother.h) on synthetic motion whose orientation
// is known exactly: a gyroscope that clips loses an unknown rotation, and the estimate must take
// each stretch of the take from the run that has not yet passed the clip.
#include "fusion/smoother.h"

#include <algorithm>
#include <cmath>

#include <gtest/gtest.h>

#include "tests/fusion/synthetic_imu.h"

namespace caphub::fusion {
namespace {

constexpr double kRateHz = 100.0;
constexpr double kFullScaleRadS = 2000.0 * 3.14159265358979323846 / 180.0;

// A hand-held wobble for 60 s with a spin about the sensor's z axis at 45 rad/s for 0.3 s from
// each of `spinsS`: beyond the gyroscope's 2000 deg/s (34.9 rad/s), so the gyroscope reads each
// spin 10 rad/s short and the strapdown loses about 3 rad.
struct ClippedTake {
    test::SynthRun run;
    std::vector<SmootherSample> samples;
};

ClippedTake clippedTake(const std::vector<double>& spinsS, double spinRadS = 45.0,
                        double shakingFromS = 1e9) {
    test::SynthConfig c;
    c.rateHz = kRateHz;
    // From shakingFromS on, the sensor is also shaken (3 m/s^2 horizontally).
    c.linearAccEarth = [shakingFromS](double t) -> Vec3d {
        return t < shakingFromS ? Vec3d::Zero()
                                : Vec3d(3.0 * std::sin(5.0 * t), 3.0 * std::cos(4.0 * t), 0.0);
    };
    const auto base = test::wobble(1.5);
    const auto omega = [&](double t) -> Vec3d {
        Vec3d w = base(t);
        for (double s : spinsS) {
            if (t >= s && t < s + 0.3) {
                w.z() += spinRadS;
            }
        }
        return w;
    };
    ClippedTake take;
    take.run = test::synthesize(c, Quatd::Identity(), 60.0, omega);
    for (const ImuSample& in : take.run.samples) {
        SmootherSample s;
        s.gyrRadS = in.gyrRadS.cwiseMax(-kFullScaleRadS).cwiseMin(kFullScaleRadS);
        s.gyrClipped = s.gyrRadS != in.gyrRadS;
        s.accMps2 = in.accMps2;
        s.magUt = in.magUt;
        s.magFresh = true;
        take.samples.push_back(s);
    }
    return take;
}

FilterParams paramsAt100Hz() {
    FilterParams p;
    p.gyrRateHz = p.accRateHz = p.magRateHz = kRateHz;
    return p;
}

// Mean angle (deg) between the estimate and the truth over the samples in [fromS, toS).
double meanErrorDeg(const std::vector<Quatd>& est, const std::vector<Quatd>& truth, double fromS,
                    double toS) {
    double sum = 0;
    int count = 0;
    for (std::size_t k = static_cast<std::size_t>(fromS * kRateHz);
         k < std::min(est.size(), static_cast<std::size_t>(toS * kRateHz)); ++k) {
        sum += est[k].angularDistance(truth[k]) * 180.0 / 3.14159265358979323846;
        ++count;
    }
    return count > 0 ? sum / count : 0.0;
}

std::vector<Quatd> causalRun(const std::vector<SmootherSample>& samples, const FilterParams& p) {
    OrientationFilter<FloatTypes> f(p);
    std::vector<Quatd> out;
    for (const SmootherSample& s : samples) {
        f.updateGyr({static_cast<float>(s.gyrRadS.x()), static_cast<float>(s.gyrRadS.y()),
                     static_cast<float>(s.gyrRadS.z())},
                    s.gyrClipped);
        f.updateAcc({static_cast<float>(s.accMps2.x()), static_cast<float>(s.accMps2.y()),
                     static_cast<float>(s.accMps2.z())});
        f.updateMag({static_cast<float>(s.magUt.x()), static_cast<float>(s.magUt.y()),
                     static_cast<float>(s.magUt.z())});
        const auto q = f.quat();
        out.push_back(Quatd(q.w, q.x, q.y, q.z).normalized());
    }
    return out;
}

bool anyClipped(const ClippedTake& take) {
    return std::any_of(take.samples.begin(), take.samples.end(),
                       [](const SmootherSample& s) { return s.gyrClipped; });
}

// The take through the causal filter and through the smoother, both at 100 Hz.
struct Estimates {
    std::vector<Quatd> causal;
    std::vector<Quatd> smoothed;
};

Estimates estimatesOf(const ClippedTake& take) {
    const FilterParams p = paramsAt100Hz();
    return {causalRun(take.samples, p), smoothOrientations(take.samples, p)};
}

TEST(Smoother, AfterAClipTheTakeIsTheBackwardRunsWhichHasNotPassedIt) {
    const ClippedTake take = clippedTake({25.0});
    ASSERT_TRUE(anyClipped(take));
    const auto [causal, smoothed] = estimatesOf(take);
    const auto& truth = take.run.truth;
    // The causal run carries the lost turn for tens of seconds (its heading gain).
    const double causalAfter = meanErrorDeg(causal, truth, 26.0, 60.0);
    EXPECT_GT(causalAfter, 10.0);
    // The smoothed estimate does not, before the clip or after it.
    EXPECT_LT(meanErrorDeg(smoothed, truth, 26.0, 60.0), 1.5) << "causal " << causalAfter;
    EXPECT_LT(meanErrorDeg(smoothed, truth, 5.0, 24.5), 1.5);
    // Nor where the causal run is right: the backward run's own passage of the clip is not
    // carried back into the stretch before it.
    EXPECT_LT(meanErrorDeg(smoothed, truth, 5.0, 24.5),
              meanErrorDeg(causal, truth, 5.0, 24.5) + 0.5);
}

TEST(Smoother, AClipNearTheEndDoesNotTurnTheBackwardRunsStart) {
    // The backward run starts from the causal run's state at the end; 5 s after a clip that
    // state is still off by the lost turn, so the backward run aligns afresh there.
    const ClippedTake take = clippedTake({55.0});
    const FilterParams p = paramsAt100Hz();
    const auto smoothed = smoothOrientations(take.samples, p);
    EXPECT_LT(meanErrorDeg(smoothed, take.run.truth, 56.0, 60.0), 3.0);
    EXPECT_LT(meanErrorDeg(smoothed, take.run.truth, 5.0, 54.5), 3.0);
}

TEST(Smoother, WithoutAClipTheHeadingIsTheCausalRunsAndTheEstimateFollowsTheTruth) {
    const ClippedTake take = clippedTake({});
    const FilterParams p = paramsAt100Hz();
    const auto causal = causalRun(take.samples, p);
    SmootherStats stats;
    const auto smoothed = smoothOrientations(take.samples, p, {}, &stats);
    // The heading is the causal run's: the two differ only in inclination.
    double maxHeadingDeg = 0;
    for (std::size_t k = 0; k < smoothed.size(); ++k) {
        maxHeadingDeg = std::max(maxHeadingDeg, std::abs(test::headingDeg(smoothed[k], causal[k])));
    }
    EXPECT_LT(maxHeadingDeg, 0.05);
    EXPECT_LT(meanErrorDeg(smoothed, take.run.truth, 2.0, 60.0), 1.0);
    EXPECT_LT(stats.maxDisagreementDeg, 5.0);
}

// A steady turn about up read by a gyroscope whose scale is 0.5 % high: the heading gain's lag
// (about 30 s) leaves the causal run behind the field by scale error x rate x lag, and a run
// backward in time ahead of it by as much. Combining both runs' headings removes the lag.
TEST(Smoother, ARunRealignedWhileTheLimbIsShakenSettlesItsTiltBeforeItsHeading) {
    // A spin just beyond the full scale at 55 s (about 2 deg lost: the causal run's end still
    // carries it, so the backward run aligns afresh at the end), and the sensor shaken at
    // 3 m/s^2 from 50 s on: one sample's acceleration is not gravity there, and a tilt off by
    // it turns the field's horizontal part, the heading with it.
    const ClippedTake take = clippedTake({55.0}, 35.0, 50.0);
    ASSERT_TRUE(anyClipped(take));
    const auto [causal, smoothed] = estimatesOf(take);
    const auto& truth = take.run.truth;
    EXPECT_LT(meanErrorDeg(smoothed, truth, 56.0, 60.0), meanErrorDeg(causal, truth, 56.0, 60.0));
    EXPECT_LT(meanErrorDeg(smoothed, truth, 5.0, 54.5),
              meanErrorDeg(causal, truth, 5.0, 54.5) + 0.3);
}

TEST(Smoother, BothRunsHeadingsTogetherHaveNoLag) {
    test::SynthConfig c;
    c.rateHz = kRateHz;
    const auto wobble = test::wobble(0.3);
    const Quatd tilted(Eigen::AngleAxisd(0.3, Vec3d::UnitX()));
    // About the earth's vertical, seen in the sensor frame of the tilted start (wobbling).
    const Vec3d upInSensor = tilted.conjugate() * Vec3d::UnitZ();
    const test::SynthRun run = test::synthesize(
        c, tilted, 120.0, [&](double t) -> Vec3d { return upInSensor * 0.5 + 0.2 * wobble(t); });
    std::vector<SmootherSample> samples;
    for (const ImuSample& in : run.samples) {
        SmootherSample s;
        s.gyrRadS = in.gyrRadS * 1.005;
        s.accMps2 = in.accMps2;
        s.magUt = in.magUt;
        s.magFresh = true;
        samples.push_back(s);
    }
    const FilterParams p = paramsAt100Hz();
    const auto causalHeading = smoothOrientations(samples, p);
    SmootherOptions both;
    both.forwardHeading = false;
    const auto bothHeadings = smoothOrientations(samples, p, both);
    // Away from the ends, where one of the runs has not yet caught up with the lag.
    double causalDeg = 0;
    double bothDeg = 0;
    int count = 0;
    constexpr auto kFrom = static_cast<std::size_t>(40 * kRateHz);
    constexpr auto kTo = static_cast<std::size_t>(80 * kRateHz);
    for (std::size_t k = kFrom; k < kTo; ++k) {
        causalDeg += std::abs(test::headingDeg(causalHeading[k], run.truth[k]));
        bothDeg += std::abs(test::headingDeg(bothHeadings[k], run.truth[k]));
        ++count;
    }
    causalDeg /= count;
    bothDeg /= count;
    EXPECT_GT(causalDeg, 3.0);
    EXPECT_LT(bothDeg, 0.3 * causalDeg) << "causal heading " << causalDeg;
}

// Still for 10 s, moved by hand for 60 s where the field's horizontal part points 5 deg east
// of where it points at the rest places (a room's field varies from place to place), still
// again for 10 s; the gyroscope has a bias. `secondRest` false: the take ends moving.
struct RestsTake {
    test::SynthRun run;
    std::vector<SmootherSample> samples;
};

RestsTake restsTake(bool secondRest) {
    test::SynthConfig c;
    c.rateHz = kRateHz;
    c.gyrBiasRadS = Vec3d(0.002, -0.003, 0.004);
    const double horizontal = std::hypot(c.magEarthUt.x(), c.magEarthUt.y());
    const double east = horizontal * std::tan(5.0 * 3.14159265358979323846 / 180.0);
    const auto moving = [secondRest](double t) { return t >= 10.0 && (t < 70.0 || !secondRest); };
    c.magDisturbanceEarthUt = [moving, east](double t) -> Vec3d {
        return moving(t) ? Vec3d(east, 0.0, 0.0) : Vec3d::Zero();
    };
    const auto hand = test::wobble(1.5);
    RestsTake take;
    take.run = test::synthesize(c, Quatd::Identity(), 80.0, [&](double t) -> Vec3d {
        return moving(t) ? hand(t) : Vec3d::Zero();
    });
    for (const ImuSample& in : take.run.samples) {
        SmootherSample s;
        s.gyrRadS = in.gyrRadS;
        s.accMps2 = in.accMps2;
        s.magUt = in.magUt;
        s.magFresh = true;
        take.samples.push_back(s);
    }
    return take;
}

double meanHeadingErrorDeg(const std::vector<Quatd>& est, const std::vector<Quatd>& truth,
                           double fromS, double toS) {
    double sum = 0;
    int count = 0;
    for (auto k = static_cast<std::size_t>(fromS * kRateHz);
         k < static_cast<std::size_t>(toS * kRateHz); ++k) {
        sum += std::abs(test::headingDeg(est[k], truth[k]));
        ++count;
    }
    return sum / count;
}

// The take smoothed with the causal heading and with the rest heading.
struct Headings {
    std::vector<Quatd> causal;
    std::vector<Quatd> rest;
};

Headings headingsOf(const std::vector<SmootherSample>& samples) {
    const FilterParams p = paramsAt100Hz();
    SmootherOptions rest;
    EXPECT_TRUE(setSmoothHeading(rest, "rest"));
    return {smoothOrientations(samples, p), smoothOrientations(samples, p, rest)};
}

TEST(Smoother, BetweenTwoRestsTheHeadingIsTheGyroscopesAnchoredOnTheFieldAtRest) {
    const RestsTake take = restsTake(true);
    const auto [causalHeading, bridged] = headingsOf(take.samples);
    const auto& truth = take.run.truth;
    // The causal heading follows the field of the place the sensor moves in; the gyroscope's,
    // anchored at both rests and its bias measured there, does not.
    const double causalDeg = meanHeadingErrorDeg(causalHeading, truth, 30.0, 70.0);
    const double bridgedDeg = meanHeadingErrorDeg(bridged, truth, 30.0, 70.0);
    EXPECT_GT(causalDeg, 2.0);
    EXPECT_LT(bridgedDeg, 0.5) << "causal " << causalDeg;
    EXPECT_LT(meanHeadingErrorDeg(bridged, truth, 10.0, 30.0), 0.5);
    EXPECT_LT(meanHeadingErrorDeg(bridged, truth, 72.0, 80.0), 0.5);
    // The inclination is the smoother's either way.
    for (std::size_t k = 0; k < truth.size(); k += 50) {
        ASSERT_NEAR(test::inclinationDeg(bridged[k], truth[k]),
                    test::inclinationDeg(causalHeading[k], truth[k]), 0.05)
            << k;
    }
}

TEST(Smoother, WithoutASecondRestTheRestHeadingIsTheCausalOne) {
    const RestsTake take = restsTake(false);
    const auto [causalHeading, same] = headingsOf(take.samples);
    ASSERT_EQ(same.size(), causalHeading.size());
    for (std::size_t k = 0; k < same.size(); ++k) {
        ASSERT_EQ(same[k].coeffs(), causalHeading[k].coeffs()) << k;
    }
}

// One glitched rate between the rests (the filter rejects it): integrated, it would turn the
// bridge by tens of radians; the take keeps the causal heading instead.
TEST(Smoother, AGlitchBetweenTheRestsLeavesTheCausalHeading) {
    RestsTake take = restsTake(true);
    take.samples[4000].gyrRadS.x() = 5000.0;
    const auto [causalHeading, same] = headingsOf(take.samples);
    ASSERT_EQ(same.size(), causalHeading.size());
    for (std::size_t k = 0; k < same.size(); ++k) {
        ASSERT_TRUE(same[k].coeffs().allFinite()) << k;
        ASSERT_EQ(same[k].coeffs(), causalHeading[k].coeffs()) << k;
    }
}

TEST(Smoother, TheHeadingChoiceIsNamed) {
    SmootherOptions o;
    EXPECT_TRUE(setSmoothHeading(o, "both"));
    EXPECT_FALSE(o.forwardHeading);
    EXPECT_TRUE(setSmoothHeading(o, "causal"));
    EXPECT_TRUE(o.forwardHeading);
    EXPECT_FALSE(o.restAnchoredHeading);
    EXPECT_TRUE(setSmoothHeading(o, "rest"));
    EXPECT_TRUE(o.forwardHeading);
    EXPECT_TRUE(o.restAnchoredHeading);
    EXPECT_TRUE(setSmoothHeading(o, "causal"));
    EXPECT_FALSE(o.restAnchoredHeading);
    EXPECT_FALSE(setSmoothHeading(o, "forward"));
    EXPECT_TRUE(o.forwardHeading);
}

}  // namespace
}  // namespace caphub::fusion
