#include "fusion/body/kinematics.h"

namespace caphub::body {

void worldFromLocal(Pose& pose) {
    pose.qWorld[0] = pose.qLocal[0];
    for (int i = 1; i < kSegmentCount; ++i) {
        const auto u = static_cast<std::size_t>(i);
        pose.qWorld[u] = pose.qWorld[static_cast<std::size_t>(parentOf(i))] * pose.qLocal[u];
    }
}

void localFromWorld(Pose& pose) {
    pose.qLocal[0] = pose.qWorld[0];
    for (int i = 1; i < kSegmentCount; ++i) {
        const auto u = static_cast<std::size_t>(i);
        pose.qLocal[u] =
            pose.qWorld[static_cast<std::size_t>(parentOf(i))].conjugate() * pose.qWorld[u];
    }
}

void forwardKinematics(const Dimensions& d, const Vec3d& rootM, Pose& pose) {
    pose.positionM[0] = rootM;
    // Segment frames equal the world frame in the reference pose, so a joint's reference offset
    // in its parent's frame is its reference offset in the world: P_final = M(parent) P_i.
    for (int i = 1; i < kSegmentCount; ++i) {
        const auto u = static_cast<std::size_t>(i);
        const auto p = static_cast<std::size_t>(parentOf(i));
        pose.positionM[u] = pose.positionM[p] + pose.qWorld[p] * d.offsetM[u];
    }
}

void jointRates(const Pose& previous, const Pose& current, double dtS, JointRates& out) {
    const double inv = dtS > 0 ? 1.0 / dtS : 0.0;
    for (int i = 0; i < kSegmentCount; ++i) {
        const auto u = static_cast<std::size_t>(i);
        // q_now = q_prev exp(w dt): the rate in the segment's own (body) frame.
        out[u] = toRotationVector<double>(previous.qLocal[u].conjugate() * current.qLocal[u]) * inv;
    }
}

void spatialJacobian(const Pose& pose, int end, const Vec3d& pointLocalM, ChainJacobian& out) {
    std::array<int, kMaxChainJoints> rev{};
    int n = 0;
    for (int s = end; s >= 0 && n < kMaxChainJoints; s = parentOf(s)) {
        rev[static_cast<std::size_t>(n++)] = s;
    }
    out.jointCount = n;
    out.pointM = pointOnSegment(pose, end, pointLocalM);
    out.j.setZero();
    out.j.block<3, 3>(0, 0).setIdentity();
    for (int k = 0; k < n; ++k) {
        const int s = rev[static_cast<std::size_t>(n - 1 - k)];
        out.segments[static_cast<std::size_t>(k)] = s;
        const auto u = static_cast<std::size_t>(s);
        const Eigen::Matrix3d r = pose.qWorld[u].toRotationMatrix();
        const Vec3d lever = out.pointM - pose.positionM[u];
        for (int c = 0; c < 3; ++c) {
            const Vec3d a = r.col(c);
            const int col = 3 + 3 * k + c;
            out.j.block<3, 1>(0, col) = a.cross(lever);
            out.j.block<3, 1>(3, col) = a;
        }
    }
}

Twist endEffectorTwist(const ChainJacobian& jac, const Vec3d& rootVelocityMps,
                       const JointRates& rates) {
    Eigen::Matrix<double, kMaxJacobianColumns, 1> dtheta;
    dtheta.setZero();
    dtheta.segment<3>(0) = rootVelocityMps;
    for (int k = 0; k < jac.jointCount; ++k) {
        dtheta.segment<3>(3 + 3 * k) =
            rates[static_cast<std::size_t>(jac.segments[static_cast<std::size_t>(k)])];
    }
    return jac.j * dtheta;
}

}  // namespace caphub::body
