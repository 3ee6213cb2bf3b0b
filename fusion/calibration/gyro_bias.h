// Gyroscope bias from a recording at rest: the mean rate, refused when the sensor moved.
#pragma once

#include <span>

#include "hal/core/error.h"
#include "hal/core/quaternion.h"

namespace caphub::fusion {

struct GyroBiasParams {
    double maxStdDps = 0.5;  // deg/s, largest per-axis standard deviation accepted as "at rest"
    int minSamples = 100;    // fewer samples are refused
};

struct GyroBiasResult {
    Vec3d biasRadS = Vec3d::Zero();
    Vec3d stdRadS = Vec3d::Zero();  // per-axis standard deviation of the samples
    int samples = 0;
};

Result<GyroBiasResult> estimateGyroBias(std::span<const Vec3d> gyrRadS,
                                        const GyroBiasParams& params = {});

}  // namespace caphub::fusion
