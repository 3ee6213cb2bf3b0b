// The sensor calibrations from what the sensors delivered, without printing: shared by
// `caphub calibrate` (which prints its tables from the results) and the guided calibration of
// `caphub serve` (firmware/serve/sensor_calibration_session.h). Each step updates one sensor's
// entry of a calibration set and returns what it found, or why it failed.
#pragma once

#include <optional>
#include <vector>

#include "board/board.h"
#include "firmware/runtime/bus_worker.h"
#include "fusion/calibration/ellipsoid_fit.h"
#include "fusion/calibration/gyro_bias.h"
#include "fusion/calibration/imu_axes.h"
#include "fusion/calibration/sensor_calibration.h"
#include "hal/core/error.h"

namespace caphub::firmware {

// What each board sensor delivered during a calibration.
struct CalibrationSamples {
    std::vector<std::vector<Vec3d>> gyr;
    std::vector<std::vector<Vec3d>> acc;
    std::vector<std::vector<Vec3d>> mag;     // fresh magnetometer readings only
    std::vector<std::vector<Vec3d>> magAcc;  // the accelerometer reading beside each of them
    std::vector<double> rateHz;

    explicit CalibrationSamples(const board::Board& b);
    void add(const SensorSample& s);
    void clear();
};

// Gyroscope bias: the sensor at rest.
Result<fusion::GyroBiasResult> calibrateGyroBias(const CalibrationSamples& st, std::size_t i,
                                                 fusion::SensorCalibration& cal);

// The accelerometer's offset and axes and the gyroscope's axes from the held positions and the
// turns between them (nine positions or more); with fewer, the six-position per-axis
// calibration of the accelerometer (gyro empty).
struct AxesResult {
    int heldPositions = 0;
    fusion::AccelAxesResult acc;
    std::optional<fusion::GyroAxesResult> gyro;
};
Result<AxesResult> calibrateAxes(const CalibrationSamples& st, std::size_t i,
                                 fusion::SensorCalibration& cal);

// The magnetometer's hard and soft iron and, when the accelerometer is calibrated already, its
// alignment to the accelerometer's frame (folded into the soft-iron matrix).
struct MagResult {
    fusion::EllipsoidFitResult fit;
    std::optional<fusion::MagAlignResult> align;
};
Result<MagResult> calibrateMagnetometer(const CalibrationSamples& st, std::size_t i,
                                        fusion::SensorCalibration& cal);

}  // namespace caphub::firmware
