// caphub's skeleton world frame (docs/frames.md: Y up, right-handed, the subject facing +Z with
// +X their left) to Unity's (Y up, left-handed, an avatar facing +Z with +X its right), as VMC
// and VRChat take them. docs/streams.md derives it.
#pragma once

#include <Eigen/Geometry>

namespace caphub::firmware::unity {

// The two frames differ by a mirror of X (M = diag(-1, 1, 1)): the same place and direction of
// the body has x negated. A rotation R becomes M R M: as a quaternion (w, x, -y, -z).
inline Eigen::Vector3f position(const Eigen::Vector3f& p) {
    return {-p.x(), p.y(), p.z()};
}
inline Eigen::Quaternionf rotation(const Eigen::Quaternionf& q) {
    return {q.w(), q.x(), -q.y(), -q.z()};
}

// Unity's Euler angles (Transform.eulerAngles), degrees: the rotation is about Z by z, then
// about X by x, then about Y by y, each about the fixed axes: q = qY(y) qX(x) qZ(z). x in
// [-90, 90]; at x = +-90 (gimbal lock) z is 0 and y takes the whole turn about the vertical.
Eigen::Vector3f eulerZxyDeg(const Eigen::Quaternionf& q);
// Back: Quaternion.Euler(x, y, z).
Eigen::Quaternionf fromEulerZxyDeg(const Eigen::Vector3f& deg);

}  // namespace caphub::firmware::unity
