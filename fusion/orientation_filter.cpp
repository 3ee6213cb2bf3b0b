#include "fusion/orientation_filter.h"

#include <array>
#include <cmath>

namespace caphub::fusion {

const char* invalidFilterParameter(const FilterParams& p) {
    // Rates: a gyroscope period must fit the fixed-point coefficient range (below 2 s; the
    // slowest chip rate in the catalogue is the LIS3MDL's 0.625 Hz), and 20 kHz is three times
    // the fastest. Times up to 1e4 s keep every sample count within an int32 at that rate.
    constexpr double kMinRateHz = 0.6;
    constexpr double kMaxRateHz = 20e3;
    constexpr double kAboveZero = 1e-9;
    constexpr double kLongS = 1e4;
    constexpr double kLarge = 1e7;
    const struct {
        const char* name;
        double value;
        double lo;
        double hi;
    } checks[] = {
        {"gyrRateHz", p.gyrRateHz, kMinRateHz, kMaxRateHz},
        {"accRateHz", p.accRateHz, kMinRateHz, kMaxRateHz},
        {"magRateHz", p.magRateHz, kMinRateHz, kMaxRateHz},
        {"tauAccS", p.tauAccS, kAboveZero, kLongS},
        {"accLpDamping", p.accLpDamping, kAboveZero, 10.0},
        {"gyrNoiseDpsRtHz", p.gyrNoiseDpsRtHz, kAboveZero, kLarge},
        {"biasDriftDpsRtS", p.biasDriftDpsRtS, 0.0, kLarge},
        {"inclNoiseDegRtHz", p.inclNoiseDegRtHz, kAboveZero, kLarge},
        {"headingNoiseDegRtHz", p.headingNoiseDegRtHz, kAboveZero, kLarge},
        {"accDynamicThMps2", p.accDynamicThMps2, 0.0, kLarge},
        {"gravityMps2", p.gravityMps2, kAboveZero, kLarge},
        {"biasMaxDps", p.biasMaxDps, 0.0, kLarge},
        {"restBiasTauS", p.restBiasTauS, kAboveZero, kLongS},
        {"recoveryGainFactor", p.recoveryGainFactor, 0.0, kLarge},
        {"gyrLimitDps", p.gyrLimitDps, kAboveZero, kLarge},
        {"accLimitMps2", p.accLimitMps2, kAboveZero, kLarge},
        {"magLimitUt", p.magLimitUt, kAboveZero, kLarge},
        {"rest.filterTauS", p.rest.filterTauS, 0.0, kLongS},
        {"rest.thGyrDps", p.rest.thGyrDps, 0.0, kLarge},
        {"rest.thAccMps2", p.rest.thAccMps2, 0.0, kLarge},
        {"rest.minTimeS", p.rest.minTimeS, 0.0, kLongS},
        {"magDisturbance.normTh", p.magDisturbance.normTh, 0.0, 10.0},
        {"magDisturbance.dipThDeg", p.magDisturbance.dipThDeg, 0.0, 180.0},
        {"magDisturbance.refTauS", p.magDisturbance.refTauS, 0.0, kLongS},
        {"magDisturbance.newFieldTimeS", p.magDisturbance.newFieldTimeS, 0.0, kLongS},
        {"magDisturbance.newFieldMinRateDps", p.magDisturbance.newFieldMinRateDps, 0.0, kLarge},
        {"magDisturbance.candidateTauS", p.magDisturbance.candidateTauS, 0.0, kLongS},
        {"magDisturbance.recoveryTimeS", p.magDisturbance.recoveryTimeS, 0.0, kLongS},
    };
    for (const auto& c : checks) {
        if (!(c.value >= c.lo && c.value <= c.hi)) {  // false for NaN too
            return c.name;
        }
    }
    // The gravity low-pass's semi-implicit Euler step is stable for omega_c dt < 1.
    if (!(2.0 * p.accLpDamping / p.tauAccS / p.accRateHz < 1.0)) {
        return "tauAccS";
    }
    return nullptr;
}

// Per horizontal axis, between two measurements dt apart:
//   angle error   phi_k+1 = phi_k + dt b_k + w,  w ~ N(0, sigmaG^2 dt)
//   bias error    b_k+1   = b_k + v,             v ~ N(0, sigmaB^2 dt)
//   measurement   z_k     = phi_k + n,           n ~ N(0, sigmaM^2)
// The covariance recursion is iterated until the gain stops changing: the stationary Kalman
// gain, which the filter then applies with no division on the per-sample path.
namespace {

SteadyGains iterateRiccati(double dtS, double angleNoiseRadRtHz, double biasDriftRadRtS,
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

}  // namespace

// The iteration takes up to milliseconds where the bias drift is small against the measurement
// noise, and every filter constructed computes two: `reprocess --smooth` builds dozens with the
// same parameters and spent a third of its time here (docs/reprocess.md, "Speed"). The last few
// arguments and their gains are kept, per thread; the gains are the same to the bit.
SteadyGains steadyStateGains(double dtS, double angleNoiseRadRtHz, double biasDriftRadRtS,
                             double measNoiseRad) {
    struct Entry {
        std::array<double, 4> args{};
        SteadyGains gains;
        bool used = false;
    };
    thread_local std::array<Entry, 8> cache;
    thread_local std::size_t next = 0;
    const std::array<double, 4> args{dtS, angleNoiseRadRtHz, biasDriftRadRtS, measNoiseRad};
    for (const Entry& e : cache) {
        if (e.used && e.args == args) {
            return e.gains;
        }
    }
    const SteadyGains g = iterateRiccati(dtS, angleNoiseRadRtHz, biasDriftRadRtS, measNoiseRad);
    cache[next] = Entry{args, g, true};
    next = (next + 1) % cache.size();
    return g;
}

template class OrientationFilter<FloatTypes>;
template class OrientationFilter<FixedTypes>;

}  // namespace caphub::fusion
