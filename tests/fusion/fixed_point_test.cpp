// The Q-format scalar: conversion, rounding, saturation, normalisation and the series exp map.
#include "fusion/fixed_point.h"

#include <algorithm>
#include <cmath>
#include <cstdint>

#include <gtest/gtest.h>

#include "fusion/scalar_ops.h"
#include "hal/core/quaternion.h"

namespace caphub::fusion {
namespace {

TEST(FixedPoint, ConvertsToTheNearestStep) {
    using Q = Fixed<30>;
    const double step = std::ldexp(1.0, -30);
    EXPECT_EQ(Q::fromDouble(0.5).raw, 1 << 29);
    EXPECT_EQ(Q::fromDouble(-0.25).raw, -(1 << 28));
    // Half a step and more rounds up, less rounds down.
    EXPECT_EQ(Q::fromDouble(0.6 * step).raw, 1);
    EXPECT_EQ(Q::fromDouble(0.4 * step).raw, 0);
    EXPECT_DOUBLE_EQ(Q::fromDouble(0.123456789).toDouble(), std::round(0.123456789 / step) * step);
}

TEST(FixedPoint, SaturatesInsteadOfWrappingOutsideItsRange) {
    using Q = Fixed<30>;  // [-2, 2)
    EXPECT_EQ(Q::fromDouble(5.0).raw, std::numeric_limits<std::int32_t>::max());
    EXPECT_EQ(Q::fromDouble(-5.0).raw, std::numeric_limits<std::int32_t>::min());
    // NaN has no side: it goes to the bottom, where the filter's input check rejects it.
    EXPECT_EQ(Q::fromDouble(std::nan("")).raw, std::numeric_limits<std::int32_t>::min());
    EXPECT_TRUE(Q::fromDouble(std::nan("")).saturated());
    EXPECT_TRUE(Q::fromDouble(5.0).saturated());
    EXPECT_FALSE(Q::fromDouble(1.999).saturated());
    // A product that does not fit the target format saturates too.
    const auto big = Fixed<20>::fromDouble(1500.0) * Fixed<20>::fromDouble(1500.0);
    EXPECT_EQ(scalarCast<Fixed<20>>(big).raw, std::numeric_limits<std::int32_t>::max());
}

TEST(FixedPoint, ProductsRoundToNearestInTheTargetFormat) {
    const auto a = Fixed<25>::fromDouble(3.7);
    const auto b = Fixed<30>::fromDouble(0.0035);
    const double exact = a.toDouble() * b.toDouble();
    const auto p = scalarCast<Fixed<30>>(a * b);
    // Round to nearest: within half a step of the exact product of the two stored values.
    EXPECT_LE(std::abs(p.toDouble() - exact), 0.5 * std::ldexp(1.0, -30));
}

TEST(FixedPoint, NormalisesVectorsOfAnyFormatToUnitLength) {
    // Magnitudes from 1e-3 to 1e3 uT in Q20 and m/s^2 in Q22: the result is a unit vector to
    // within a few Q30 steps (the Newton inverse square root converges to 1e-9).
    for (double scale : {1e-3, 0.1, 1.0, 45.0, 900.0}) {
        const Vec3<Fixed<20>> v = fromDoubleVec<Fixed<20>>(0.3 * scale, -0.5 * scale, 0.8 * scale);
        Vec3<Fixed<30>> u;
        ASSERT_TRUE(normalizeInto(v, u));
        const Vec3<double> d = toDoubleVec(u);
        const Vec3<double> in = toDoubleVec(v);
        const double n = std::sqrt(in.x * in.x + in.y * in.y + in.z * in.z);
        EXPECT_NEAR(d.x, in.x / n, 1e-8) << scale;
        EXPECT_NEAR(d.y, in.y / n, 1e-8) << scale;
        EXPECT_NEAR(d.z, in.z / n, 1e-8) << scale;
    }
}

TEST(FixedPoint, InverseSquareRootIsWithinOneAndAQuarterStepsOverItsWholeDomain) {
    // The input's top 30 bits are the value it is computed for (v in Q30, [0.25, 1]): every
    // 9973rd of them (about 81,000, every seed interval many times) and both ends. The table seed
    // and its two Newton steps stay within 1.25 Q30 steps of the exact value (1.24 over all
    // inputs when the table was written).
    const std::int64_t lo = std::int64_t{1} << 58;
    const std::int64_t hi = std::int64_t{1} << 60;
    double worst = 0.0;
    auto check = [&](std::int64_t m) {
        const double v = std::ldexp(static_cast<double>(m >> 30), -30);
        const double exact = std::ldexp(1.0 / std::sqrt(v), 30);
        const double err = std::abs(static_cast<double>(detail::rsqrtNormalizedQ30(m)) - exact);
        worst = std::max(worst, err);
        EXPECT_LE(err, 1.25) << m;
    };
    check(lo);
    check(hi);
    for (std::int64_t v = lo >> 30; v <= hi >> 30; v += 9973) {
        check((v << 30) | (v & 0x3fffffff));  // low bits that the computation shifts out
    }
    EXPECT_GT(worst, 0.5);  // the check saw rounding, not a table of exact answers
}

TEST(FixedPoint, RefusesToNormaliseTheZeroVector) {
    Vec3<Fixed<30>> u = fromDoubleVec<Fixed<30>>(1.0, 0.0, 0.0);
    EXPECT_FALSE(normalizeInto(Vec3<Fixed<22>>{}, u));
    EXPECT_EQ(u.x.raw, Fixed<30>::fromDouble(1.0).raw);  // untouched
}

TEST(ScalarOps, SeriesExpMapMatchesTheExactRotationUpTo0p5Rad) {
    for (double angle : {1e-6, 0.01, 0.1, 0.3, 0.5}) {
        const Vec3<float> tf{static_cast<float>(angle * 0.6), static_cast<float>(angle * 0.8),
                             0.0f};
        const Quat<float> qf = smallRotation(tf);
        const Vec3<Fixed<30>> tx = fromDoubleVec<Fixed<30>>(angle * 0.6, angle * 0.8, 0.0);
        const Quat<Fixed<30>> qx = smallRotation(tx);
        const double w = std::cos(angle / 2);
        const double s = std::sin(angle / 2);
        // The fourth-order series leaves ~angle^6 / 46080 (3.4e-7 at 0.5 rad); float adds its
        // own 1e-7 rounding.
        EXPECT_NEAR(qf.w, w, 6e-7) << angle;
        EXPECT_NEAR(qf.x, 0.6 * s, 6e-7) << angle;
        EXPECT_NEAR(qx.w.toDouble(), w, 4e-7) << angle;
        EXPECT_NEAR(qx.y.toDouble(), 0.8 * s, 4e-7) << angle;
    }
}

TEST(ScalarOps, RotateMatchesEigenForBothScalars) {
    const Quatd q = Quatd(Eigen::AngleAxisd(1.1, Vec3d(0.2, -0.7, 0.4).normalized()));
    const Vec3d v(9.0, -3.0, 40.0);
    const Vec3d expect = q * v;
    const Quat<Fixed<30>> qx{Fixed<30>::fromDouble(q.w()), Fixed<30>::fromDouble(q.x()),
                             Fixed<30>::fromDouble(q.y()), Fixed<30>::fromDouble(q.z())};
    const auto rx = toDoubleVec(rotate(qx, fromDoubleVec<Fixed<22>>(v.x(), v.y(), v.z())));
    // Q22 steps are 2.4e-7 m/s^2 and the quaternion's 1e-9: a few steps of error at most.
    EXPECT_NEAR(rx.x, expect.x(), 2e-6);
    EXPECT_NEAR(rx.y, expect.y(), 2e-6);
    EXPECT_NEAR(rx.z, expect.z(), 2e-6);
    const Quat<float> qf{static_cast<float>(q.w()), static_cast<float>(q.x()),
                         static_cast<float>(q.y()), static_cast<float>(q.z())};
    const auto rf = rotate(qf, Vec3<float>{9.0f, -3.0f, 40.0f});
    EXPECT_NEAR(rf.z, expect.z(), 1e-4);  // float: 40 * 1e-7 relative, with margin
}

}  // namespace
}  // namespace caphub::fusion
