// Accelerometer offset and per-axis scale from six static positions: each axis pointing up and
// down once (in any order). Each position is the mean of a still recording.
#pragma once

#include <array>

#include "hal/core/error.h"
#include "hal/core/quaternion.h"

namespace caphub::fusion {

struct AccelSixPositionParams {
    double gravityMps2 = 9.81;
    double maxAxisTiltDeg = 15.0;  // deg, largest tilt of the pointing axis from vertical
    double maxScaleError = 0.2;    // a fitted scale outside 1 +- this is refused
};

struct AccelSixPositionResult {
    Vec3d offsetMps2 = Vec3d::Zero();  // acc = (raw - offset) / scale
    Vec3d scale = Vec3d::Ones();
    double residualMps2 = 0.0;  // RMS of |corrected| - g over the six positions
};

Result<AccelSixPositionResult> calibrateAccelSixPosition(const std::array<Vec3d, 6>& meanAccMps2,
                                                         const AccelSixPositionParams& params = {});

}  // namespace caphub::fusion
