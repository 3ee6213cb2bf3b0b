// The orientation filter's behaviour on synthetic data with known truth, in float and in fixed
// point (the same tests run on both variants).
#include "fusion/orientation_filter.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>

#include <gtest/gtest.h>

#include "tests/fusion/synthetic_imu.h"

namespace caphub::fusion {
namespace {

constexpr double kDeg = 0.017453292519943295;

template <typename T>
class OrientationFilterTest : public ::testing::Test {
protected:
    static FilterVariant variant() {
        return std::is_same_v<T, FloatTypes> ? FilterVariant::Float : FilterVariant::Fixed;
    }
    // Runs a filter sample by sample; returns its estimates and leaves it for inspection.
    static std::vector<Quatd> run(OrientationFilter<T>& f, const std::vector<ImuSample>& s) {
        std::vector<Quatd> out;
        for (const auto& x : s) {
            f.updateGyr(
                fromDoubleVec<typename T::Gyr>(x.gyrRadS.x(), x.gyrRadS.y(), x.gyrRadS.z()));
            f.updateAcc(
                fromDoubleVec<typename T::Acc>(x.accMps2.x(), x.accMps2.y(), x.accMps2.z()));
            f.updateMag(fromDoubleVec<typename T::Mag>(x.magUt.x(), x.magUt.y(), x.magUt.z()));
            const auto q = f.quat();
            out.emplace_back(toDouble(q.w), toDouble(q.x), toDouble(q.y), toDouble(q.z));
        }
        return out;
    }
    static FilterParams params(double rateHz) {
        FilterParams p;
        p.gyrRateHz = p.accRateHz = p.magRateHz = rateHz;
        return p;
    }
};

using Variants = ::testing::Types<FloatTypes, FixedTypes>;
TYPED_TEST_SUITE(OrientationFilterTest, Variants);

TYPED_TEST(OrientationFilterTest, CountsEachGyroscopeClippingEpisodeOnce) {
    OrientationFilter<TypeParam> f(this->params(100.0));
    const auto gyr = fromDoubleVec<typename TypeParam::Gyr>(34.5, 0.0, 0.0);
    const auto run = [&](int samples, bool clipped) {
        for (int i = 0; i < samples; ++i) {
            f.updateGyr(gyr, clipped);
        }
    };
    run(10, false);
    EXPECT_EQ(f.clipEvents(), 0U);
    run(5, true);  // one episode of five samples
    EXPECT_EQ(f.clipEvents(), 1U);
    run(3, false);
    run(1, true);  // a second one
    run(2, false);
    EXPECT_EQ(f.clipEvents(), 2U);
    f.resetState();
    EXPECT_EQ(f.clipEvents(), 0U);
}

TYPED_TEST(OrientationFilterTest, InclinationConvergesToTruthWithin2sAtRest) {
    test::SynthConfig c;
    const Quatd q0 = fromAxisAngle<double>(Vec3d(1.0, 0.5, 0.2), 35.0 * kDeg);
    const auto run = test::synthesize(c, q0, 10.0, [](double) -> Vec3d { return Vec3d::Zero(); });
    OrientationFilter<TypeParam> f(this->params(c.rateHz));
    const auto est = this->run(f, run.samples);
    // From 2 s on, the error is the accelerometer noise averaged by the low-pass: 0.03 m/s^2 per
    // sample is 0.18 deg on one sample, far less after averaging; 0.3 deg leaves room for it
    // and fails for any real misalignment.
    for (std::size_t i = static_cast<std::size_t>(2.0 * c.rateHz); i < est.size(); ++i) {
        ASSERT_LT(test::inclinationDeg(est[i], run.truth[i]), 0.3)
            << "at t = " << run.samples[i].tS;
    }
}

TYPED_TEST(OrientationFilterTest, AKnownSustainedAccelerationDoesNotTiltTheEstimate) {
    // Starting to walk: 0 to 1.2 m/s northwards in 1.5 s, then steady walking, with the sensor
    // wobbling. The filter that is not told tilts by the acceleration's share of the filtered
    // gravity (degrees); told it through linAccEarth, it stays within its noise.
    test::SynthConfig c;
    c.linearAccEarth = [](double t) -> Vec3d {
        return t >= 5.0 && t < 6.5 ? Vec3d(0.0, 0.8, 0.0) : Vec3d::Zero();
    };
    const Quatd q0 = fromAxisAngle<double>(Vec3d(0.2, 1.0, 0.1), 20.0 * kDeg);
    const auto run = test::synthesize(c, q0, 15.0, test::wobble(0.5));
    const auto peakError = [&](bool told) {
        OrientationFilter<TypeParam> f(this->params(c.rateHz));
        double peak = 0;
        for (std::size_t i = 0; i < run.samples.size(); ++i) {
            const auto& x = run.samples[i];
            const Vec3d a = told ? c.linearAccEarth(x.tS) : Vec3d::Zero();
            f.updateGyr(fromDoubleVec<typename TypeParam::Gyr>(x.gyrRadS.x(), x.gyrRadS.y(),
                                                               x.gyrRadS.z()));
            f.updateAcc(
                fromDoubleVec<typename TypeParam::Acc>(x.accMps2.x(), x.accMps2.y(), x.accMps2.z()),
                fromDoubleVec<typename TypeParam::Acc>(a.x(), a.y(), a.z()));
            f.updateMag(
                fromDoubleVec<typename TypeParam::Mag>(x.magUt.x(), x.magUt.y(), x.magUt.z()));
            if (x.tS >= 5.0) {
                const auto q = f.quat();
                const Quatd e(toDouble(q.w), toDouble(q.x), toDouble(q.y), toDouble(q.z));
                peak = std::max(peak, test::inclinationDeg(e, run.truth[i]));
            }
        }
        return peak;
    };
    const double untold = peakError(false);
    const double told = peakError(true);
    EXPECT_GT(untold, 1.0);
    EXPECT_LT(told, 0.3);
}

TYPED_TEST(OrientationFilterTest, HeadingAlignsWithMagneticNorthFromTheFirstSamples) {
    test::SynthConfig c;
    const Quatd q0 = fromAxisAngle<double>(Vec3d(0.2, -0.3, 1.0), 120.0 * kDeg);
    const auto run = test::synthesize(c, q0, 3.0, [](double) -> Vec3d { return Vec3d::Zero(); });
    OrientationFilter<TypeParam> f(this->params(c.rateHz));
    const auto est = this->run(f, run.samples);
    // One noisy magnetometer sample (0.3 uT on a 19 uT horizontal field) sets the heading to
    // within about 1 deg; 2 deg fails for a wrong sign or axis.
    EXPECT_LT(test::headingDeg(est[1], run.truth[1]), 2.0);
    EXPECT_LT(test::headingDeg(est.back(), run.truth.back()), 2.0);
}

TYPED_TEST(OrientationFilterTest, ConstantGyroBiasIsEstimatedAtRestWithin0p05Dps) {
    test::SynthConfig c;
    c.gyrBiasRadS = Vec3d(0.8, -1.2, 0.5) * kDeg;
    const auto run =
        test::synthesize(c, Quatd::Identity(), 12.0, [](double) -> Vec3d { return Vec3d::Zero(); });
    OrientationFilter<TypeParam> f(this->params(c.rateHz));
    this->run(f, run.samples);
    EXPECT_TRUE(f.atRest());
    const Vec3d b(toDouble(f.bias().x), toDouble(f.bias().y), toDouble(f.bias().z));
    EXPECT_LT((b - c.gyrBiasRadS).cwiseAbs().maxCoeff() / kDeg, 0.05) << b.transpose() / kDeg;
}

TYPED_TEST(OrientationFilterTest, GyroBiasIsTrackedDuringMotion) {
    // No rest at all: only the Kalman bias update can learn the bias. With the default gains the
    // bias loop's slow pole is K_bias / K_incl, a time constant of about 150 s (docs/fusion.md),
    // so after 10 min (four time constants) the error must be below a quarter of its start
    // (0.54 deg/s); a wrong sign would drive it up to the clamp instead.
    test::SynthConfig c;
    c.gyrBiasRadS = Vec3d(0.3, -0.4, 0.2) * kDeg;
    const auto run = test::synthesize(c, Quatd::Identity(), 600.0, test::wobble(1.0));
    OrientationFilter<TypeParam> f(this->params(c.rateHz));
    this->run(f, run.samples);
    EXPECT_FALSE(f.atRest());
    const Vec3d b(toDouble(f.bias().x), toDouble(f.bias().y), toDouble(f.bias().z));
    EXPECT_LT((b - c.gyrBiasRadS).norm(), 0.25 * c.gyrBiasRadS.norm()) << b.transpose() / kDeg;
}

TYPED_TEST(OrientationFilterTest, MagnetNearTheSensorLeavesHeadingWithin2DegOfTheUndisturbedRun) {
    test::SynthConfig clean;
    test::SynthConfig dist = clean;
    // A magnet brought within a few cm for 10 s: 60 uT along east in the earth frame, ramping in
    // and out over 0.5 s, more than the earth's field itself.
    dist.magDisturbanceEarthUt = [](double t) -> Vec3d {
        const double ramp = std::clamp(std::min(t - 20.0, 30.0 - t) / 0.5, 0.0, 1.0);
        return Vec3d(60.0, 0.0, 10.0) * ramp;
    };
    const Quatd q0 = Quatd::Identity();
    const auto a = test::synthesize(clean, q0, 60.0, test::wobble(1.5));
    const auto b = test::synthesize(dist, q0, 60.0, test::wobble(1.5));
    OrientationFilter<TypeParam> fa(this->params(clean.rateHz));
    OrientationFilter<TypeParam> fb(this->params(clean.rateHz));
    const auto ea = this->run(fa, a.samples);
    const auto eb = this->run(fb, b.samples);
    double worst = 0.0;
    bool rejected = false;
    for (std::size_t i = 0; i < ea.size(); ++i) {
        worst = std::max(worst, test::headingDeg(eb[i], ea[i]));
    }
    // Re-run to see the detector engage during the disturbance.
    OrientationFilter<TypeParam> fc(this->params(clean.rateHz));
    for (std::size_t i = 0; i < b.samples.size(); ++i) {
        const auto& x = b.samples[i];
        std::vector<ImuSample> one{x};
        this->run(fc, one);
        rejected = rejected || (x.tS > 21.0 && x.tS < 29.0 && fc.magDisturbed());
    }
    EXPECT_TRUE(rejected);
    EXPECT_LT(worst, 2.0);
}

TYPED_TEST(OrientationFilterTest, TracksFastRotationAt25RadPerSecond) {
    // 25 rad/s about a tilted axis, sampled at 285.7 Hz and at 57 Hz: the strapdown must keep up
    // (0.44 rad per sample at 57 Hz) and the fixed-point angle increment must not overflow.
    for (double rate : {285.714, 57.1428}) {
        test::SynthConfig c;
        c.rateHz = rate;
        const Vec3d axis = Vec3d(0.3, 0.4, 0.866).normalized();
        const auto run = test::synthesize(c, Quatd::Identity(), 6.0, [&](double t) -> Vec3d {
            return t > 2.0 && t < 4.0 ? Vec3d(axis * 25.0) : Vec3d(Vec3d::Zero());
        });
        OrientationFilter<TypeParam> f(this->params(rate));
        const auto est = this->run(f, run.samples);
        double worst = 0.0;
        for (std::size_t i = 0; i < est.size(); ++i) {
            worst = std::max(worst, angleBetween(est[i], run.truth[i]));
        }
        // Exact gyro data: 50 turns must not cost more than 2 deg (the series exp map is
        // accurate to 1e-6 rad per 0.44 rad step; heading/tilt corrections are slow).
        EXPECT_LT(worst / kDeg, 2.0) << "rate " << rate;
    }
}

// Every time constant and noise density is stated per second, so the filter's response in time
// must not depend on its sample rate (docs/fusion.md, "The same filter at every rate"): a tilt or
// heading error put into a filter at rest decays as fast, and an acceleration it is not told of
// tilts it as much and as late, at 50, 100, 200 and 285.7 Hz.
TYPED_TEST(OrientationFilterTest, ItsResponseInTimeIsTheSameAtEveryRate) {
    struct Trace {
        std::vector<double> t, inclDeg, headDeg;
    };
    // Noise-free rest at `rateHz` for 40 s; after 3 s the state's qCorr is turned by `turn`
    // (earth frame). The errors against the truth from then on.
    const auto trace = [this](double rateHz, const Quatd& turn,
                              const std::function<Vec3d(double)>& linAcc) {
        test::SynthConfig c;
        c.rateHz = rateHz;
        c.gyrNoiseRadS = 0.0;
        c.accNoiseMps2 = 0.0;
        c.magNoiseUt = 0.0;
        c.linearAccEarth = linAcc;
        const Quatd q0 = fromAxisAngle<double>(Vec3d(0.3, -0.2, 1.0), 40.0 * kDeg);
        const auto run = test::synthesize(c, q0, 40.0, [](double) { return Vec3d::Zero(); });
        OrientationFilter<TypeParam> f(this->params(rateHz));
        using U = typename TypeParam::Unit;
        Trace out;
        for (std::size_t i = 0; i < run.samples.size(); ++i) {
            const ImuSample& x = run.samples[i];
            if (i == static_cast<std::size_t>(3.0 * rateHz)) {
                auto st = f.state();
                const Quatd qc(toDouble(st.qCorr.w), toDouble(st.qCorr.x), toDouble(st.qCorr.y),
                               toDouble(st.qCorr.z));
                const Quatd q = (turn * qc).normalized();
                st.qCorr = {fromDouble<U>(q.w()), fromDouble<U>(q.x()), fromDouble<U>(q.y()),
                            fromDouble<U>(q.z())};
                f.setState(st);
            }
            f.updateGyr(fromDoubleVec<typename TypeParam::Gyr>(x.gyrRadS.x(), x.gyrRadS.y(),
                                                               x.gyrRadS.z()));
            f.updateAcc(fromDoubleVec<typename TypeParam::Acc>(x.accMps2.x(), x.accMps2.y(),
                                                               x.accMps2.z()));
            f.updateMag(
                fromDoubleVec<typename TypeParam::Mag>(x.magUt.x(), x.magUt.y(), x.magUt.z()));
            if (x.tS >= 3.0) {
                const auto q = f.quat();
                const Quatd e(toDouble(q.w), toDouble(q.x), toDouble(q.y), toDouble(q.z));
                out.t.push_back(x.tS - 3.0);
                out.inclDeg.push_back(test::inclinationDeg(e, run.truth[i]));
                out.headDeg.push_back(test::headingDeg(e, run.truth[i]));
            }
        }
        return out;
    };
    // When a series first falls below `level` (s from the injection; 1e9: never).
    const auto firstBelow = [](const Trace& tr, const std::vector<double>& v, double level) {
        for (std::size_t i = 0; i < v.size(); ++i) {
            if (v[i] < level) {
                return tr.t[i];
            }
        }
        return 1e9;
    };
    const auto noAcc = [](double) { return Vec3d::Zero(); };
    // 2 m/s^2 east for 1 s from the injection on, not told to the filter.
    const auto push = [](double t) {
        return t >= 3.0 && t < 4.0 ? Vec3d(2.0, 0.0, 0.0) : Vec3d::Zero();
    };
    struct Response {
        double tiltDecayS, headingDecayS, pushPeakDeg, pushPeakAtS;
    };
    const auto respond = [&](double rateHz) {
        Response r{};
        const Trace tilt = trace(rateHz, fromAxisAngle<double>(Vec3d::UnitX(), 5.0 * kDeg), noAcc);
        r.tiltDecayS = firstBelow(tilt, tilt.inclDeg, 5.0 / std::exp(1.0));
        const Trace head = trace(rateHz, fromAxisAngle<double>(Vec3d::UnitZ(), 20.0 * kDeg), noAcc);
        r.headingDecayS = firstBelow(head, head.headDeg, 20.0 / std::exp(1.0));
        const Trace pushed = trace(rateHz, Quatd::Identity(), push);
        const auto peak = std::max_element(pushed.inclDeg.begin(), pushed.inclDeg.end());
        r.pushPeakDeg = *peak;
        r.pushPeakAtS = pushed.t[static_cast<std::size_t>(peak - pushed.inclDeg.begin())];
        return r;
    };
    const Response ref = respond(285.714);
    ASSERT_LT(ref.tiltDecayS, 10.0);
    ASSERT_LT(ref.headingDecayS, 39.0);
    ASSERT_GT(ref.pushPeakDeg, 0.5);  // the push does tilt it: something to compare
    for (const double rate : {50.0, 100.0, 200.0}) {
        const Response r = respond(rate);
        std::printf(
            "%6.1f Hz: tilt decay %.3f s, heading decay %.2f s, push peak %.3f deg at "
            "%.3f s (285.7 Hz: %.3f, %.2f, %.3f at %.3f)\n",
            rate, r.tiltDecayS, r.headingDecayS, r.pushPeakDeg, r.pushPeakAtS, ref.tiltDecayS,
            ref.headingDecayS, ref.pushPeakDeg, ref.pushPeakAtS);
        // Within a sample period or 5 %.
        const double dt = 1.0 / rate;
        EXPECT_NEAR(r.tiltDecayS, ref.tiltDecayS, std::max(dt, 0.05 * ref.tiltDecayS)) << rate;
        EXPECT_NEAR(r.headingDecayS, ref.headingDecayS, std::max(dt, 0.05 * ref.headingDecayS))
            << rate;
        EXPECT_NEAR(r.pushPeakDeg, ref.pushPeakDeg, 0.05 * ref.pushPeakDeg) << rate;
        EXPECT_NEAR(r.pushPeakAtS, ref.pushPeakAtS, std::max(dt, 0.05 * ref.pushPeakAtS)) << rate;
    }
}

TEST(OrientationFilterFixedPoint, MatchesFloatWithin0p05DegUnder16gAndFastMotion) {
    test::SynthConfig c;
    c.rateHz = 285.714;
    auto run = test::synthesize(c, Quatd::Identity(), 40.0, test::wobble(6.0));
    // Shocks of 16 g every 2 s on one sample (tapping): within the Acc range of 52 g.
    for (std::size_t i = 0; i < run.samples.size(); i += 571) {
        run.samples[i].accMps2 += Vec3d(16.0 * 9.81, 0.0, 0.0);
    }
    const auto fl = runFilter(run.samples, c.rateHz, 1, FilterVariant::Float);
    const auto fx = runFilter(run.samples, c.rateHz, 1, FilterVariant::Fixed);
    double worst = 0.0;
    for (std::size_t i = 0; i < fl.size(); ++i) {
        worst = std::max(worst, angleBetween(fl[i], fx[i]));
    }
    // float itself rounds at 6e-8 relative; the Q30 quaternion at 1e-9: the two differ by
    // rounding only, which stays far below 0.05 deg over 40 s.
    EXPECT_LT(worst / kDeg, 0.05);
}

TEST(SteadyStateGains, MatchTheScalarRiccatiSolutionWithoutBias) {
    // One state, random walk q per step, measurement noise r: P = (q + sqrt(q^2 + 4 q r)) / 2
    // before the update, K = P / (P + r).
    const double dt = 0.01;
    const double g = 0.01;
    const double m = 0.05;
    const SteadyGains k = steadyStateGains(dt, g, 0.0, m);
    const double q = g * g * dt;
    const double r = m * m;
    const double p = 0.5 * (q + std::sqrt(q * q + 4.0 * q * r));
    EXPECT_NEAR(k.kAngle, p / (p + r), 1e-9);
    EXPECT_EQ(k.kBias, 0.0);
}

}  // namespace
}  // namespace caphub::fusion
