#include "fusion/body/kinematics.h"

#include <cmath>

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

Vec3d logUnit(const Quatd& q) {
    // q and -q are the same rotation: take the one with w >= 0 (angle in [0, pi]).
    const double sign = q.w() < 0 ? -1.0 : 1.0;
    const Vec3d v = q.vec() * sign;
    const double w = q.w() * sign;
    const double s2 = v.squaredNorm();
    // angle / s = 2 atan(x) / s with x = s / w. For x < 0.1 the series
    // 2/w (1 - x^2/3 + x^4/5 - x^6/7 + x^8/9) leaves out x^10/11 < 1e-11 relative; it needs no
    // square root (most joint rates per frame take it).
    if (s2 < 0.01 * w * w) {
        const double x2 = s2 / (w * w);
        const double series =
            1.0 - x2 * (1.0 / 3 - x2 * (1.0 / 5 - x2 * (1.0 / 7 - x2 * (1.0 / 9))));
        return v * (2.0 / w * series);
    }
    const double s = std::sqrt(s2);
    return v * (2.0 * std::atan2(s, w) / s);
}

void jointRates(const std::array<Quatd, kSegmentCount>& previousLocal,
                const std::array<Quatd, kSegmentCount>& currentLocal, double dtS, JointRates& out) {
    const double inv = dtS > 0 ? 1.0 / dtS : 0.0;
    for (std::size_t u = 0; u < previousLocal.size(); ++u) {
        // q_now = q_prev exp(w dt): the rate in the segment's own (body) frame.
        out[u] = logUnit(previousLocal[u].conjugate() * currentLocal[u]) * inv;
    }
}

void jointRates(const Pose& previous, const Pose& current, double dtS, JointRates& out) {
    jointRates(previous.qLocal, current.qLocal, dtS, out);
}

void spatialJacobian(const Pose& pose, int end, const Vec3d& pointLocalM, ChainJacobian& out) {
    std::array<int, kMaxChainJoints> rev{};
    int n = 0;
    for (int s = end; s >= 0 && n < kMaxChainJoints; s = parentOf(s)) {
        rev[static_cast<std::size_t>(n++)] = s;
    }
    out.jointCount = n;
    out.pointM = pointOnSegment(pose, end, pointLocalM);
    out.j.block<3, 3>(0, 0).setIdentity();
    out.j.block<3, 3>(3, 0).setZero();
    // Only the columns past the chain need clearing: every used column is written below.
    const int used = 3 + 3 * n;
    out.j.rightCols(kMaxJacobianColumns - used).setZero();
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
    // J dtheta over the chain's columns only (the rest are zero): the root translation block
    // is [I; 0].
    Twist tw;
    tw.head<3>() = rootVelocityMps;
    tw.tail<3>().setZero();
    for (int k = 0; k < jac.jointCount; ++k) {
        tw.noalias() += jac.j.block<6, 3>(0, 3 + 3 * k) *
                        rates[static_cast<std::size_t>(jac.segments[static_cast<std::size_t>(k)])];
    }
    return tw;
}

}  // namespace caphub::body
