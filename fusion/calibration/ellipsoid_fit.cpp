#include "fusion/calibration/ellipsoid_fit.h"

#include <array>
#include <cmath>

#include <Eigen/Dense>
#include <Eigen/Eigenvalues>
#include <fmt/format.h>

namespace caphub::fusion {

namespace {

std::array<Vec3d, 26> cubeDirections() {
    std::array<Vec3d, 26> d;
    int n = 0;
    for (int x = -1; x <= 1; ++x) {
        for (int y = -1; y <= 1; ++y) {
            for (int z = -1; z <= 1; ++z) {
                if (x == 0 && y == 0 && z == 0) {
                    continue;
                }
                d[n++] = Vec3d(x, y, z).normalized();
            }
        }
    }
    return d;
}

}  // namespace

double directionCoverage(std::span<const Vec3d> v) {
    static const std::array<Vec3d, 26> dirs = cubeDirections();
    std::array<bool, 26> hit{};
    for (const auto& x : v) {
        const double n = x.norm();
        if (!(n > 0.0)) {
            continue;
        }
        int best = 0;
        double bestDot = -2.0;
        for (int i = 0; i < 26; ++i) {
            const double d = dirs[i].dot(x) / n;
            if (d > bestDot) {
                bestDot = d;
                best = i;
            }
        }
        hit[best] = true;
    }
    int count = 0;
    for (bool h : hit) {
        count += h ? 1 : 0;
    }
    return count / 26.0;
}

Result<EllipsoidFitResult> fitEllipsoid(std::span<const Vec3d> m, const EllipsoidFitParams& p) {
    if (static_cast<int>(m.size()) < std::max(p.minSamples, 9)) {
        return Error{EINVAL, fmt::format("ellipsoid fit: {} samples, need at least {}", m.size(),
                                         std::max(p.minSamples, 9))};
    }
    // Centre and scale the data first: the normal equations of raw uT values (x^2 ~ 1e3..1e4
    // next to 1) are badly conditioned.
    Vec3d mean = Vec3d::Zero();
    for (const auto& x : m) {
        if (!x.allFinite()) {
            return Error{EINVAL, "ellipsoid fit: a sample is not finite"};
        }
        mean += x;
    }
    mean /= static_cast<double>(m.size());
    double scale = 0.0;
    for (const auto& x : m) {
        scale = std::max(scale, (x - mean).norm());
    }
    if (!(scale > 0.0)) {
        return Error{EINVAL, "ellipsoid fit: all samples are equal"};
    }
    // a x^2 + b y^2 + c z^2 + 2d xy + 2e xz + 2f yz + 2g x + 2h y + 2i z = 1
    Eigen::MatrixXd design(static_cast<Eigen::Index>(m.size()), 9);
    for (std::size_t k = 0; k < m.size(); ++k) {
        const Vec3d u = (m[k] - mean) / scale;
        design.row(static_cast<Eigen::Index>(k)) << u.x() * u.x(), u.y() * u.y(), u.z() * u.z(),
            2 * u.x() * u.y(), 2 * u.x() * u.z(), 2 * u.y() * u.z(), 2 * u.x(), 2 * u.y(),
            2 * u.z();
    }
    const Eigen::VectorXd ones = Eigen::VectorXd::Ones(design.rows());
    const Eigen::VectorXd c = design.colPivHouseholderQr().solve(ones);
    Eigen::Matrix3d a;
    a << c[0], c[3], c[4], c[3], c[1], c[5], c[4], c[5], c[2];
    const Vec3d b(c[6], c[7], c[8]);
    // u' A u + 2 b' u = 1  ->  (u - u0)' A (u - u0) = 1 + u0' A u0 with u0 = -A^-1 b.
    const Eigen::FullPivLU<Eigen::Matrix3d> lu(a);
    if (!lu.isInvertible()) {
        return Error{EINVAL,
                     "ellipsoid fit: the samples do not span an ellipsoid (turn the "
                     "sensor through more directions)"};
    }
    const Vec3d u0 = -lu.solve(b);
    const double k = 1.0 + u0.dot(a * u0);
    const Eigen::Matrix3d mShape = a / k;  // in scaled units
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(mShape);
    if (eig.info() != Eigen::Success || eig.eigenvalues().minCoeff() <= 0.0) {
        return Error{EINVAL,
                     "ellipsoid fit: the fitted quadric is not an ellipsoid (turn the "
                     "sensor through more directions)"};
    }
    // Back to uT: M = mShape / scale^2, hard iron = mean + scale u0.
    EllipsoidFitResult r;
    r.hardIronUt = mean + scale * u0;
    const Vec3d radii = eig.eigenvalues().cwiseSqrt().cwiseInverse() * scale;  // uT
    const double norm = p.fieldNormUt > 0.0 ? p.fieldNormUt : std::cbrt(radii.prod());
    // softIron = norm * M^(1/2): maps the ellipsoid onto the sphere of that norm.
    r.softIron = eig.eigenvectors() * radii.cwiseInverse().asDiagonal() *
                 eig.eigenvectors().transpose() * norm;
    r.fieldNormUt = norm;

    std::vector<Vec3d> corrected;
    corrected.reserve(m.size());
    double sum = 0.0;
    for (const auto& x : m) {
        const Vec3d y = r.softIron * (x - r.hardIronUt);
        corrected.push_back(y);
        const double e = (y.norm() - norm) / norm;
        sum += e * e;
    }
    r.qualityPct = 100.0 * std::sqrt(sum / static_cast<double>(m.size()));
    r.coverage = directionCoverage(corrected);
    if (r.coverage < p.minCoverage) {
        return Error{EINVAL, fmt::format("ellipsoid fit: the samples cover {:.0f} % of the "
                                         "directions, need {:.0f} % (turn the sensor through more "
                                         "orientations)",
                                         100.0 * r.coverage, 100.0 * p.minCoverage)};
    }
    if (r.qualityPct > p.maxQualityPct) {
        return Error{EINVAL, fmt::format("ellipsoid fit: corrected norms scatter {:.1f} %, at most "
                                         "{:.1f} % (a magnetic disturbance during calibration?)",
                                         r.qualityPct, p.maxQualityPct)};
    }
    return r;
}

}  // namespace caphub::fusion
