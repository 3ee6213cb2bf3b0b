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
                              const std::optional<Vec3d>& rootSpecificForceMps2,
                              const FootSensorMotion* footSensors) {
    const Dimensions& d = skeleton_.dimensions();
    poseSolver_.solve(frame, pose_, &limits_);
    forwardKinematics(d, Vec3d::Zero(), pose_);
    if (first_) {
        for (auto& r : rates_) {
            r.setZero();
        }
    } else {
        body::jointRates(previousLocal_, pose_.qLocal, dtS, rates_);
    }
    // Each chain's Jacobian once, with the root at the origin: its columns hold only
    // differences of positions, so moving the root later shifts just the end point. The feet's
    // contact velocities come from the same Jacobians as their twists.
    for (int e = 0; e < kEndEffectorCount; ++e) {
        const auto u = static_cast<std::size_t>(e);
        spatialJacobian(skeleton_, pose_, static_cast<EndEffector>(e), jacobians_[u]);
        twists_[u] = endEffectorTwist(jacobians_[u], Vec3d::Zero(), rates_);
    }
    footState(d, pose_, jacobians_[static_cast<std::size_t>(EndEffector::LFoot)],
              jacobians_[static_cast<std::size_t>(EndEffector::RFoot)], rates_, feet_);
    if (first_) {
        root_.reset(d, pose_, resetAtM_.x(), resetAtM_.z());
        first_ = false;
    } else {
        root_.update(d, pose_, feet_, dtS, rootSpecificForceMps2, footSensors);
    }
    const Vec3d& rootM = pose_.positionM[0];
    for (int e = 0; e < kEndEffectorCount; ++e) {
        const auto u = static_cast<std::size_t>(e);
        jacobians_[u].pointM += rootM;
        twists_[u].head<3>() += root_.rootVelocityMps();
    }
    previousLocal_ = pose_.qLocal;
    return pose_;
}

}  // namespace caphub::body
