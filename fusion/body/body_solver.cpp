#include "fusion/body/body_solver.h"

namespace caphub::body {

BodySolver::BodySolver(const Skeleton& skeleton, SegmentMask sensors,
                       const BodySolverOptions& options)
    : skeleton_(skeleton), poseSolver_(sensors, options.pose), root_(options.contact) {
    for (auto& r : rates_) {
        r.setZero();
    }
    for (auto& t : twists_) {
        t.setZero();
    }
}

void BodySolver::resetRoot(double xM, double zM) {
    first_ = true;
    resetAtM_ = Vec3d(xM, 0, zM);
}

const Pose& BodySolver::solve(const SensorFrame& frame, double dtS,
                              std::optional<double> rootSpecificForceMps2) {
    const Dimensions& d = skeleton_.dimensions();
    poseSolver_.solve(frame, pose_, &limits_);
    forwardKinematics(d, Vec3d::Zero(), pose_);
    if (first_) {
        for (auto& r : rates_) {
            r.setZero();
        }
    } else {
        body::jointRates(previous_, pose_, dtS, rates_);
    }
    footState(d, pose_, rates_, feet_);
    if (first_) {
        root_.reset(d, pose_, resetAtM_.x(), resetAtM_.z());
        first_ = false;
    } else {
        root_.update(d, pose_, feet_, dtS, rootSpecificForceMps2);
    }
    for (int e = 0; e < kEndEffectorCount; ++e) {
        const auto u = static_cast<std::size_t>(e);
        spatialJacobian(skeleton_, pose_, static_cast<EndEffector>(e), jacobians_[u]);
        twists_[u] = endEffectorTwist(jacobians_[u], root_.rootVelocityMps(), rates_);
    }
    previous_ = pose_;
    return pose_;
}

}  // namespace caphub::body
