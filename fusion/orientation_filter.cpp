#include "fusion/orientation_filter.h"

#include <cmath>

namespace caphub::fusion {

// Per horizontal axis, between two measurements dt apart:
//   angle error   phi_k+1 = phi_k + dt b_k + w,  w ~ N(0, sigmaG^2 dt)
//   bias error    b_k+1   = b_k + v,             v ~ N(0, sigmaB^2 dt)
//   measurement   z_k     = phi_k + n,           n ~ N(0, sigmaM^2)
// The covariance recursion is iterated until the gain stops changing: the stationary Kalman
// gain, which the filter then applies with no division on the per-sample path.
SteadyGains steadyStateGains(double dtS, double angleNoiseRadRtHz, double biasDriftRadRtS,
                             double measNoiseRad) {
    const double q00 = angleNoiseRadRtHz * angleNoiseRadRtHz * dtS;
    const double q11 = biasDriftRadRtS * biasDriftRadRtS * dtS;
    const double r = measNoiseRad * measNoiseRad;
    // Start from a large uncertainty: the recursion converges from any positive start.
    double p00 = 1.0;
    double p01 = 0.0;
    double p11 = q11 > 0.0 ? 1e-2 : 0.0;
    SteadyGains g;
    for (int i = 0; i < 20'000'000; ++i) {
        // Predict: P = F P F' + Q with F = [1 dt; 0 1].
        const double a00 = p00 + 2.0 * dtS * p01 + dtS * dtS * p11 + q00;
        const double a01 = p01 + dtS * p11;
        const double a11 = p11 + q11;
        // Update with H = [1 0].
        const double s = a00 + r;
        const double k0 = a00 / s;
        const double k1 = a01 / s;
        p00 = (1.0 - k0) * a00;
        p01 = (1.0 - k0) * a01;
        p11 = a11 - k1 * a01;
        const bool settled = std::fabs(k0 - g.kAngle) <= 1e-13 * std::fabs(k0) &&
                             std::fabs(k1 - g.kBias) <= 1e-13 * std::fabs(k1) + 1e-300;
        g.kAngle = k0;
        g.kBias = k1;
        if (settled && i > 10) {
            break;
        }
    }
    return g;
}

template class OrientationFilter<FloatTypes>;
template class OrientationFilter<FixedTypes>;

}  // namespace caphub::fusion
