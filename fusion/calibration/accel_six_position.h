// Accelerometer offset and per-axis scale from six static positions: each axis pointing up and
// down once (in any order). Each position is the mean of a still recording.
#pragma once

#include <array>
#include <span>

#include "fusion/calibration/still_intervals.h"
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

// Finding the six positions in a stream: the sensor was turned so that each axis pointed up and
// down in turn, held still a while in each (in any order, with any motion in between).
// The mean specific force of the still windows in each of the six positions, ordered +x, -x,
// +y, -y, +z, -z up. Refused, naming the positions missing, when one has too little still time.
Result<std::array<Vec3d, 6>> findSixPositions(std::span<const Vec3d> accMps2,
                                              std::span<const Vec3d> gyrRadS, double rateHz,
                                              const StillPositionParams& params = {});

}  // namespace caphub::fusion
