// Forward kinematics (paper eqs. 7-10) and the spatial Jacobian of the chains to the head, hands
// and feet (eqs. 11-13) on caphub's skeleton. Fixed-size and allocation-free: runs per frame.
#pragma once

#include <array>

#include <Eigen/Core>

#include "fusion/body/skeleton.h"

namespace caphub::body {

// The skeleton's state in one frame, in the skeleton world frame (docs/frames.md).
struct Pose {
    std::array<Quatd, kSegmentCount> qWorld;     // segment -> world
    std::array<Quatd, kSegmentCount> qLocal;     // segment -> parent segment: the joint rotation
    std::array<Vec3d, kSegmentCount> positionM;  // segment origins = joint centres

    Pose() {
        qWorld.fill(Quatd::Identity());
        qLocal.fill(Quatd::Identity());
        positionM.fill(Vec3d::Zero());
    }
    const Quatd& world(Segment s) const { return qWorld[static_cast<std::size_t>(idx(s))]; }
    const Vec3d& position(Segment s) const { return positionM[static_cast<std::size_t>(idx(s))]; }
};

// qWorld from qLocal, root first (eq. 8 for the rotations).
void worldFromLocal(Pose& pose);
// qLocal from qWorld.
void localFromWorld(Pose& pose);

// Eqs. 7-10: every joint centre from the root position and qWorld. M_i^(i-1) = [R_i, P_i] with
// P_i the reference offset of joint i in its parent's frame; M(i) = M(root) ... M_i^(i-1).
void forwardKinematics(const Dimensions& d, const Vec3d& rootM, Pose& pose);

// A point fixed on a segment (in its frame), in world coordinates.
inline Vec3d pointOnSegment(const Pose& pose, int segment, const Vec3d& localM) {
    const auto i = static_cast<std::size_t>(segment);
    return pose.positionM[i] + pose.qWorld[i] * localM;
}

// The rotation vector of a unit quaternion (the logarithm map), for the per-frame paths: a
// plain norm instead of stableNorm and, for angles below 11 deg (tan of the half angle < 0.1),
// a series instead of atan2 (relative error < 1e-11). Agrees with toRotationVector of
// hal/core/quaternion.h for unit quaternions; it takes only ratios of the components, so a
// quaternion off the unit sphere by rounding (a product of unit ones) needs no normalising.
Vec3d logUnit(const Quatd& q);

// Joint velocities: per segment, the angular velocity of the segment relative to its parent,
// in the segment's own frame (rad/s); for the pelvis its angular velocity in the world, in the
// pelvis frame. Computed from two consecutive poses.
using JointRates = std::array<Vec3d, kSegmentCount>;
void jointRates(const Pose& previous, const Pose& current, double dtS, JointRates& out);
void jointRates(const std::array<Quatd, kSegmentCount>& previousLocal,
                const std::array<Quatd, kSegmentCount>& currentLocal, double dtS, JointRates& out);

// Columns: root translation (3), then 3 per joint along the chain from the pelvis.
inline constexpr int kMaxChainJoints = 8;
inline constexpr int kMaxJacobianColumns = 3 + 3 * kMaxChainJoints;
using Twist = Eigen::Matrix<double, 6, 1>;  // linear velocity (m/s) of the point, then angular

struct ChainJacobian {
    std::array<int, kMaxChainJoints> segments{};  // pelvis first
    int jointCount = 0;
    Vec3d pointM = Vec3d::Zero();  // the end-effector point, world
    // J_s = [xi_root_translation, xi_1 ... xi_n]: for joint j with world rotation columns
    // a = R_Wj e_k, xi = [a x (p_end - p_j); a] (eq. 13 written with the lever arm in world
    // coordinates). Unused columns are zero.
    Eigen::Matrix<double, 6, kMaxJacobianColumns> j =
        Eigen::Matrix<double, 6, kMaxJacobianColumns>::Zero();
};

// Eqs. 11-13 for the chain to segment `end` and a point fixed on it (segment frame).
void spatialJacobian(const Pose& pose, int end, const Vec3d& pointLocalM, ChainJacobian& out);
inline void spatialJacobian(const Skeleton& sk, const Pose& pose, EndEffector e,
                            ChainJacobian& out) {
    spatialJacobian(pose, idx(endEffectorSegment(e)), sk.endSiteM(e), out);
}

// dS = J dtheta (eq. 11): the twist of the end-effector point for the given root velocity and
// joint rates.
Twist endEffectorTwist(const ChainJacobian& jac, const Vec3d& rootVelocityMps,
                       const JointRates& rates);

}  // namespace caphub::body
