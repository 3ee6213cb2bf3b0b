// The whole per-frame body solve: sensor orientations -> segment orientations and joint
// rotations -> forward kinematics -> joint rates and end-effector Jacobians and twists -> foot
// contacts and root translation. No heap after construction.
#pragma once

#include <array>
#include <optional>

#include "fusion/body/pose_solver.h"
#include "fusion/body/root_tracker.h"
#include "fusion/body/skeleton.h"

namespace caphub::body {

struct BodySolverOptions {
    PoseSolverOptions pose;
    ContactOptions contact;
};

class BodySolver {
public:
    BodySolver(const Skeleton& skeleton, SegmentMask sensors,
               const BodySolverOptions& options = {});

    void setCalibration(const BodyCalibration& cal) { poseSolver_.setCalibration(cal); }
    // The next frame places the root on the floor at (x, z) and restarts contact tracking.
    void resetRoot(double xM = 0, double zM = 0);

    // One frame, dtS after the previous one. rootSpecificForceMps2: see RootTracker::update.
    const Pose& solve(const SensorFrame& frame, double dtS,
                      const std::optional<Vec3d>& rootSpecificForceMps2 = std::nullopt,
                      const FootSensorMotion* footSensors = nullptr);

    const Pose& pose() const { return pose_; }
    const Skeleton& skeleton() const { return skeleton_; }
    const PoseSolver& poseSolver() const { return poseSolver_; }
    const RootTracker& rootTracker() const { return root_; }
    const JointLimitReport& limitReport() const { return limits_; }
    const JointRates& jointRates() const { return rates_; }
    const ChainJacobian& jacobian(EndEffector e) const {
        return jacobians_[static_cast<std::size_t>(e)];
    }
    const Twist& twist(EndEffector e) const { return twists_[static_cast<std::size_t>(e)]; }
    const FootState& feet() const { return feet_; }

private:
    Skeleton skeleton_;
    PoseSolver poseSolver_;
    RootTracker root_;
    Pose pose_;
    std::array<Quatd, kSegmentCount> previousLocal_;  // joint rotations of the last frame
    JointRates rates_{};
    JointLimitReport limits_;
    FootState feet_;
    std::array<ChainJacobian, kEndEffectorCount> jacobians_;
    std::array<Twist, kEndEffectorCount> twists_{};
    bool first_ = true;
    Vec3d resetAtM_ = Vec3d::Zero();
};

}  // namespace caphub::body
