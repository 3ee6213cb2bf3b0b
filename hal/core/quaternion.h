// Quaternion helpers on Eigen, shared by every area. Conventions (docs/frames.md): Hamilton
// product, Eigen::Quaternion in code, w-first in files; q and -q are the same rotation.
#pragma once

#include <array>
#include <cmath>
#include <string_view>

#include <Eigen/Geometry>

namespace caphub {

using Quatd = Eigen::Quaterniond;
using Vec3d = Eigen::Vector3d;

template <typename T>
struct AxisAngle {
    Eigen::Matrix<T, 3, 1> axis;  // unit vector
    T angle;                      // rad, in [0, pi]
};

// Paper eq. (1): sqrt(w^2 + x^2 + y^2 + z^2).
template <typename T>
T quatNorm(const Eigen::Quaternion<T>& q) {
    return q.coeffs().norm();
}

// Paper eq. (2): q / |q|. A zero or non-finite quaternion carries no rotation: identity.
template <typename T>
Eigen::Quaternion<T> normalizedOrIdentity(const Eigen::Quaternion<T>& q) {
    const T n = quatNorm(q);
    if (!(n > T(0)) || !std::isfinite(n)) {
        return Eigen::Quaternion<T>::Identity();
    }
    return Eigen::Quaternion<T>(q.coeffs() / n);
}

// The representative with w >= 0 (on w == 0, the first non-zero of x, y, z positive), so that
// q and -q map to one value.
template <typename T>
Eigen::Quaternion<T> canonical(const Eigen::Quaternion<T>& q) {
    const auto& c = q.coeffs();  // x, y, z, w
    bool negate = c.w() < T(0);
    if (c.w() == T(0)) {
        for (int i = 0; i < 3; ++i) {
            if (c[i] != T(0)) {
                negate = c[i] < T(0);
                break;
            }
        }
    }
    return negate ? Eigen::Quaternion<T>(-c) : q;
}

// Paper eqs. (3)-(6), done robustly. The paper's theta = 2 acos(w) loses precision near
// w = +-1 and its axis = v / sin(theta/2) divides by zero at theta = 0. Here the angle is
// 2 atan2(|v|, |w|), accurate everywhere, and the axis is v / |v|, with +x for the identity.
// q and -q give the same result; the angle is in [0, pi].
template <typename T>
AxisAngle<T> toAxisAngle(const Eigen::Quaternion<T>& q) {
    const Eigen::Quaternion<T> c = canonical(normalizedOrIdentity(q));
    const Eigen::Matrix<T, 3, 1> v = c.vec();
    const T s = v.stableNorm();  // no underflow for tiny angles
    if (s == T(0)) {
        return {Eigen::Matrix<T, 3, 1>::UnitX(), T(0)};
    }
    return {v / s, T(2) * std::atan2(s, c.w())};
}

template <typename T>
Eigen::Quaternion<T> fromAxisAngle(const Eigen::Matrix<T, 3, 1>& axis, T angle) {
    const T n = axis.norm();
    if (!(n > T(0))) {
        return Eigen::Quaternion<T>::Identity();
    }
    const T half = angle / T(2);
    Eigen::Quaternion<T> q;
    q.w() = std::cos(half);
    q.vec() = axis * (std::sin(half) / n);
    return q;
}

// Rotation vector (axis * angle, rad) of q: the logarithm map, with angle in [0, pi].
// Accurate for tiny angles: no 0/0 and no cancellation.
template <typename T>
Eigen::Matrix<T, 3, 1> toRotationVector(const Eigen::Quaternion<T>& q) {
    const Eigen::Quaternion<T> c = canonical(normalizedOrIdentity(q));
    const T s = c.vec().stableNorm();
    const T w = c.w();
    // angle / s = 2 atan2(s, w) / s; its series near s = 0 (w ~ 1) is 2/w (1 - s^2 / (3 w^2)).
    if (s < T(1e-4) && w > T(0.5)) {
        return c.vec() * (T(2) / w * (T(1) - s * s / (T(3) * w * w)));
    }
    return c.vec() * (T(2) * std::atan2(s, w) / s);
}

// The quaternion of a rotation vector: the exponential map, accurate for tiny angles.
template <typename T>
Eigen::Quaternion<T> fromRotationVector(const Eigen::Matrix<T, 3, 1>& rv) {
    const T theta = rv.stableNorm();
    T w;
    T k;  // sin(theta / 2) / theta
    if (theta < T(1e-4)) {
        const T t2 = theta * theta;
        w = T(1) - t2 / T(8);
        k = T(0.5) - t2 / T(48);
    } else {
        w = std::cos(theta / T(2));
        k = std::sin(theta / T(2)) / theta;
    }
    Eigen::Quaternion<T> q;
    q.w() = w;
    q.vec() = rv * k;
    return q.normalized();
}

// The angle of the rotation that takes a to b (rad, in [0, pi]); q and -q are equal.
template <typename T>
T angleBetween(const Eigen::Quaternion<T>& a, const Eigen::Quaternion<T>& b) {
    const Eigen::Quaternion<T> d = normalizedOrIdentity(a).conjugate() * normalizedOrIdentity(b);
    return T(2) * std::atan2(d.vec().norm(), std::abs(d.w()));
}

// Orientation after turning for dt seconds at angular velocity omega given in the body frame
// (rad/s): q * exp(omega dt / 2).
template <typename T>
Eigen::Quaternion<T> integrateBodyRate(const Eigen::Quaternion<T>& q,
                                       const Eigen::Matrix<T, 3, 1>& omega, T dtS) {
    return (q * fromRotationVector<T>(omega * dtS)).normalized();
}

// w-first arrays, as in files and docs.
template <typename T>
Eigen::Quaternion<T> fromWxyz(const std::array<T, 4>& a) {
    return Eigen::Quaternion<T>(a[0], a[1], a[2], a[3]);
}

template <typename T>
std::array<T, 4> toWxyz(const Eigen::Quaternion<T>& q) {
    return {q.w(), q.x(), q.y(), q.z()};
}

// Intrinsic Euler rotation: axes is a permutation of "XYZ" (e.g. "ZXY", as in BVH channel
// order), angles in rad in the same order; the result is R(a0) * R(a1) * R(a2). Returns
// false for an axes string that is not three of X, Y, Z (case-insensitive).
bool fromEulerIntrinsic(std::string_view axes, const Vec3d& anglesRad, Quatd& out);

}  // namespace caphub
