#include "firmware/export/euler.h"

#include <cmath>
#include <numbers>

namespace caphub::firmware::exporter {

EulerZxyDeg eulerZxyDeg(const Quatd& q) {
    // R = Rz(a) Rx(b) Ry(c) multiplies out to
    //   [ ca cc - sa sb sc   -sa cb   ca sc + sa sb cc ]
    //   [ sa cc + ca sb sc    ca cb   sa sc - ca sb cc ]
    //   [ -cb sc              sb      cb cc            ]
    const Eigen::Matrix3d r = normalizedOrIdentity(q).toRotationMatrix();
    const double cb = std::hypot(r(0, 1), r(1, 1));  // |cos b|; b is taken in [-90, 90]
    double a = 0;
    double b = std::atan2(r(2, 1), cb);  // accurate at every angle, unlike asin(r21)
    double c = 0;
    // Below this, a and c are no longer separately determined (their error grows as 1e-16 / cb)
    // while only a + sin(b) c matters: c is set to 0 and a taken from the first column. The
    // rotation this represents differs from q by at most about 2 cb rad (2e-6 rad, 1e-4 deg).
    constexpr double kLockedCos = 1e-6;
    if (cb > kLockedCos) {
        a = std::atan2(-r(0, 1), r(1, 1));
        c = std::atan2(-r(2, 0), r(2, 2));
    } else {
        a = std::atan2(r(1, 0), r(0, 0));  // with c = 0: first column is (ca, sa, 0)
    }
    constexpr double kDeg = 180.0 / std::numbers::pi;
    return {a * kDeg, b * kDeg, c * kDeg};
}

}  // namespace caphub::firmware::exporter
