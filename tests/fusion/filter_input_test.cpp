// What the orientation filter does with samples no supported sensor can produce (non-finite, or
// beyond the chips' full scale) and with parameters that give no sample period: it refuses them,
// counts them, and neither its state nor its output becomes non-finite (docs/fusion.md, "Input
// validation"). Float and fixed point alike.
#include <cmath>
#include <limits>
#include <optional>
#include <type_traits>

#include <gtest/gtest.h>

#include "fusion/orientation_filter.h"
#include "tests/fusion/synthetic_imu.h"

namespace caphub::fusion {
namespace {

constexpr double kDeg = 0.017453292519943295;
constexpr double kNan = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

enum class Sensor { Gyr, Acc, Mag };

const char* name(Sensor s) {
    return s == Sensor::Gyr ? "gyroscope" : (s == Sensor::Acc ? "accelerometer" : "magnetometer");
}

bool finite(const Quatd& q) {
    return std::isfinite(q.w()) && std::isfinite(q.x()) && std::isfinite(q.y()) &&
           std::isfinite(q.z());
}

// One sample's reading of one sensor that differs from the recorded one: replaced by `value`, or
// not fed at all (no value).
struct Override {
    std::size_t index = 0;
    Sensor sensor = Sensor::Gyr;
    std::optional<Vec3d> value;
};

template <typename T>
class FilterInputTest : public ::testing::Test {
public:
    static FilterParams params(double rateHz) {
        FilterParams p;
        p.gyrRateHz = p.accRateHz = p.magRateHz = rateHz;
        return p;
    }
    static Quatd quat(const OrientationFilter<T>& f) {
        const auto q = f.quat();
        return {toDouble(q.w), toDouble(q.x), toDouble(q.y), toDouble(q.z)};
    }
    // Feeds every sample (each sensor in turn, as the runtime does); returns the estimates.
    static std::vector<Quatd> run(OrientationFilter<T>& f, const std::vector<ImuSample>& samples,
                                  const std::optional<Override>& o = std::nullopt) {
        std::vector<Quatd> out;
        for (std::size_t i = 0; i < samples.size(); ++i) {
            const ImuSample& x = samples[i];
            const auto reading = [&](Sensor s, const Vec3d& recorded) -> std::optional<Vec3d> {
                if (o && o->index == i && o->sensor == s) {
                    return o->value;
                }
                return recorded;
            };
            if (const auto g = reading(Sensor::Gyr, x.gyrRadS)) {
                f.updateGyr(fromDoubleVec<typename T::Gyr>(g->x(), g->y(), g->z()));
            }
            if (const auto a = reading(Sensor::Acc, x.accMps2)) {
                f.updateAcc(fromDoubleVec<typename T::Acc>(a->x(), a->y(), a->z()));
            }
            if (const auto m = reading(Sensor::Mag, x.magUt)) {
                f.updateMag(fromDoubleVec<typename T::Mag>(m->x(), m->y(), m->z()));
            }
            out.push_back(quat(f));
        }
        return out;
    }
    // 20 s of hand-held-like motion at 100 Hz from a tilted and turned start; noiseless, so that
    // an alignment one sample later is as exact as one at the first sample.
    static test::SynthRun motion(bool noise = true) {
        test::SynthConfig c;
        if (!noise) {
            c.gyrNoiseRadS = c.accNoiseMps2 = c.magNoiseUt = 0.0;
        }
        const Quatd q0 = fromAxisAngle<double>(Vec3d(0.4, -0.2, 1.0), 70.0 * kDeg);
        return test::synthesize(c, q0, 20.0, test::wobble(1.5));
    }
};

using Variants = ::testing::Types<FloatTypes, FixedTypes>;
TYPED_TEST_SUITE(FilterInputTest, Variants);

// A glitched bus read: one reading far beyond any supported chip's full scale (2000 deg/s =
// 35 rad/s, 16 g, 4912 uT), in the first sample (the initial alignment) or during the motion.
// The filter drops it, exactly as if it had not been read, and so stays as close to the run on
// the data without the glitch as one lost reading allows.
TYPED_TEST(FilterInputTest, ASpikeBeyondTheSensorsRangeIsDroppedAndCounted) {
    const auto data = this->motion(false);
    OrientationFilter<TypeParam> clean(this->params(100.0));
    const auto ref = this->run(clean, data.samples);
    const struct {
        Sensor sensor;
        Vec3d spike;
    } cases[] = {{Sensor::Gyr, Vec3d(5000.0, 0.0, 0.0)},
                 {Sensor::Gyr, Vec3d(0.0, -60.0, 0.0)},
                 {Sensor::Acc, Vec3d(0.0, 1000.0, 0.0)},
                 {Sensor::Mag, Vec3d(10000.0, 0.0, 0.0)}};
    for (const auto& c : cases) {
        for (const std::size_t k : {std::size_t{0}, std::size_t{1000}}) {
            OrientationFilter<TypeParam> spiked(this->params(100.0));
            const auto est = this->run(spiked, data.samples, Override{k, c.sensor, c.spike});
            OrientationFilter<TypeParam> unread(this->params(100.0));
            const auto skipped = this->run(unread, data.samples, Override{k, c.sensor, {}});
            double worst = 0.0;
            for (std::size_t i = 0; i < est.size(); ++i) {
                ASSERT_TRUE(finite(est[i])) << name(c.sensor) << " spike at " << k << ", i " << i;
                ASSERT_EQ(est[i].coeffs(), skipped[i].coeffs())
                    << name(c.sensor) << " spike at " << k << ", i " << i;
                if (i >
                    k) {  // at k itself an accelerometer dropped at the start leaves no tilt yet
                    worst = std::max(worst, angleBetween(est[i], ref[i]));
                }
            }
            // Against the run without the glitch: a dropped gyroscope reading loses the turn of
            // its period, |omega| dt (below 0.9 deg at this motion's 1.5 rad/s), which the slow
            // corrections do not undo within the run; a dropped accelerometer or magnetometer
            // reading is one input among thousands to the low-pass and the heading correction
            // (gain 3e-4), and at the first sample the next one aligns as exactly (noiseless
            // data). 0.05 deg above that; a spike that reaches the state turns the estimate by
            // degrees (0.64 rad for the 64 rad/s the fixed-point format holds, over one 10 ms
            // period) or leaves it NaN.
            const double lostDeg =
                c.sensor == Sensor::Gyr ? data.samples[k].gyrRadS.norm() * 0.01 / kDeg : 0.0;
            EXPECT_LT(worst / kDeg, lostDeg + 0.05) << name(c.sensor) << " spike at sample " << k;
            const FilterRejections r = spiked.rejections();
            EXPECT_EQ(r.gyr, c.sensor == Sensor::Gyr ? 1U : 0U) << name(c.sensor);
            EXPECT_EQ(r.acc, c.sensor == Sensor::Acc ? 1U : 0U) << name(c.sensor);
            EXPECT_EQ(r.mag, c.sensor == Sensor::Mag ? 1U : 0U) << name(c.sensor);
            EXPECT_EQ(clean.rejections().samples(), 0U);
        }
    }
}

// NaN or an infinity in one reading of each sensor: the filter ends exactly where it would have
// had that update not been called (in fixed point the conversion marks a NaN as out of range).
TYPED_TEST(FilterInputTest, ANonFiniteReadingIsRejectedAsIfItHadNotBeenRead) {
    const auto data = this->motion();
    for (const Sensor s : {Sensor::Gyr, Sensor::Acc, Sensor::Mag}) {
        for (const Vec3d& bad : {Vec3d(kNan, 0.1, 0.2), Vec3d(0.1, kInf, 0.2),
                                 Vec3d(0.1, 0.2, -kInf), Vec3d(kNan, kNan, kNan)}) {
            for (const std::size_t k : {std::size_t{0}, std::size_t{1000}}) {
                OrientationFilter<TypeParam> f(this->params(100.0));
                const auto est = this->run(f, data.samples, Override{k, s, bad});
                OrientationFilter<TypeParam> skipped(this->params(100.0));
                const auto ref = this->run(skipped, data.samples, Override{k, s, std::nullopt});
                for (std::size_t i = 0; i < est.size(); ++i) {
                    ASSERT_TRUE(finite(est[i])) << name(s) << " at " << k << ": sample " << i;
                    // Exact: a rejected reading must not touch the state at all.
                    ASSERT_EQ(est[i].coeffs(), ref[i].coeffs())
                        << name(s) << " " << bad.transpose() << " at " << k << ": sample " << i;
                }
                EXPECT_EQ(f.rejections().samples(), 1U) << name(s) << " " << bad.transpose();
            }
        }
    }
}

// The body's acceleration handed to updateAcc comes from outside the sensor: a non-finite or
// impossible one is taken as unknown (zero), and counted.
TYPED_TEST(FilterInputTest, AnImplausibleKnownAccelerationIsTakenAsUnknown) {
    const auto data = this->motion();
    using Acc = typename TypeParam::Acc;
    for (const Vec3d& bad : {Vec3d(kNan, 0.0, 0.0), Vec3d(0.0, kInf, 0.0), Vec3d(0.0, 0.0, 1e6)}) {
        OrientationFilter<TypeParam> f(this->params(100.0));
        OrientationFilter<TypeParam> unknown(this->params(100.0));
        for (std::size_t i = 0; i < 300; ++i) {
            const ImuSample& x = data.samples[i];
            for (auto* g : {&f, &unknown}) {
                g->updateGyr(fromDoubleVec<typename TypeParam::Gyr>(x.gyrRadS.x(), x.gyrRadS.y(),
                                                                    x.gyrRadS.z()));
                const Vec3d lin = g == &f && i == 150 ? bad : Vec3d::Zero();
                g->updateAcc(fromDoubleVec<Acc>(x.accMps2.x(), x.accMps2.y(), x.accMps2.z()),
                             fromDoubleVec<Acc>(lin.x(), lin.y(), lin.z()));
                g->updateMag(
                    fromDoubleVec<typename TypeParam::Mag>(x.magUt.x(), x.magUt.y(), x.magUt.z()));
            }
            ASSERT_TRUE(finite(this->quat(f))) << bad.transpose() << ", sample " << i;
            if constexpr (std::is_same_v<TypeParam, FloatTypes>) {
                // The same arithmetic, but the compiler may fuse the multiply-adds (FMA on ARM)
                // differently where it knows the acceleration is zero: equal to float rounding.
                ASSERT_TRUE(this->quat(f).coeffs().isApprox(this->quat(unknown).coeffs(), 1e-6))
                    << bad.transpose() << ", sample " << i;
            } else {
                ASSERT_EQ(this->quat(f).coeffs(), this->quat(unknown).coeffs())
                    << bad.transpose() << ", sample " << i;
            }
        }
        EXPECT_EQ(f.rejections().linAcc, 1U) << bad.transpose();
        EXPECT_EQ(f.rejections().samples(), 0U) << bad.transpose();
    }
}

// The filter's sample periods come from its rates at setup (there is no per-sample dt): a rate
// of zero, below zero, NaN or infinite gives no period. The filter refuses such parameters,
// names the first bad one, and rejects every sample: its output stays the identity, finite.
TYPED_TEST(FilterInputTest, ARateThatGivesNoSamplePeriodIsRefused) {
    const auto data = this->motion();
    const std::vector<ImuSample> first(data.samples.begin(), data.samples.begin() + 50);
    for (const char* field : {"gyrRateHz", "accRateHz", "magRateHz"}) {
        for (const double rate : {0.0, -100.0, kNan, kInf}) {
            FilterParams p = this->params(100.0);
            double& r = std::string(field) == "gyrRateHz"
                            ? p.gyrRateHz
                            : (std::string(field) == "accRateHz" ? p.accRateHz : p.magRateHz);
            r = rate;
            ASSERT_NE(invalidFilterParameter(p), nullptr) << field << " = " << rate;
            EXPECT_STREQ(invalidFilterParameter(p), field) << field << " = " << rate;
            OrientationFilter<TypeParam> f(p);
            EXPECT_FALSE(f.configured()) << field << " = " << rate;
            const auto est = this->run(f, first);
            for (const auto& q : est) {
                ASSERT_TRUE(finite(q)) << field << " = " << rate;
                // Without the refusal the first accelerometer sample would align the tilt (70
                // deg from the identity here).
                ASSERT_EQ(q.coeffs(), Quatd::Identity().coeffs()) << field << " = " << rate;
            }
            const FilterRejections rej = f.rejections();
            EXPECT_EQ(rej.gyr, first.size());
            EXPECT_EQ(rej.acc, first.size());
            EXPECT_EQ(rej.mag, first.size());
        }
    }
    EXPECT_EQ(invalidFilterParameter(this->params(100.0)), nullptr);
    EXPECT_EQ(invalidFilterParameter(FilterParams{}), nullptr);
    EXPECT_TRUE(OrientationFilter<TypeParam>(this->params(100.0)).configured());
}

// A rate within the gyroscope's range can still be a turn of many rad per sample at a low sample
// rate (40 rad/s at 1 Hz), which the strapdown's series exp map cannot follow: the float state
// used to diverge to NaN and the fixed-point quaternion drifted off the unit sphere (|q|^2 0.6).
// The filter restarts instead, counts it, and its output stays a unit quaternion.
TYPED_TEST(FilterInputTest, ATurnTooFastForTheSampleRateRestartsTheFilterInsteadOfDiverging) {
    OrientationFilter<TypeParam> f(this->params(1.0));
    for (int i = 0; i < 50; ++i) {
        f.updateGyr(fromDoubleVec<typename TypeParam::Gyr>(40.0, 5.0, 0.0));
        f.updateAcc(fromDoubleVec<typename TypeParam::Acc>(0.0, 0.0, 9.81));
        f.updateMag(fromDoubleVec<typename TypeParam::Mag>(0.0, 19.0, -45.0));
        const Quatd q = this->quat(f);
        ASSERT_TRUE(finite(q)) << "sample " << i;
        // Renormalised each update: unit to far better than 1 %.
        ASSERT_NEAR(q.squaredNorm(), 1.0, 0.01) << "sample " << i;
    }
    EXPECT_GE(f.rejections().stateResets, 1U);
    EXPECT_EQ(f.rejections().samples(), 0U);  // no reading was beyond its limit
}

// A non-finite state cannot come from checked inputs, but a snapshot (setState) can carry one:
// the filter notices after its next update, restarts, counts it, and re-aligns from the next
// good samples. Float only: a fixed-point state has no NaN.
TEST(FilterInputFloat, ANonFiniteStateRestartsFromTheNextGoodSample) {
    test::SynthConfig c;
    const Quatd q0 = fromAxisAngle<double>(Vec3d(1.0, 0.3, 0.2), 40.0 * kDeg);
    const auto data = test::synthesize(c, q0, 8.0, [](double) -> Vec3d { return Vec3d::Zero(); });
    OrientationFilter<FloatTypes> f(FilterInputTest<FloatTypes>::params(c.rateHz));
    std::vector<ImuSample> before(data.samples.begin(), data.samples.begin() + 300);
    std::vector<ImuSample> after(data.samples.begin() + 300, data.samples.end());
    FilterInputTest<FloatTypes>::run(f, before);
    FilterState<FloatTypes> s = f.state();
    s.qCorr.w = std::numeric_limits<float>::quiet_NaN();
    s.bias.y = std::numeric_limits<float>::infinity();
    f.setState(s);
    const auto est = FilterInputTest<FloatTypes>::run(f, after);
    for (std::size_t i = 0; i < est.size(); ++i) {
        ASSERT_TRUE(finite(est[i])) << "sample " << i << " after the bad state";
    }
    // Re-aligned from the first sample after the restart, as a new filter started there: the
    // restart only loses that sample's gyroscope reading (the sensor is still) and its rest
    // low-pass history, which differ by far less than 0.05 deg (a state that stayed bad, or a
    // restart from a stale orientation, is off by NaN or by the 40 deg tilt).
    OrientationFilter<FloatTypes> fresh(FilterInputTest<FloatTypes>::params(c.rateHz));
    const auto ref = FilterInputTest<FloatTypes>::run(fresh, after);
    for (std::size_t i = 0; i < est.size(); ++i) {
        ASSERT_LT(angleBetween(est[i], ref[i]) / kDeg, 0.05) << "sample " << i;
    }
    EXPECT_EQ(f.rejections().stateResets, 1U);
    EXPECT_EQ(f.rejections().samples(), 0U);
}

}  // namespace
}  // namespace caphub::fusion
