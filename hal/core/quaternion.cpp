#include "hal/core/quaternion.h"

namespace caphub {

bool fromEulerIntrinsic(std::string_view axes, const Vec3d& anglesRad, Quatd& out) {
    if (axes.size() != 3) {
        return false;
    }
    Quatd q = Quatd::Identity();
    for (std::size_t i = 0; i < 3; ++i) {
        Vec3d axis;
        switch (axes[i]) {
            case 'X':
            case 'x':
                axis = Vec3d::UnitX();
                break;
            case 'Y':
            case 'y':
                axis = Vec3d::UnitY();
                break;
            case 'Z':
            case 'z':
                axis = Vec3d::UnitZ();
                break;
            default:
                return false;
        }
        q = q * Quatd(Eigen::AngleAxisd(anglesRad[static_cast<Eigen::Index>(i)], axis));
    }
    out = q;
    return true;
}

}  // namespace caphub
