// The calibration of one 9-axis sensor and how it is applied to raw samples before the filter:
// gyroscope bias and axes, accelerometer offset and axes (scale and cross-axis), magnetometer
// hard and soft iron.
#pragma once

#include <Eigen/Core>

#include "fusion/evaluation.h"

namespace caphub::fusion {

struct SensorCalibration {
    bool hasGyro = false;
    Vec3d gyroBiasRadS = Vec3d::Zero();  // subtracted from the rate
    bool hasGyroAxes = false;
    Eigen::Matrix3d gyroMatrix = Eigen::Matrix3d::Identity();  // gyr = matrix * (raw - bias)

    bool hasAccel = false;
    Vec3d accOffsetMps2 = Vec3d::Zero();                      // acc = matrix * (raw - offset)
    Eigen::Matrix3d accMatrix = Eigen::Matrix3d::Identity();  // diagonal: per-axis 1 / scale

    bool hasMag = false;
    Vec3d magHardIronUt = Vec3d::Zero();  // mag = softIron * (raw - hardIron)
    Eigen::Matrix3d magSoftIron = Eigen::Matrix3d::Identity();
    double magQualityPct = 0.0;  // RMS deviation of the corrected norm from the field norm, %
    double magCoverage = 0.0;    // fraction of the 26 sphere directions the data visited

    // The calibrated sample (the uncalibrated parts pass through unchanged).
    ImuSample apply(const ImuSample& raw) const {
        ImuSample s = raw;
        if (hasGyro) {
            s.gyrRadS = raw.gyrRadS - gyroBiasRadS;
        }
        if (hasGyroAxes) {
            s.gyrRadS = gyroMatrix * s.gyrRadS;
        }
        if (hasAccel) {
            s.accMps2 = accMatrix * (raw.accMps2 - accOffsetMps2);
        }
        if (hasMag) {
            s.magUt = magSoftIron * (raw.magUt - magHardIronUt);
        }
        return s;
    }
};

}  // namespace caphub::fusion
