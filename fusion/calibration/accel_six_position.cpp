#include "fusion/calibration/accel_six_position.h"

#include <cmath>

#include <fmt/format.h>

namespace caphub::fusion {

Result<AccelSixPositionResult> calibrateAccelSixPosition(const std::array<Vec3d, 6>& pos,
                                                         const AccelSixPositionParams& p) {
    constexpr double kDegToRad = 0.017453292519943295;
    static constexpr const char* kAxis = "xyz";
    // Sort the positions by the axis they point along and its sign: [axis][0 = up, 1 = down].
    int slot[3][2] = {{-1, -1}, {-1, -1}, {-1, -1}};
    for (int i = 0; i < 6; ++i) {
        const Vec3d& a = pos[i];
        if (!a.allFinite() || a.norm() < 0.5 * p.gravityMps2) {
            return Error{EINVAL, fmt::format("accel six-position: position {} reads {:.2f} m/s^2, "
                                             "not gravity",
                                             i + 1, a.norm())};
        }
        int axis = 0;
        a.cwiseAbs().maxCoeff(&axis);
        const double tilt = std::acos(std::min(1.0, std::abs(a[axis]) / a.norm()));
        if (tilt > p.maxAxisTiltDeg * kDegToRad) {
            return Error{EINVAL, fmt::format("accel six-position: position {} is tilted {:.1f} deg "
                                             "from its axis (at most {:.1f})",
                                             i + 1, tilt / kDegToRad, p.maxAxisTiltDeg)};
        }
        const int dir = a[axis] > 0 ? 0 : 1;
        if (slot[axis][dir] >= 0) {
            return Error{
                EINVAL, fmt::format("accel six-position: positions {} and {} both have "
                                    "{}{} up; each axis must point up and down once",
                                    slot[axis][dir] + 1, i + 1, dir == 0 ? "+" : "-", kAxis[axis])};
        }
        slot[axis][dir] = i;
    }
    AccelSixPositionResult r;
    for (int k = 0; k < 3; ++k) {
        const double up = pos[slot[k][0]][k];
        const double down = pos[slot[k][1]][k];
        r.offsetMps2[k] = 0.5 * (up + down);
        r.scale[k] = (up - down) / (2.0 * p.gravityMps2);
        if (std::abs(r.scale[k] - 1.0) > p.maxScaleError) {
            return Error{EINVAL, fmt::format("accel six-position: {} scale {:.3f} is implausible",
                                             kAxis[k], r.scale[k])};
        }
    }
    double sum = 0.0;
    for (const auto& a : pos) {
        const double e = (a - r.offsetMps2).cwiseQuotient(r.scale).norm() - p.gravityMps2;
        sum += e * e;
    }
    r.residualMps2 = std::sqrt(sum / 6.0);
    return r;
}

}  // namespace caphub::fusion
