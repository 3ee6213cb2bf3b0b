#include "firmware/stream/unity_frame.h"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace caphub::firmware::unity {

Eigen::Vector3f eulerZxyDeg(const Eigen::Quaternionf& qIn) {
    // R = Ry(y) Rx(x) Rz(z): R12 = -sin x, R02 = sin y cos x, R22 = cos y cos x,
    // R10 = cos x sin z, R11 = cos x cos z.
    const Eigen::Matrix3d r = qIn.cast<double>().normalized().toRotationMatrix();
    constexpr double kDeg = 180.0 / std::numbers::pi;
    const double sx = std::clamp(-r(1, 2), -1.0, 1.0);
    const double x = std::asin(sx);
    double y = 0;
    double z = 0;
    if (std::abs(sx) < 0.9999995) {
        y = std::atan2(r(0, 2), r(2, 2));
        z = std::atan2(r(1, 0), r(1, 1));
    } else {
        // cos x = 0: only y - z (x = 90) or y + z (x = -90) is defined; z = 0 takes it in y.
        // With z = 0: R00 = cos y, R20 = -sin y (for either sign of x).
        y = std::atan2(-r(2, 0), r(0, 0));
    }
    return Eigen::Vector3d(x * kDeg, y * kDeg, z * kDeg).cast<float>();
}

Eigen::Quaternionf fromEulerZxyDeg(const Eigen::Vector3f& deg) {
    constexpr float kRad = std::numbers::pi_v<float> / 180.0f;
    return Eigen::AngleAxisf(deg.y() * kRad, Eigen::Vector3f::UnitY()) *
           Eigen::AngleAxisf(deg.x() * kRad, Eigen::Vector3f::UnitX()) *
           Eigen::AngleAxisf(deg.z() * kRad, Eigen::Vector3f::UnitZ());
}

}  // namespace caphub::firmware::unity
