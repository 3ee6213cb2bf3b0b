// The axes of the accelerometer and the gyroscope from one session of still positions with
// turns between them (after Tedaldi, Pretto and Menegatti, "A robust and easy to implement method
// for IMU calibration without external equipments", ICRA 2014):
//  - the accelerometer: offset and a symmetric 3x3 matrix (scale and cross-axis) such that every
//    held position reads gravity's norm, by an ellipsoid fit to nine or more positions;
//  - the gyroscope: a full 3x3 matrix (scale, cross-axis and its misalignment to the
//    accelerometer) such that the integrated turn between two held positions carries the
//    gravity direction of the first onto that of the second, by Gauss-Newton.
//  - the magnetometer's alignment to the accelerometer: the rotation under which the angle
//    between gravity and the field stays the same in every orientation (the field's dip), from
//    a session turning through every direction.
// The accelerometer then defines the sensor frame and the gyroscope and magnetometer read in it.
#pragma once

#include <span>

#include <Eigen/Core>

#include "fusion/calibration/still_intervals.h"
#include "hal/core/error.h"
#include "hal/core/quaternion.h"

namespace caphub::fusion {

// The largest departure of a calibration matrix's entries from the identity's.
double axisDeparture(const Eigen::Matrix3d& m);

struct AccelAxesParams {
    double gravityMps2 = 9.81;
    int minPositions = 9;          // the fit has nine unknowns
    double maxResidualMps2 = 0.1;  // a fit whose corrected norms scatter more is refused
    double maxAxisError = 0.1;     // a scale off 1 or a cross term beyond this is refused
};

struct AccelAxesResult {
    Vec3d offsetMps2 = Vec3d::Zero();                      // acc = matrix * (raw - offset)
    Eigen::Matrix3d matrix = Eigen::Matrix3d::Identity();  // symmetric
    double residualMps2 = 0.0;  // RMS of |corrected| - g over the positions
    int positions = 0;
};

// From the mean specific force of each held position (raw, sensor frame).
Result<AccelAxesResult> calibrateAccelAxes(std::span<const Vec3d> positionMeansMps2,
                                           const AccelAxesParams& params = {});

struct GyroAxesParams {
    int minTurns = 6;             // turns between consecutive held positions
    double minTurnDeg = 20.0;     // smaller turns carry little of the scale and are left out
    double maxResidualDeg = 2.0;  // a fit whose turns still miss by more (RMS) is refused
    double maxAxisError = 0.1;    // a scale off 1 or a cross term beyond this is refused
    int maxIterations = 20;
};

struct GyroAxesResult {
    Eigen::Matrix3d matrix = Eigen::Matrix3d::Identity();  // gyr = matrix * (raw - bias)
    Vec3d biasRadS = Vec3d::Zero();                        // the mean rate of the held positions
    double residualDeg = 0.0;      // RMS miss of the turns' end directions, fitted
    double uncalibratedDeg = 0.0;  // the same with the identity matrix
    int turns = 0;
};

// gyrRadS: the raw rates of the session at rateHz; positions: its held positions in stream order
// (findHeldPositions); the accelerometer calibration of the same session.
Result<GyroAxesResult> calibrateGyroAxes(std::span<const Vec3d> gyrRadS, double rateHz,
                                         std::span<const StillInterval> positions,
                                         const AccelAxesResult& accel,
                                         const GyroAxesParams& params = {});

struct MagAlignParams {
    double maxAccDeviationMps2 = 0.3;  // samples whose |acc| is further from g are left out
    double gravityMps2 = 9.81;
    int minSamples = 100;
    double maxAngleDeg = 10.0;  // a larger fitted rotation is refused
    int maxIterations = 20;
};

struct MagAlignResult {
    Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();  // mag_accel = rotation * mag
    double angleDeg = 0.0;                                   // the rotation's angle
    double dipDeg = 0.0;        // the field's dip below the horizontal, fitted
    double residualDeg = 0.0;   // RMS spread of the gravity-field angle, aligned
    double unalignedDeg = 0.0;  // the same before
    int samples = 0;
};

// accMps2[k] and magUt[k]: calibrated readings of the same instant (the accelerometer's offset
// and axes, the magnetometer's hard and soft iron applied), while the sensor turns slowly.
// Gauss-Newton on the rotation (a rotation vector) and the dip.
Result<MagAlignResult> alignMagToAccel(std::span<const Vec3d> accMps2, std::span<const Vec3d> magUt,
                                       const MagAlignParams& params = {});

}  // namespace caphub::fusion
