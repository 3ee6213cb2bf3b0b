// Small vectors and quaternions over a filter scalar (float or a Fixed format), with the handful
// of operations the orientation filter needs, written once for both: products go through
// scalarCast so a fixed-point build rounds exactly where the code says.
#pragma once

#include <cmath>

#include "fusion/fixed_point.h"

namespace caphub::fusion {

template <typename T>
struct Vec3 {
    T x{}, y{}, z{};
};

// Hamilton quaternion, w first.
template <typename T>
struct Quat {
    T w{}, x{}, y{}, z{};
    static constexpr Quat identity() { return {fromDouble<T>(1.0), T{}, T{}, T{}}; }
};

template <typename T>
constexpr Vec3<T> operator+(const Vec3<T>& a, const Vec3<T>& b) {
    return {a.x + b.x, a.y + b.y, a.z + b.z};
}
template <typename T>
constexpr Vec3<T> operator-(const Vec3<T>& a, const Vec3<T>& b) {
    return {a.x - b.x, a.y - b.y, a.z - b.z};
}

// k * v in the format of v.
template <typename K, typename T>
constexpr Vec3<T> scaled(K k, const Vec3<T>& v) {
    return {scalarCast<T>(k * v.x), scalarCast<T>(k * v.y), scalarCast<T>(k * v.z)};
}

template <typename To, typename T>
constexpr Vec3<To> castVec(const Vec3<T>& v) {
    if constexpr (std::is_same_v<To, T>) {
        return v;
    } else {
        return {scalarCast<To>(v.x), scalarCast<To>(v.y), scalarCast<To>(v.z)};
    }
}

// |v| <= limit on every axis: the filter's input check. False for NaN and the infinities in
// float; in fixed point false for a saturated value (beyond the format's range, or NaN, both of
// which Fixed::fromDouble saturates), whatever the limit, so a limit beyond the range means
// "up to the range".
inline bool withinLimit(float v, float limit) {
    return std::fabs(v) <= limit;  // false for NaN; inf > any finite limit
}
template <int F>
constexpr bool withinLimit(Fixed<F> v, Fixed<F> limit) {
    return !v.saturated() && absOf(v) <= limit;
}
template <typename T>
bool withinLimit(const Vec3<T>& v, T limit) {
    // Bitwise: three compares and one branch, the caller's.
    return withinLimit(v.x, limit) & withinLimit(v.y, limit) & withinLimit(v.z, limit);
}

template <typename T>
Vec3<double> toDoubleVec(const Vec3<T>& v) {
    return {toDouble(v.x), toDouble(v.y), toDouble(v.z)};
}

template <typename T>
Vec3<T> fromDoubleVec(double x, double y, double z) {
    return {fromDouble<T>(x), fromDouble<T>(y), fromDouble<T>(z)};
}

// a * b (Hamilton), in the format of the quaternions (unit quaternions: every sum stays in [-1,
// 1]).
template <typename Q>
constexpr Quat<Q> quatMul(const Quat<Q>& a, const Quat<Q>& b) {
    return {scalarCast<Q>(a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z),
            scalarCast<Q>(a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y),
            scalarCast<Q>(a.w * b.y - a.x * b.z + a.y * b.w + a.z * b.x),
            scalarCast<Q>(a.w * b.z + a.x * b.y - a.y * b.x + a.z * b.w)};
}

template <typename Q>
constexpr Quat<Q> conjugate(const Quat<Q>& q) {
    return {q.w, -q.x, -q.y, -q.z};
}

// q v q* for a unit quaternion: v + w t + u x t with t = 2 u x v (15 products, no matrix).
template <typename Q, typename T>
constexpr Vec3<T> rotate(const Quat<Q>& q, const Vec3<T>& v) {
    const T tx = twice(scalarCast<T>(q.y * v.z - q.z * v.y));
    const T ty = twice(scalarCast<T>(q.z * v.x - q.x * v.z));
    const T tz = twice(scalarCast<T>(q.x * v.y - q.y * v.x));
    return {v.x + scalarCast<T>(q.w * tx + q.y * tz - q.z * ty),
            v.y + scalarCast<T>(q.w * ty + q.z * tx - q.x * tz),
            v.z + scalarCast<T>(q.w * tz + q.x * ty - q.y * tx)};
}

// Renormalises a quaternion that is already close to unit length (it drifts by rounding and by
// the small corrections only; |n - 1| < 1e-3 leaves a residual of 1.5e-6 that the next call
// removes): one Newton step of 1/sqrt(n) around n = 1, (3 - n) / 2 = 1 + (1 - n) / 2 (written so
// that no constant leaves the Q30 range), with no square root and no division.
template <typename Q>
Quat<Q> renormalized(const Quat<Q>& q) {
    const Q one = fromDouble<Q>(1.0);
    const Q n = scalarCast<Q>(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z);
    const Q f = one + half(one - n);
    return {scalarCast<Q>(f * q.w), scalarCast<Q>(f * q.x), scalarCast<Q>(f * q.y),
            scalarCast<Q>(f * q.z)};
}

// The unit vector of v in the unit format U (Fixed<30> or float); false for a zero vector.
template <int F>
bool normalizeInto(const Vec3<Fixed<F>>& v, Vec3<Fixed<30>>& out) {
    const Fixed<F> in[3] = {v.x, v.y, v.z};
    Fixed<30> o[3];
    if (!normalizeToQ30(in, o)) {
        return false;
    }
    out = {o[0], o[1], o[2]};
    return true;
}
inline bool normalizeInto(const Vec3<float>& v, Vec3<float>& out) {
    const float n2 = v.x * v.x + v.y * v.y + v.z * v.z;
    if (!(n2 > 0.0f) || !std::isfinite(n2)) {
        return false;
    }
    const float f = 1.0f / std::sqrt(n2);
    out = {v.x * f, v.y * f, v.z * f};
    return true;
}

// A unit quaternion from a non-zero one of any scale (the initial alignments build one from a
// half-angle construction).
template <int F>
bool normalizeInto(const Quat<Fixed<F>>& q, Quat<Fixed<30>>& out) {
    const Fixed<F> in[4] = {q.w, q.x, q.y, q.z};
    Fixed<30> o[4];
    if (!normalizeToQ30(in, o)) {
        return false;
    }
    out = {o[0], o[1], o[2], o[3]};
    return true;
}
inline bool normalizeInto(const Quat<float>& q, Quat<float>& out) {
    const float n2 = q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z;
    if (!(n2 > 0.0f) || !std::isfinite(n2)) {
        return false;
    }
    const float f = 1.0f / std::sqrt(n2);
    out = {q.w * f, q.x * f, q.y * f, q.z * f};
    return true;
}

// 2-vector normalisation (the horizontal part of the magnetic field).
template <typename U>
bool normalize2(U& x, U& y) {
    if constexpr (std::is_floating_point_v<U>) {
        const U n2 = x * x + y * y;
        if (!(n2 > U(0))) {
            return false;
        }
        const U f = U(1) / std::sqrt(n2);
        x *= f;
        y *= f;
        return true;
    } else {
        const U in[2] = {x, y};
        Fixed<30> o[2];
        if (!normalizeToQ30(in, o)) {
            return false;
        }
        x = scalarCast<U>(o[0]);
        y = scalarCast<U>(o[1]);
        return true;
    }
}

// exp of a small rotation vector theta (rad): [cos(|t|/2), sin(|t|/2) t/|t|] by its series to
// fourth order, exact to 1e-7 rad for |theta| <= 0.5 rad (a 25 rad/s turn sampled at 50 Hz). No
// trigonometry on the per-sample path. Not renormalised: its norm is 1 within 3.4e-7 at 0.5 rad
// (1e-17 at a typical 0.01 rad), and a norm does not change the rotation a quaternion stands for;
// every caller renormalises the product it is multiplied into.
template <typename U>
Quat<U> smallRotation(const Vec3<U>& theta) {
    const U t2 = scalarCast<U>(theta.x * theta.x + theta.y * theta.y + theta.z * theta.z);
    const U t4 = scalarCast<U>(t2 * t2);
    const U c8 = fromDouble<U>(1.0 / 8.0);
    const U c384 = fromDouble<U>(1.0 / 384.0);
    const U c48 = fromDouble<U>(1.0 / 48.0);
    const U c3840 = fromDouble<U>(1.0 / 3840.0);
    const U w = fromDouble<U>(1.0) - scalarCast<U>(c8 * t2) + scalarCast<U>(c384 * t4);
    // sin(t/2)/t = 1/2 - t^2/48 + t^4/3840
    const U k = fromDouble<U>(0.5) - scalarCast<U>(c48 * t2) + scalarCast<U>(c3840 * t4);
    return Quat<U>{w, scalarCast<U>(k * theta.x), scalarCast<U>(k * theta.y),
                   scalarCast<U>(k * theta.z)};
}

}  // namespace caphub::fusion
