#include "fusion/body/knee_heading.h"

#include <cmath>

#include <Eigen/Eigenvalues>

namespace caphub::body {

void KneeHeading::reset() {
    for (auto& m : moments_) {
        m.setZero();
    }
    samples_ = {0, 0};
}

void KneeHeading::add(int knee, const Vec3d& relativeRateSegment) {
    if (knee < 0 || knee > 1 || !relativeRateSegment.allFinite() ||
        relativeRateSegment.norm() < options_.minRateRadS) {
        return;
    }
    const auto k = static_cast<std::size_t>(knee);
    moments_[k] += relativeRateSegment * relativeRateSegment.transpose();
    ++samples_[k];
}

std::optional<double> KneeHeading::kneeErrorRad(int knee) const {
    if (knee < 0 || knee > 1) {
        return std::nullopt;
    }
    const auto k = static_cast<std::size_t>(knee);
    if (samples_[k] < options_.minSamples) {
        return std::nullopt;
    }
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(moments_[k]);
    const double sum = eig.eigenvalues().sum();
    if (eig.info() != Eigen::Success || !(sum > 0) ||
        eig.eigenvalues()(2) < options_.minPlanarity * sum) {
        return std::nullopt;
    }
    // The axis, on the side of the segment's x (the sign of an axis is the sense of the turn).
    Vec3d a = eig.eigenvectors().col(2);
    if (a.x() < 0) {
        a = -a;
    }
    // A capture heading off by d shows the true axis x as Ry(d) x = (cos d, 0, -sin d).
    const double error = std::atan2(-a.z(), a.x());
    return std::abs(error) <= options_.maxErrorRad ? std::optional<double>(error) : std::nullopt;
}

std::optional<double> KneeHeading::headingErrorRad() const {
    const std::optional<double> left = kneeErrorRad(0);
    const std::optional<double> right = kneeErrorRad(1);
    if (!left || !right || std::abs(*left - *right) > options_.maxDisagreementRad) {
        return std::nullopt;
    }
    return 0.5 * (*left + *right);
}

}  // namespace caphub::body
