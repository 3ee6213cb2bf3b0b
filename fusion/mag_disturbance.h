// Magnetic disturbance detection for the heading correction: a sample is trusted when its field
// norm and dip angle match a learned reference. A different field that stays steady through
// motion for long enough is accepted as the new reference; a rejected phase ends with a short
// period of faster heading correction (recovery).
#pragma once

#include <cstdint>

#include "fusion/scalar_ops.h"
#include "hal/core/angles.h"

namespace caphub::fusion {

struct MagDisturbanceParams {
    double normTh = 0.1;     // relative field-norm deviation tolerated (0.1 = 10 %)
    double dipThDeg = 10.0;  // deg, dip deviation tolerated (compared as sin(dip))
    double refTauS = 20.0;   // s, time constant with which the reference follows trusted samples
    double newFieldTimeS = 20.0;  // s, a steady new field is accepted after this much motion in it
    double newFieldMinRateDps =
        20.0;                    // deg/s, the motion that counts towards accepting a new field
    double candidateTauS = 1.0;  // s, time constant of the candidate-field average
    double recoveryTimeS = 5.0;  // s, faster heading correction after a rejection
};

template <typename S>
struct MagDisturbanceCoefficients {
    typename S::Coef refK{};       // per-sample gain of the reference average
    typename S::Coef candK{};      // per-sample gain of the candidate average
    typename S::Coef normLoSq{};   // (1 - normTh)^2
    typename S::Coef normHiSq{};   // (1 + normTh)^2
    typename S::Unit dipTh{};      // tolerated |sin(dip) - sin(dipRef)|
    typename S::Coef minRateSq{};  // (rad/s)^2
    std::int32_t newFieldSamples = 0;
    std::int32_t recoverySamples = 0;
};

template <typename S>
struct MagDisturbanceState {
    typename S::MagSq refNormSq{};  // uT^2, learned field norm squared
    typename S::Unit refDip{};  // learned sin(dip) (the earth-frame up component of the unit field)
    typename S::MagSq candNormSq{};
    typename S::Unit candDip{};
    std::int32_t candSamples = 0;   // samples (with motion) the candidate has stayed steady
    std::int32_t recoveryLeft = 0;  // samples of faster heading correction left
    bool refValid = false;
    bool disturbed = false;
};

template <typename S>
MagDisturbanceCoefficients<S> makeMagDisturbanceCoefficients(const MagDisturbanceParams& p,
                                                             double magPeriodS) {
    using hal::kDegToRad;
    using Coef = typename S::Coef;
    MagDisturbanceCoefficients<S> c;
    c.refK = fromDouble<Coef>(magPeriodS / (p.refTauS + magPeriodS));
    c.candK = fromDouble<Coef>(magPeriodS / (p.candidateTauS + magPeriodS));
    c.normLoSq = fromDouble<Coef>((1.0 - p.normTh) * (1.0 - p.normTh));
    c.normHiSq = fromDouble<Coef>((1.0 + p.normTh) * (1.0 + p.normTh));
    // The dip is compared through its sine, the up component of the unit field; near the
    // reference dip (about 60 deg here) d(sin)/d(dip) = cos(dip), so the threshold on the sine is
    // dipTh * cos(60 deg), the tolerance a person would state in degrees.
    c.dipTh = fromDouble<typename S::Unit>(std::sin(p.dipThDeg * kDegToRad) * 0.5);
    const double minRate = p.newFieldMinRateDps * kDegToRad;
    c.minRateSq = fromDouble<Coef>(minRate * minRate);
    c.newFieldSamples = static_cast<std::int32_t>(p.newFieldTimeS / magPeriodS + 0.5);
    c.recoverySamples = static_cast<std::int32_t>(p.recoveryTimeS / magPeriodS + 0.5);
    return c;
}

namespace detail {

// normSq within [lo, hi] * refSq, and |dip - refDip| <= dipTh.
template <typename S>
bool matchesField(const MagDisturbanceCoefficients<S>& c, typename S::MagSq normSq,
                  typename S::Unit dip, typename S::MagSq refSq, typename S::Unit refDip) {
    const auto lo = scalarCast<typename S::MagSq>(c.normLoSq * refSq);
    const auto hi = scalarCast<typename S::MagSq>(c.normHiSq * refSq);
    return normSq >= lo && normSq <= hi && absOf(dip - refDip) <= c.dipTh;
}

}  // namespace detail

// Classifies one magnetometer sample from its squared norm (uT^2) and sin(dip) (the earth-frame
// up component of the unit field, estimated with the current orientation). `moving` is
// |gyr|^2 > minRateSq, decided by the caller. Returns true when the sample may correct the heading.
template <typename S>
bool magClassify(const MagDisturbanceCoefficients<S>& c, MagDisturbanceState<S>& s,
                 typename S::MagSq normSq, typename S::Unit dip, bool moving) {
    if (!s.refValid) {
        s.refNormSq = normSq;
        s.refDip = dip;
        s.candNormSq = normSq;
        s.candDip = dip;
        s.refValid = true;
        s.disturbed = false;
        return true;
    }
    if (detail::matchesField(c, normSq, dip, s.refNormSq, s.refDip)) {
        if (s.disturbed) {
            s.disturbed = false;
            s.recoveryLeft = c.recoverySamples;
        }
        s.refNormSq = s.refNormSq + scalarCast<typename S::MagSq>(c.refK * (normSq - s.refNormSq));
        s.refDip = s.refDip + scalarCast<typename S::Unit>(c.refK * (dip - s.refDip));
        s.candSamples = 0;
        s.candNormSq = normSq;
        s.candDip = dip;
        return true;
    }
    // Disturbed. Track whether the field is a steady new one: an attached magnet (hard iron that
    // moves with the sensor) changes norm and dip as the sensor turns and never qualifies; a
    // changed but homogeneous environment does.
    s.disturbed = true;
    s.recoveryLeft = 0;
    if (detail::matchesField(c, normSq, dip, s.candNormSq, s.candDip)) {
        s.candNormSq =
            s.candNormSq + scalarCast<typename S::MagSq>(c.candK * (normSq - s.candNormSq));
        s.candDip = s.candDip + scalarCast<typename S::Unit>(c.candK * (dip - s.candDip));
        if (moving) {
            ++s.candSamples;
        }
        if (s.candSamples >= c.newFieldSamples) {
            s.refNormSq = s.candNormSq;
            s.refDip = s.candDip;
            s.disturbed = false;
            s.candSamples = 0;
            s.recoveryLeft = c.recoverySamples;
            return true;
        }
    } else {
        s.candNormSq = normSq;
        s.candDip = dip;
        s.candSamples = 0;
    }
    return false;
}

}  // namespace caphub::fusion
