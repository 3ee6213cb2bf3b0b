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

namespace {

// Per-axis mean and largest per-axis standard deviation of a window.
void windowStats(std::span<const Vec3d> v, Vec3d& mean, double& maxStd) {
    mean = Vec3d::Zero();
    for (const auto& x : v) {
        mean += x;
    }
    mean /= static_cast<double>(v.size());
    Vec3d var = Vec3d::Zero();
    for (const auto& x : v) {
        var += (x - mean).cwiseAbs2();
    }
    maxStd = std::sqrt(var.maxCoeff() / static_cast<double>(v.size()));
}

}  // namespace

Result<std::array<Vec3d, 6>> findSixPositions(std::span<const Vec3d> acc,
                                              std::span<const Vec3d> gyr, double rateHz,
                                              const StillPositionParams& p) {
    constexpr double kRadToDeg = 57.29577951308232;
    if (acc.size() != gyr.size() || rateHz <= 0) {
        return Error{EINVAL, "accel six-position: accelerometer and gyroscope streams differ"};
    }
    const auto n = static_cast<std::size_t>(std::max(2.0, std::round(p.windowS * rateHz)));
    std::array<Vec3d, 6> sum;
    sum.fill(Vec3d::Zero());
    std::array<std::size_t, 6> count{};
    for (std::size_t start = 0; start + n <= acc.size(); start += n) {
        Vec3d accMean;
        Vec3d gyrMean;
        double accStd = 0;
        double gyrStd = 0;
        windowStats(acc.subspan(start, n), accMean, accStd);
        windowStats(gyr.subspan(start, n), gyrMean, gyrStd);
        if (accStd > p.maxAccStdMps2 || gyrStd * kRadToDeg > p.maxGyroStdDps) {
            continue;
        }
        int axis = 0;
        accMean.cwiseAbs().maxCoeff(&axis);
        const auto slot = static_cast<std::size_t>(2 * axis + (accMean[axis] > 0 ? 0 : 1));
        sum[slot] += accMean * static_cast<double>(n);
        count[slot] += n;
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
