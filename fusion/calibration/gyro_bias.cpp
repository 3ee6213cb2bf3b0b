#include "fusion/calibration/gyro_bias.h"

#include <cmath>

#include <fmt/format.h>

#include "hal/core/angles.h"

namespace caphub::fusion {

Result<GyroBiasResult> estimateGyroBias(std::span<const Vec3d> gyr, const GyroBiasParams& p) {
    using hal::kRadToDeg;
    if (static_cast<int>(gyr.size()) < p.minSamples) {
        return Error{EINVAL, fmt::format("gyro bias: {} samples, need at least {}", gyr.size(),
                                         p.minSamples)};
    }
    // Two passes (mean, then spread) rather than sum of squares: no cancellation.
    Vec3d mean = Vec3d::Zero();
    for (const auto& g : gyr) {
        if (!g.allFinite()) {
            return Error{EINVAL, "gyro bias: a sample is not finite"};
        }
        mean += g;
    }
    mean /= static_cast<double>(gyr.size());
    Vec3d var = Vec3d::Zero();
    for (const auto& g : gyr) {
        var += (g - mean).cwiseAbs2();
    }
    var /= static_cast<double>(gyr.size() - 1);
    GyroBiasResult r;
    r.biasRadS = mean;
    r.stdRadS = var.cwiseSqrt();
    r.samples = static_cast<int>(gyr.size());
    const double worstDps = r.stdRadS.maxCoeff() * kRadToDeg;
    if (worstDps > p.maxStdDps) {
        return Error{EINVAL, fmt::format("gyro bias: the sensor moved (rate spread {:.2f} deg/s, "
                                         "at most {:.2f} deg/s at rest)",
                                         worstDps, p.maxStdDps)};
    }
    return r;
}

}  // namespace caphub::fusion
