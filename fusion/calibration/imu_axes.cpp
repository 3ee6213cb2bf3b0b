#include "fusion/calibration/imu_axes.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include <Eigen/Dense>
#include <fmt/format.h>

#include "fusion/calibration/ellipsoid_fit.h"
#include "hal/core/angles.h"

namespace caphub::fusion {

namespace {

using hal::kRadToDeg;

// Gauss-Newton on x, the Jacobian of residuals(x) by central differences of the given step;
// stops when a step is shorter than tolerance. False when the normal equations are singular
// (a step that is not finite).
template <int N, typename Residuals>
bool gaussNewton(Eigen::Matrix<double, N, 1>& x, const Residuals& residuals, double step,
                 double tolerance, int maxIterations) {
    Eigen::VectorXd res = residuals(x);
    for (int it = 0; it < maxIterations; ++it) {
        Eigen::MatrixXd jac(res.size(), N);
        for (int j = 0; j < N; ++j) {
            Eigen::Matrix<double, N, 1> hi = x;
            Eigen::Matrix<double, N, 1> lo = x;
            hi[j] += step;
            lo[j] -= step;
            jac.col(j) = (residuals(hi) - residuals(lo)) / (2.0 * step);
        }
        const Eigen::Matrix<double, N, 1> delta = jac.colPivHouseholderQr().solve(-res);
        if (!delta.allFinite()) {
            return false;
        }
        x += delta;
        res = residuals(x);
        if (delta.norm() < tolerance) {
            break;
        }
    }
    return true;
}

// The rotation of a rotation vector (axis times angle, rad).
Eigen::Matrix3d rotationFromVector(const Vec3d& v) {
    const double angle = v.norm();
    return angle > 0.0 ? Eigen::AngleAxisd(angle, v / angle).toRotationMatrix()
                       : Eigen::Matrix3d::Identity();
}

// A fitted calibration matrix further from the identity than allowed: refused, with the hint.
Result<void> checkAxes(const char* what, const Eigen::Matrix3d& m, double maxDeparture,
                       const char* hint) {
    const double d = axisDeparture(m);
    if (d > maxDeparture) {
        return Error{EINVAL, fmt::format("{}: the fitted matrix is {:.3f} off the identity (at "
                                         "most {:.3f}): {}",
                                         what, d, maxDeparture, hint)};
    }
    return {};
}

// One turn between two held positions: the bias-corrected raw rates, the gravity direction
// before and after (calibrated accelerometer, sensor frame).
struct Turn {
    std::vector<Vec3d> rates;
    Vec3d upBefore = Vec3d::Zero();
    Vec3d upAfter = Vec3d::Zero();
};

// Where the turn, integrated with rates matrix * raw, carries the first gravity direction: the
// sensor frame at the end, seen from the start, is the product of each sample's rotation.
Vec3d predictedUp(const Turn& turn, const Eigen::Matrix3d& matrix, double dtS) {
    Quatd q = Quatd::Identity();
    for (const Vec3d& raw : turn.rates) {
        const Vec3d phi = matrix * raw * dtS;
        const double angle = phi.norm();
        const Quatd step =
            angle > 0.0 ? Quatd(Eigen::AngleAxisd(angle, phi / angle)) : Quatd::Identity();
        q = q * step;
    }
    return q.conjugate() * turn.upBefore;
}

// The stacked misses (predicted minus measured direction) of every turn.
Eigen::VectorXd misses(const std::vector<Turn>& turns, const Eigen::Matrix3d& matrix, double dtS) {
    Eigen::VectorXd r(3 * static_cast<Eigen::Index>(turns.size()));
    for (std::size_t i = 0; i < turns.size(); ++i) {
        r.segment<3>(3 * static_cast<Eigen::Index>(i)) =
            predictedUp(turns[i], matrix, dtS) - turns[i].upAfter;
    }
    return r;
}

// RMS of the turns' misses as angles, degrees (a miss of chord c is an angle of 2 asin(c / 2)).
double rmsMissDeg(const Eigen::VectorXd& r) {
    double sum = 0.0;
    const auto n = r.size() / 3;
    for (Eigen::Index i = 0; i < n; ++i) {
        const double a = 2.0 * std::asin(std::min(1.0, r.segment<3>(3 * i).norm() / 2.0));
        sum += a * a;
    }
    return n > 0 ? std::sqrt(sum / static_cast<double>(n)) * kRadToDeg : 0.0;
}

Eigen::Matrix3d fromParams(const Eigen::Matrix<double, 9, 1>& x) {
    Eigen::Matrix3d m;
    m << x[0], x[1], x[2], x[3], x[4], x[5], x[6], x[7], x[8];
    return m;
}

}  // namespace

double axisDeparture(const Eigen::Matrix3d& m) {
    return (m - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
}

Result<AccelAxesResult> calibrateAccelAxes(std::span<const Vec3d> pos, const AccelAxesParams& p) {
    if (static_cast<int>(pos.size()) < p.minPositions) {
        return Error{EINVAL, fmt::format("accel axes: {} held positions, need at least {} (hold "
                                         "the sensor still with each face and each corner up)",
                                         pos.size(), p.minPositions)};
    }
    EllipsoidFitParams fit;
    fit.fieldNormUt = p.gravityMps2;
    fit.minSamples = p.minPositions;
    fit.minCoverage = 0.0;  // judged below, by the residual and the matrix itself
    fit.maxQualityPct = 100.0;
    auto e = fitEllipsoid(pos, fit);
    if (!e) {
        return Error{EINVAL, fmt::format("accel axes: {}", e.error().message)};
    }
    AccelAxesResult r;
    r.offsetMps2 = e->hardIronUt;
    r.matrix = e->softIron;
    r.positions = static_cast<int>(pos.size());
    double sum = 0.0;
    for (const Vec3d& a : pos) {
        const double d = (r.matrix * (a - r.offsetMps2)).norm() - p.gravityMps2;
        sum += d * d;
    }
    r.residualMps2 = std::sqrt(sum / static_cast<double>(pos.size()));
    if (auto c = checkAxes("accel axes", r.matrix, p.maxAxisError,
                           "the positions are too few or too alike");
        !c) {
        return c.error();
    }
    if (r.residualMps2 > p.maxResidualMps2) {
        return Error{EINVAL, fmt::format("accel axes: the positions miss gravity by {:.3f} m/s^2 "
                                         "RMS after the fit (at most {:.3f}): was the sensor "
                                         "moving while held?",
                                         r.residualMps2, p.maxResidualMps2)};
    }
    return r;
}

Result<GyroAxesResult> calibrateGyroAxes(std::span<const Vec3d> gyr, double rateHz,
                                         std::span<const StillInterval> positions,
                                         const AccelAxesResult& accel, const GyroAxesParams& p) {
    using hal::kDegToRad;
    if (!(rateHz > 0)) {
        return Error{EINVAL, "gyro axes: the rate must be positive"};
    }
    GyroAxesResult r;
    std::size_t held = 0;
    for (const auto& s : positions) {
        if (s.end > gyr.size() || s.begin >= s.end) {
            return Error{EINVAL, "gyro axes: a held position lies outside the stream"};
        }
        r.biasRadS += s.meanGyrRadS * static_cast<double>(s.size());
        held += s.size();
    }
    if (held > 0) {
        r.biasRadS /= static_cast<double>(held);
    }
    auto up = [&accel](const StillInterval& s) {
        return (accel.matrix * (s.meanAccMps2 - accel.offsetMps2)).normalized();
    };
    std::vector<Turn> turns;
    for (std::size_t i = 0; i + 1 < positions.size(); ++i) {
        Turn t;
        t.upBefore = up(positions[i]);
        t.upAfter = up(positions[i + 1]);
        const double angle = std::acos(std::clamp(t.upBefore.dot(t.upAfter), -1.0, 1.0));
        if (angle < p.minTurnDeg * kDegToRad) {
            continue;
        }
        for (std::size_t k = positions[i].end; k < positions[i + 1].begin; ++k) {
            t.rates.push_back(gyr[k] - r.biasRadS);
        }
        turns.push_back(std::move(t));
    }
    r.turns = static_cast<int>(turns.size());
    if (r.turns < p.minTurns) {
        return Error{EINVAL, fmt::format("gyro axes: {} turns of at least {:.0f} deg between held "
                                         "positions, need {}",
                                         r.turns, p.minTurnDeg, p.minTurns)};
    }
    const double dt = 1.0 / rateHz;
    Eigen::Matrix<double, 9, 1> x;
    x << 1, 0, 0, 0, 1, 0, 0, 0, 1;
    const auto residuals = [&turns, dt](const Eigen::Matrix<double, 9, 1>& m) {
        return misses(turns, fromParams(m), dt);
    };
    r.uncalibratedDeg = rmsMissDeg(residuals(x));
    // Gauss-Newton on the nine entries.
    if (!gaussNewton(x, residuals, 1e-6, 1e-10, p.maxIterations)) {
        return Error{EINVAL,
                     "gyro axes: the turns do not determine the axes (turn the "
                     "sensor about each of its axes)"};
    }
    r.matrix = fromParams(x);
    r.residualDeg = rmsMissDeg(residuals(x));
    if (auto c =
            checkAxes("gyro axes", r.matrix, p.maxAxisError, "the turns do not determine the axes");
        !c) {
        return c.error();
    }
    if (r.residualDeg > p.maxResidualDeg) {
        return Error{EINVAL, fmt::format("gyro axes: the turns still miss by {:.2f} deg RMS after "
                                         "the fit (at most {:.2f}): was a held position not still?",
                                         r.residualDeg, p.maxResidualDeg)};
    }
    return r;
}

Result<MagAlignResult> alignMagToAccel(std::span<const Vec3d> acc, std::span<const Vec3d> mag,
                                       const MagAlignParams& p) {
    if (acc.size() != mag.size()) {
        return Error{EINVAL, "mag alignment: the accelerometer and magnetometer readings differ"};
    }
    std::vector<Vec3d> up;
    std::vector<Vec3d> field;
    for (std::size_t k = 0; k < acc.size(); ++k) {
        const double a = acc[k].norm();
        const double m = mag[k].norm();
        if (std::abs(a - p.gravityMps2) > p.maxAccDeviationMps2 || !(m > 0.0) ||
            !acc[k].allFinite() || !mag[k].allFinite()) {
            continue;
        }
        up.push_back(acc[k] / a);
        field.push_back(mag[k] / m);
    }
    MagAlignResult r;
    r.samples = static_cast<int>(up.size());
    if (r.samples < p.minSamples) {
        return Error{EINVAL, fmt::format("mag alignment: {} readings with the sensor near still, "
                                         "need {}",
                                         r.samples, p.minSamples)};
    }
    // Residual k: up . (R field) - sin(elevation); R = exp(x.head(3)), x[3] the sine.
    auto residuals = [&](const Eigen::Vector4d& x) {
        const Eigen::Matrix3d rot = rotationFromVector(x.head<3>());
        Eigen::VectorXd res(static_cast<Eigen::Index>(up.size()));
        for (std::size_t k = 0; k < up.size(); ++k) {
            res[static_cast<Eigen::Index>(k)] = up[k].dot(rot * field[k]) - x[3];
        }
        return res;
    };
    auto spreadDeg = [&](const Eigen::VectorXd& res, double sine) {
        double sum = 0.0;
        const double base = std::asin(std::clamp(sine, -1.0, 1.0));
        for (Eigen::Index k = 0; k < res.size(); ++k) {
            const double d = std::asin(std::clamp(res[k] + sine, -1.0, 1.0)) - base;
            sum += d * d;
        }
        return std::sqrt(sum / static_cast<double>(res.size())) * kRadToDeg;
    };
    Eigen::Vector4d x = Eigen::Vector4d::Zero();
    double meanDot = 0.0;
    for (std::size_t k = 0; k < up.size(); ++k) {
        meanDot += up[k].dot(field[k]);
    }
    x[3] = meanDot / static_cast<double>(up.size());
    r.unalignedDeg = spreadDeg(residuals(x), x[3]);
    if (!gaussNewton(x, residuals, 1e-7, 1e-12, p.maxIterations)) {
        return Error{EINVAL,
                     "mag alignment: the readings do not determine the rotation (turn "
                     "the sensor through every direction)"};
    }
    const Vec3d v = x.head<3>();
    r.angleDeg = v.norm() * kRadToDeg;
    r.rotation = rotationFromVector(v);
    // Up and the field (pointing down, north) make an angle of 90 deg + dip.
    r.dipDeg = -std::asin(std::clamp(x[3], -1.0, 1.0)) * kRadToDeg;
    r.residualDeg = spreadDeg(residuals(x), x[3]);
    if (r.angleDeg > p.maxAngleDeg) {
        return Error{EINVAL,
                     fmt::format("mag alignment: the fitted rotation is {:.1f} deg (at most "
                                 "{:.1f}): a disturbance during the turning?",
                                 r.angleDeg, p.maxAngleDeg)};
    }
    return r;
}

}  // namespace caphub::fusion
