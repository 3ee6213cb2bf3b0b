// Euler angles of a rotation in BVH's Z-X-Y channel order: R = Rz(z) * Rx(x) * Ry(y) (intrinsic,
// the order the channels are listed), robust at and near gimbal lock (x = +-90 degrees).
#pragma once

#include "hal/core/quaternion.h"

namespace caphub::firmware::exporter {

struct EulerZxyDeg {
    double z = 0;  // first channel, in (-180, 180]
    double x = 0;  // in [-90, 90]
    double y = 0;  // in (-180, 180]
};

EulerZxyDeg eulerZxyDeg(const Quatd& q);

}  // namespace caphub::firmware::exporter
