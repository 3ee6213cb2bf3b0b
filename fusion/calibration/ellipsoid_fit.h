// Magnetometer hard- and soft-iron calibration by an ellipsoid fit to samples taken while the
// sensor is turned through all directions, with a coverage check and a quality figure.
#pragma once

#include <span>

#include <Eigen/Core>

#include "hal/core/error.h"
#include "hal/core/quaternion.h"

namespace caphub::fusion {

struct EllipsoidFitParams {
    // uT. The corrected field is scaled to this norm; 0 keeps the fitted ellipsoid's volume (the
    // geometric mean of its radii), when the local field is not known.
    double fieldNormUt = 0.0;
    double minCoverage = 0.7;  // fraction of the 26 directions that must hold a sample
                               // (one hemisphere reaches 17 of 26, 0.65: not enough)
    int minSamples = 50;
    double maxQualityPct = 5.0;  // a fit whose corrected norms scatter more than this is refused
};

struct EllipsoidFitResult {
    Vec3d hardIronUt = Vec3d::Zero();                        // mag = softIron * (raw - hardIron)
    Eigen::Matrix3d softIron = Eigen::Matrix3d::Identity();  // symmetric positive definite
    double fieldNormUt = 0.0;                                // the norm the corrected samples have
    double qualityPct = 0.0;  // RMS of (|corrected| - norm) / norm, percent
    double coverage = 0.0;    // fraction of the 26 directions (cube faces, edges, corners) hit
};

// Fits (m - h)' M (m - h) = 1 by linear least squares on the nine coefficients of a general
// quadric, then softIron = norm * sqrt(M) (the symmetric square root).
Result<EllipsoidFitResult> fitEllipsoid(std::span<const Vec3d> magUt,
                                        const EllipsoidFitParams& params = {});

// Fraction of the 26 directions (the unit vectors to the faces, edges and corners of a cube)
// that are the nearest direction of at least one of the given vectors.
double directionCoverage(std::span<const Vec3d> v);

}  // namespace caphub::fusion
