#include "fusion/calibration/accel_six_position.h"

#include <cmath>

#include <fmt/format.h>

#include "hal/core/angles.h"

namespace caphub::fusion {

Result<AccelSixPositionResult> calibrateAccelSixPosition(const std::array<Vec3d, 6>& pos,
                                                         const AccelSixPositionParams& p) {
    using hal::kDegToRad;
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

Result<std::array<Vec3d, 6>> findSixPositions(std::span<const Vec3d> acc,
                                              std::span<const Vec3d> gyr, double rateHz,
                                              const StillPositionParams& p) {
    auto runs = findStillIntervals(acc, gyr, rateHz, p);
    if (!runs) {
        return runs.error();
    }
    // Every still run counts towards the position its largest axis points to.
    std::array<Vec3d, 6> sum;
    sum.fill(Vec3d::Zero());
    std::array<std::size_t, 6> count{};
    for (const auto& r : *runs) {
        int axis = 0;
        r.meanAccMps2.cwiseAbs().maxCoeff(&axis);
        const auto slot = static_cast<std::size_t>(2 * axis + (r.meanAccMps2[axis] > 0 ? 0 : 1));
        sum[slot] += r.meanAccMps2 * static_cast<double>(r.size());
        count[slot] += r.size();
    }
    static constexpr const char* kNames[6] = {"+x", "-x", "+y", "-y", "+z", "-z"};
    std::string missing;
    const auto needed = static_cast<std::size_t>(p.minStillS * rateHz);
    std::array<Vec3d, 6> means;
    for (std::size_t k = 0; k < 6; ++k) {
        if (count[k] < needed || count[k] == 0) {
            missing += fmt::format("{}{} up ({:.1f} s still)", missing.empty() ? "" : ", ",
                                   kNames[k], static_cast<double>(count[k]) / rateHz);
        } else {
            means[k] = sum[k] / static_cast<double>(count[k]);
        }
    }
    if (!missing.empty()) {
        return Error{EINVAL, fmt::format("accel six-position: too little still time in {} (need "
                                         "{:.1f} s each): turn the sensor so that each axis "
                                         "points up and down, and hold it still in each",
                                         missing, p.minStillS)};
    }
    return means;
}

}  // namespace caphub::fusion
