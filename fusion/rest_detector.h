// Rest detection for the orientation filter: the sensor is at rest when gyroscope and
// accelerometer stay close to their own low-pass values, and the rate is small, for a minimum
// time. At rest the filter takes the gyroscope bias straight from the low-passed rate.
#pragma once

#include <cstdint>

#include "fusion/scalar_ops.h"
#include "hal/core/angles.h"

namespace caphub::fusion {

struct RestParams {
    double filterTauS = 0.5;  // s, time constant of the low-pass the samples are compared with
    double thGyrDps = 2.0;    // deg/s, largest |gyr - lowpass(gyr)| and |lowpass(gyr) - bias|
    double thAccMps2 = 0.5;   // m/s^2, largest |acc - lowpass(acc)|
    double minTimeS = 1.5;    // s, how long both must hold before rest is declared
};

// Derived coefficients (setup), in the filter's scalar types S.
template <typename S>
struct RestCoefficients {
    typename S::Coef gyrLpK{};   // low-pass gain per gyroscope sample
    typename S::Coef accLpK{};   // low-pass gain per accelerometer sample
    typename S::Gyr thGyr{};     // rad/s, per-component pre-check
    typename S::Acc thAcc{};     // m/s^2, per-component pre-check
    typename S::Coef thGyrSq{};  // (rad/s)^2
    typename S::Coef thAccSq{};  // (m/s^2)^2
    std::int32_t minGyrSamples = 0;
    std::int32_t minAccSamples = 0;
};

template <typename S>
struct RestState {
    Vec3<typename S::Gyr> gyrLp;
    Vec3<typename S::Acc> accLp;
    std::int32_t gyrQuietSamples = 0;  // consecutive gyroscope samples within the thresholds
    std::int32_t accQuietSamples = 0;
    bool gyrStarted = false;
    bool accStarted = false;
};

template <typename S>
RestCoefficients<S> makeRestCoefficients(const RestParams& p, double gyrPeriodS,
                                         double accPeriodS) {
    using hal::kDegToRad;
    RestCoefficients<S> c;
    c.gyrLpK = fromDouble<typename S::Coef>(gyrPeriodS / (p.filterTauS + gyrPeriodS));
    c.accLpK = fromDouble<typename S::Coef>(accPeriodS / (p.filterTauS + accPeriodS));
    const double thGyr = p.thGyrDps * kDegToRad;
    c.thGyr = fromDouble<typename S::Gyr>(thGyr);
    c.thAcc = fromDouble<typename S::Acc>(p.thAccMps2);
    c.thGyrSq = fromDouble<typename S::Coef>(thGyr * thGyr);
    c.thAccSq = fromDouble<typename S::Coef>(p.thAccMps2 * p.thAccMps2);
    c.minGyrSamples = static_cast<std::int32_t>(p.minTimeS / gyrPeriodS + 0.5);
    c.minAccSamples = static_cast<std::int32_t>(p.minTimeS / accPeriodS + 0.5);
    return c;
}

namespace detail {

// |d| < th, checked per component first so that the squares cannot overflow a fixed format.
template <typename T, typename Sq>
bool within(const Vec3<T>& d, T th, Sq thSq) {
    if (absOf(d.x) > th || absOf(d.y) > th || absOf(d.z) > th) {
        return false;
    }
    return scalarCast<Sq>(d.x * d.x + d.y * d.y + d.z * d.z) < thSq;
}

}  // namespace detail

// Feeds a raw gyroscope sample (rad/s); `bias` is the filter's current bias estimate.
template <typename S>
void restUpdateGyr(const RestCoefficients<S>& c, RestState<S>& s, const Vec3<typename S::Gyr>& gyr,
                   const Vec3<typename S::Gyr>& bias) {
    if (!s.gyrStarted) {
        s.gyrLp = gyr;
        s.gyrStarted = true;
    } else {
        s.gyrLp = s.gyrLp + scaled(c.gyrLpK, gyr - s.gyrLp);
    }
    const bool quiet = detail::within(gyr - s.gyrLp, c.thGyr, c.thGyrSq) &&
                       detail::within(s.gyrLp - bias, c.thGyr, c.thGyrSq);
    s.gyrQuietSamples = quiet ? s.gyrQuietSamples + (s.gyrQuietSamples < (1 << 30) ? 1 : 0) : 0;
}

template <typename S>
void restUpdateAcc(const RestCoefficients<S>& c, RestState<S>& s,
                   const Vec3<typename S::Acc>& acc) {
    if (!s.accStarted) {
        s.accLp = acc;
        s.accStarted = true;
    } else {
        s.accLp = s.accLp + scaled(c.accLpK, acc - s.accLp);
    }
    const bool quiet = detail::within(acc - s.accLp, c.thAcc, c.thAccSq);
    s.accQuietSamples = quiet ? s.accQuietSamples + (s.accQuietSamples < (1 << 30) ? 1 : 0) : 0;
}

template <typename S>
bool restDetected(const RestCoefficients<S>& c, const RestState<S>& s) {
    return s.gyrQuietSamples >= c.minGyrSamples && s.accQuietSamples >= c.minAccSamples;
}

}  // namespace caphub::fusion
