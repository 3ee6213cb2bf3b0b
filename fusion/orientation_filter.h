// The orientation filter of one 9-axis sensor: gyroscope strapdown in a quasi-inertial frame,
// gravity and magnetic-north corrections applied as an earth-frame correction, and a gyroscope
// bias tracked by a stationary Kalman filter and at rest. Templated on the scalar types so the
// same code runs in float and in Q-format fixed point (docs/fusion.md). No heap, no I/O.
#pragma once

#include <cstdint>
#include <type_traits>

#include "fusion/mag_disturbance.h"
#include "fusion/rest_detector.h"
#include "fusion/scalar_ops.h"
#include "hal/core/angles.h"

namespace caphub::fusion {

// The scalar types of the float filter.
struct FloatTypes {
    using Unit = float;   // quaternion components, unit vectors, small angles (rad)
    using Gyr = float;    // rad/s
    using Acc = float;    // m/s^2
    using Mag = float;    // uT
    using MagSq = float;  // uT^2
    using Coef = float;   // gains, periods
    using Bias = float;   // rad/s
};

// The Q formats of the fixed-point filter and their ranges (docs/fusion.md, "Q formats").
struct FixedTypes {
    using Unit = Fixed<30>;  // [-2, 2), step 9.3e-10
    using Gyr = Fixed<25>;   // [-64, 64) rad/s, step 3.0e-8 rad/s
    using Acc = Fixed<22>;   // [-512, 512) m/s^2 (52 g), step 2.4e-7 m/s^2
    using Mag = Fixed<20>;   // [-2048, 2048) uT, step 9.5e-7 uT; inputs clamped to +-1000 uT
    using MagSq = Fixed<8>;  // [-8.4e6, 8.4e6) uT^2, step 0.004 uT^2
    using Coef = Fixed<30>;  // [-2, 2), step 9.3e-10: a 1e-6 gain keeps three digits
    using Bias = Fixed<30>;  // [-2, 2) rad/s, step 9.3e-10 rad/s: bias steps of 1e-8 rad/s count
};

// Every parameter with its unit and default. One set for all motions (docs/fusion.md).
struct FilterParams {
    double gyrRateHz = 285.714;  // Hz, gyroscope sample rate
    double accRateHz = 285.714;  // Hz, accelerometer sample rate
    double magRateHz = 285.714;  // Hz, magnetometer sample rate

    // The gravity low-pass in the quasi-inertial frame: second order, state-variable form.
    double tauAccS = 1.8;       // s, its delay at low frequency (2 zeta / omega_c)
    double accLpDamping = 0.5;  // its damping ratio zeta (0.707 = Butterworth)
    // Kalman model of one horizontal axis: angle error driven by gyroscope noise (and gyroscope
    // model error), a gyroscope bias that wanders, and the filtered gravity direction as the
    // measurement.
    double gyrNoiseDpsRtHz = 0.3;    // deg/s/sqrt(Hz), angle random walk of the strapdown
    double biasDriftDpsRtS = 0.002;  // deg/s/sqrt(s), random walk of the gyroscope bias
    // Measurement noises as densities, so the time constants do not change with the rate: the
    // noise of one sample is density / sqrt(period).
    double inclNoiseDegRtHz = 0.03;    // deg/sqrt(Hz), noise of the filtered gravity direction
    double headingNoiseDegRtHz = 9.5;  // deg/sqrt(Hz), noise of the magnetometer heading

    double accDynamicThMps2 = 2.0;    // m/s^2, | |acc| - g | above which the sample is "dynamic"
    double gravityMps2 = 9.81;        // m/s^2
    double biasMaxDps = 20.0;         // deg/s, the bias estimate is clamped to this
    double restBiasTauS = 2.0;        // s, time constant of the bias average at rest
    double recoveryGainFactor = 4.0;  // heading gain multiplier during recovery
    // Input plausibility (docs/fusion.md, "Input validation"): a reading beyond these on any
    // axis, or not finite, cannot come from a supported chip and is rejected and counted.
    // 1.25 times the largest full scale of the catalogue (2000 deg/s, 16 g, the AK09916's
    // 4912 uT): the margin covers the calibration's scale and offset.
    double gyrLimitDps = 2500.0;  // deg/s
    double accLimitMps2 = 196.0;  // m/s^2, 20 g
    double magLimitUt = 6140.0;   // uT (the fixed-point format stops at 2048 uT before it)
    RestParams rest;
    MagDisturbanceParams magDisturbance;
};

// The first parameter that is not finite or outside its range (a rate from 0.6 Hz to 20 kHz,
// time constants and noise densities above zero, ...), by its name in FilterParams; null when
// all are usable. The filter's sample periods come from the rates: there is no per-sample dt.
const char* invalidFilterParameter(const FilterParams& params);

// What a filter refused since setup() (docs/fusion.md, "Input validation"). Saturating counts.
struct FilterRejections {
    std::uint32_t gyr = 0;          // gyroscope samples: non-finite or beyond gyrLimitDps
    std::uint32_t acc = 0;          // accelerometer samples: non-finite or beyond accLimitMps2
    std::uint32_t mag = 0;          // magnetometer samples: non-finite or beyond magLimitUt
    std::uint32_t linAcc = 0;       // known accelerations (updateAcc) taken as unknown instead
    std::uint32_t stateResets = 0;  // the state was found non-finite and restarted
    std::uint32_t samples() const { return gyr + acc + mag; }
};

// Derived coefficients: what setup() computes once from the parameters and the rates.
template <typename S>
struct FilterCoefficients {
    typename S::Coef gyrPeriodS{};  // s
    typename S::Coef accLpW{};      // omega_c * period of the gravity low-pass
    typename S::Coef accLpDamp{};   // 2 zeta
    typename S::Coef kIncl{};       // inclination gain per accelerometer sample
    typename S::Coef kBias{};       // bias gain per accelerometer sample, (rad/s)/rad
    typename S::Coef kHead{};       // heading gain per magnetometer sample
    typename S::Coef kHeadRecovery{};
    typename S::Coef restBiasK{};   // bias average gain per gyroscope sample at rest
    typename S::Coef dynLoSq{};     // ((g - th) / g)^2: |acc| is compared in units of g
    typename S::Coef dynHiSq{};     // ((g + th) / g)^2
    typename S::Bias biasMax{};     // rad/s
    typename S::Coef invGravity{};  // s^2/m, 1 / g
    typename S::Gyr gyrLimit{};     // rad/s, largest plausible reading per axis
    typename S::Acc accLimit{};     // m/s^2
    typename S::Mag magLimit{};     // uT (saturated in fixed point: the format's range applies)
    RestCoefficients<S> rest;
    MagDisturbanceCoefficients<S> mag;
};

template <typename S>
struct FilterState {
    Quat<typename S::Unit> qGyr = Quat<typename S::Unit>::identity();   // sensor -> quasi-inertial
    Quat<typename S::Unit> qCorr = Quat<typename S::Unit>::identity();  // quasi-inertial -> earth
    Vec3<typename S::Bias> bias;                                        // rad/s, sensor frame
    Vec3<typename S::Acc> accLp;    // filtered gravity, quasi-inertial frame
    Vec3<typename S::Acc> accBand;  // the low-pass's second state (its rate / omega_c)
    Vec3<typename S::Gyr> lastGyr;  // rad/s, bias-corrected
    RestState<S> rest;
    MagDisturbanceState<S> mag;
    bool inclinationInit = false;
    bool headingInit = false;
    bool atRest = false;
    bool dynamic = false;
    bool magUsed = false;
    bool gyrClipped = false;       // the last gyroscope sample was clipped
    std::uint32_t clipEvents = 0;  // clipping episodes so far
};

// Steady-state Kalman gains of the angle/bias model sampled every dtS: angle gain and bias gain
// ((rad/s)/rad) per measurement, from the discrete Riccati equation (orientation_filter.cpp).
struct SteadyGains {
    double kAngle = 0.0;
    double kBias = 0.0;
};
SteadyGains steadyStateGains(double dtS, double angleNoiseRadRtHz, double biasDriftRadRtS,
                             double measNoiseRad);

template <typename S>
class OrientationFilter {
public:
    using Unit = typename S::Unit;
    using Gyr = typename S::Gyr;
    using Acc = typename S::Acc;
    using Mag = typename S::Mag;
    using MagSq = typename S::MagSq;
    using Coef = typename S::Coef;
    using Bias = typename S::Bias;

    explicit OrientationFilter(const FilterParams& params = FilterParams{}) { setup(params); }

    // Computes the coefficients and clears the state and the rejection counts. Parameters that
    // invalidFilterParameter() refuses leave the filter unconfigured: it rejects every sample.
    void setup(const FilterParams& params);
    void resetState() { state_ = FilterState<S>{}; }
    bool configured() const { return configured_; }

    // One sample of each sensor (sensor frame; rad/s, m/s^2, uT), each at its own rate. A
    // reading that is not finite or beyond the sensor's limit on some axis is rejected: counted
    // (rejections()) and not used, as if it had not been read. After each update a non-finite
    // state (impossible from checked inputs, but setState() can bring one) is restarted: the
    // next good samples align it afresh, as at the start.
    // clipped: the chip's raw rate reached its full scale on some axis, so the rate is only a
    // lower bound and the strapdown lost an unknown rotation; counted (clipEvents) so that the
    // error that follows can be told from the filter's own.
    // The three updates are defined [[gnu::flatten]]: every helper they call (products,
    // rotations, the series exp, the renormalisation) is inlined into them. At -O2 GCC kept
    // smallRotation and renormalized out of line, and a full update on real data cost 159 ns
    // instead of 111 (docs/fusion.md, "Speed"). No result changes: fixed point is integer
    // arithmetic, and float is built without contraction (ISO C++, -ffp-contract=off).
    void updateGyr(const Vec3<Gyr>& gyr, bool clipped = false);
    // linAccEarth: the sensor's linear acceleration in the earth frame (ENU, m/s^2) when it is
    // known from outside, such as the body's motion from its foot contacts; it is taken out of
    // the specific force before the gravity low-pass, so that a sustained acceleration (starting
    // to walk, braking) does not tilt the estimate. Zero: unknown (as is one beyond the
    // accelerometer's limit, or not finite, counted in rejections().linAcc).
    void updateAcc(const Vec3<Acc>& acc, const Vec3<Acc>& linAccEarth = Vec3<Acc>{});
    void updateMag(const Vec3<Mag>& mag);

    // Orientation sensor -> earth (ENU).
    Quat<Unit> quat() const { return quatMul(state_.qCorr, state_.qGyr); }
    Vec3<Bias> bias() const { return state_.bias; }
    bool atRest() const { return state_.atRest; }
    bool magDisturbed() const { return state_.mag.disturbed; }
    std::uint32_t clipEvents() const { return state_.clipEvents; }
    // Kept across resetState() and the restarts it counts; cleared by setup().
    const FilterRejections& rejections() const { return rejections_; }

    const FilterParams& params() const { return params_; }
    const FilterCoefficients<S>& coefficients() const { return coeffs_; }
    const FilterState<S>& state() const { return state_; }
    // A state holding a non-finite value or a quaternion off the unit sphere is not taken: the
    // filter restarts instead (counted).
    void setState(const FilterState<S>& s);

private:
    // The updates once their inputs passed the checks.
    void updateAccChecked(const Vec3<Acc>& acc, const Vec3<Acc>& linAccEarth);
    void updateMagChecked(const Vec3<Mag>& mag);
    void correctInclination(const Vec3<Unit>& u);
    // Restarts the filter when `q`, a quaternion an update wrote, is not finite or has left the
    // unit sphere (|q|^2 off by 2 %; renormalisation keeps it within 1e-6). Only the quaternion
    // updates can turn checked inputs into such a value: the series exp map and the one-step
    // renormalisation diverge on a turn of several rad per sample, which a real rate gives at a
    // low sample rate (40 rad/s at 5 Hz; in fixed point the angle saturates and the norm drifts
    // instead). Everything else in the state is a low-pass of checked inputs or follows from
    // the quaternions within the same update, and setState() checks all of it.
    void restartIfDiverged(const Quat<Unit>& q) {
        const Unit n2 = scalarCast<Unit>(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z);
        if (!(n2 > fromDouble<Unit>(0.98) && n2 < fromDouble<Unit>(1.02))) [[unlikely]] {
            restart();  // NaN fails the test too
        }
    }
    // Clears the state (keeping the clipping count) and counts the restart; the next samples
    // align it afresh, as at the start.
    [[gnu::cold]] void restart();
    // Counts one rejected input, saturating.
    [[gnu::cold]] static void reject(std::uint32_t& n) { n += n < UINT32_MAX ? 1U : 0U; }

    FilterParams params_;
    FilterCoefficients<S> coeffs_;
    FilterState<S> state_;
    FilterRejections rejections_;
    bool configured_ = false;
};

namespace detail {

// True when every value of a float state is finite (a fixed-point state always is).
template <typename S>
bool finiteState(const FilterState<S>& s) {
    if constexpr (std::is_floating_point_v<typename S::Unit>) {
        const auto v = [](const auto& x) { return x.x + x.y + x.z; };
        const auto q = [](const auto& x) { return x.w + x.x + x.y + x.z; };
        return std::isfinite(q(s.qGyr) + q(s.qCorr) + v(s.bias) + v(s.accLp) + v(s.accBand) +
                             v(s.lastGyr) + v(s.rest.gyrLp) + v(s.rest.accLp) + s.mag.refNormSq +
                             s.mag.refDip + s.mag.candNormSq + s.mag.candDip);
    } else {
        return true;
    }
}

}  // namespace detail

// ---------------------------------------------------------------------------------------------

template <typename S>
void OrientationFilter<S>::setup(const FilterParams& p) {
    using hal::kDegToRad;
    params_ = p;
    rejections_ = FilterRejections{};
    configured_ = invalidFilterParameter(p) == nullptr;
    if (!configured_) {
        coeffs_ = FilterCoefficients<S>{};
        resetState();
        return;
    }
    const double gyrDt = 1.0 / p.gyrRateHz;
    const double accDt = 1.0 / p.accRateHz;
    const double magDt = 1.0 / p.magRateHz;
    FilterCoefficients<S> c;
    c.gyrPeriodS = fromDouble<Coef>(gyrDt);
    // omega_c^2 / (s^2 + 2 zeta omega_c s + omega_c^2), whose delay at DC is 2 zeta / omega_c.
    const double omegaC = 2.0 * p.accLpDamping / p.tauAccS;
    c.accLpW = fromDouble<Coef>(omegaC * accDt);
    c.accLpDamp = fromDouble<Coef>(2.0 * p.accLpDamping);
    const SteadyGains incl =
        steadyStateGains(accDt, p.gyrNoiseDpsRtHz * kDegToRad, p.biasDriftDpsRtS * kDegToRad,
                         p.inclNoiseDegRtHz * kDegToRad / std::sqrt(accDt));
    c.kIncl = fromDouble<Coef>(incl.kAngle);
    c.kBias = fromDouble<Coef>(incl.kBias);
    const SteadyGains head = steadyStateGains(magDt, p.gyrNoiseDpsRtHz * kDegToRad, 0.0,
                                              p.headingNoiseDegRtHz * kDegToRad / std::sqrt(magDt));
    c.kHead = fromDouble<Coef>(head.kAngle);
    c.kHeadRecovery = fromDouble<Coef>(std::min(1.0, head.kAngle * p.recoveryGainFactor));
    c.restBiasK = fromDouble<Coef>(1.0 - std::exp(-gyrDt / p.restBiasTauS));
    // |acc|^2 is compared in units of g^2 (acc / g in Acc, squared in Coef).
    const double lo = std::max(0.0, (p.gravityMps2 - p.accDynamicThMps2) / p.gravityMps2);
    const double hi = (p.gravityMps2 + p.accDynamicThMps2) / p.gravityMps2;
    c.dynLoSq = fromDouble<Coef>(lo * lo);
    c.dynHiSq = fromDouble<Coef>(std::min(1.99, hi * hi));
    c.biasMax = fromDouble<Bias>(p.biasMaxDps * kDegToRad);
    c.rest = makeRestCoefficients<S>(p.rest, gyrDt, accDt);
    c.mag = makeMagDisturbanceCoefficients<S>(p.magDisturbance, magDt);
    c.invGravity = fromDouble<Coef>(1.0 / p.gravityMps2);
    c.gyrLimit = fromDouble<Gyr>(p.gyrLimitDps * kDegToRad);
    c.accLimit = fromDouble<Acc>(p.accLimitMps2);
    c.magLimit = fromDouble<Mag>(p.magLimitUt);
    coeffs_ = c;
    resetState();
}

template <typename S>
void OrientationFilter<S>::restart() {
    const std::uint32_t clips = state_.clipEvents;
    resetState();
    state_.clipEvents = clips;
    reject(rejections_.stateResets);
}

template <typename S>
void OrientationFilter<S>::setState(const FilterState<S>& s) {
    state_ = s;
    if (!detail::finiteState(s)) {
        restart();
        return;
    }
    restartIfDiverged(state_.qGyr);
    restartIfDiverged(state_.qCorr);
}

template <typename S>
[[gnu::flatten]] void OrientationFilter<S>::updateGyr(const Vec3<Gyr>& gyr, bool clipped) {
    if (!configured_ || !withinLimit(gyr, coeffs_.gyrLimit)) [[unlikely]] {
        reject(rejections_.gyr);
        return;
    }
    FilterState<S>& s = state_;
    if (clipped && !s.gyrClipped) {
        ++s.clipEvents;
    }
    s.gyrClipped = clipped;
    const Vec3<Gyr> b = castVec<Gyr>(s.bias);
    restUpdateGyr(coeffs_.rest, s.rest, gyr, b);
    s.atRest = restDetected(coeffs_.rest, s.rest);
    if (s.atRest) {
        // At rest the low-passed rate is the bias: average it directly (the sharper estimate).
        s.bias = s.bias + scaled(coeffs_.restBiasK, castVec<Bias>(s.rest.gyrLp) - s.bias);
    }
    const Vec3<Gyr> w = gyr - b;
    s.lastGyr = w;
    const Vec3<Unit> theta{scalarCast<Unit>(coeffs_.gyrPeriodS * w.x),
                           scalarCast<Unit>(coeffs_.gyrPeriodS * w.y),
                           scalarCast<Unit>(coeffs_.gyrPeriodS * w.z)};
    s.qGyr = renormalized(quatMul(s.qGyr, smallRotation(theta)));
    restartIfDiverged(s.qGyr);
}

template <typename S>
[[gnu::flatten]] void OrientationFilter<S>::updateAcc(const Vec3<Acc>& acc,
                                                      const Vec3<Acc>& linAccEarthIn) {
    if (!configured_ || !withinLimit(acc, coeffs_.accLimit)) [[unlikely]] {
        reject(rejections_.acc);
        return;
    }
    Vec3<Acc> linAccEarth = linAccEarthIn;
    if (!withinLimit(linAccEarth, coeffs_.accLimit)) [[unlikely]] {
        reject(rejections_.linAcc);
        linAccEarth = Vec3<Acc>{};
    }
    updateAccChecked(acc, linAccEarth);
    restartIfDiverged(state_.qCorr);
}

template <typename S>
void OrientationFilter<S>::updateAccChecked(const Vec3<Acc>& acc, const Vec3<Acc>& linAccEarth) {
    FilterState<S>& s = state_;
    restUpdateAcc(coeffs_.rest, s.rest, acc);

    // High dynamics: |acc| far from g. Compared as (|acc| / g)^2 so that the square fits Coef.
    const Vec3<Acc> ag = scaled(coeffs_.invGravity, acc);
    const Coef n2 = scalarCast<Coef>(ag.x * ag.x + ag.y * ag.y + ag.z * ag.z);
    s.dynamic = n2 < coeffs_.dynLoSq || n2 > coeffs_.dynHiSq;

    // Gravity in the quasi-inertial frame: the specific force less the known acceleration.
    const Vec3<Acc> accI = rotate(s.qGyr, acc) - rotate(conjugate(s.qCorr), linAccEarth);
    if (!s.inclinationInit) {
        // Initial alignment: take the first sample as gravity, exactly.
        s.accLp = accI;
        s.accBand = Vec3<Acc>{};
        Vec3<Unit> u;
        if (!normalizeInto(rotate(s.qCorr, accI), u)) {
            return;
        }
        // Shortest rotation taking u to +z: [1 + u.z, u x z] normalised (halved to stay in range).
        Quat<Unit> r{half(fromDouble<Unit>(1.0)) + half(u.z), half(u.y), -half(u.x), Unit{}};
        if (!normalizeInto(r, r)) {
            r = Quat<Unit>{Unit{}, fromDouble<Unit>(1.0), Unit{},
                           Unit{}};  // upside down: half turn
        }
        s.qCorr = renormalized(quatMul(r, s.qCorr));
        s.inclinationInit = true;
        return;
    }
    // Semi-implicit Euler of lp' = omega_c band, band' = omega_c (x - lp - 2 zeta band): stable
    // for omega_c dt < 1 and well conditioned in fixed point (no coefficient near 1 - 1e-6,
    // unlike a direct-form biquad at this cut-off).
    s.accLp = s.accLp + scaled(coeffs_.accLpW, s.accBand);
    s.accBand =
        s.accBand + scaled(coeffs_.accLpW, accI - s.accLp - scaled(coeffs_.accLpDamp, s.accBand));

    Vec3<Unit> u;
    if (!normalizeInto(rotate(s.qCorr, s.accLp), u)) {
        return;
    }
    correctInclination(u);
}

// u: the filtered gravity direction in the earth frame. The rotation that takes it to +z has the
// axis u x z = (u.y, -u.x, 0) and, for small errors, that vector as its rotation vector.
template <typename S>
void OrientationFilter<S>::correctInclination(const Vec3<Unit>& u) {
    FilterState<S>& s = state_;
    const Vec3<Unit> e{u.y, -u.x, Unit{}};
    const Vec3<Unit> d{scalarCast<Unit>(coeffs_.kIncl * e.x), scalarCast<Unit>(coeffs_.kIncl * e.y),
                       Unit{}};
    s.qCorr = renormalized(quatMul(smallRotation(d), s.qCorr));

    // The bias part of the Kalman update: the earth-frame error maps to the sensor frame through
    // the inverse orientation. Not at rest (the rest average is sharper) and not under high
    // dynamics (the filtered gravity is least trustworthy then).
    if (s.atRest || s.dynamic) {
        return;
    }
    const Vec3<Unit> eS = rotate(conjugate(s.qGyr), rotate(conjugate(s.qCorr), e));
    s.bias = s.bias - scaled(coeffs_.kBias, castVec<Bias>(eS));
    const Bias m = coeffs_.biasMax;
    auto clamp = [m](Bias v) { return v > m ? m : (v < -m ? -m : v); };
    s.bias = {clamp(s.bias.x), clamp(s.bias.y), clamp(s.bias.z)};
}

template <typename S>
[[gnu::flatten]] void OrientationFilter<S>::updateMag(const Vec3<Mag>& magIn) {
    if (!configured_ || !withinLimit(magIn, coeffs_.magLimit)) [[unlikely]] {
        reject(rejections_.mag);
        state_.magUsed = false;
        return;
    }
    updateMagChecked(magIn);
    restartIfDiverged(state_.qCorr);
}

template <typename S>
void OrientationFilter<S>::updateMagChecked(const Vec3<Mag>& magIn) {
    FilterState<S>& s = state_;
    s.magUsed = false;
    if (!s.inclinationInit) {
        return;
    }
    // Clamp to the documented input range (keeps the squared norm inside MagSq).
    const Mag lim = fromDouble<Mag>(1000.0);
    auto clamp = [lim](Mag v) { return v > lim ? lim : (v < -lim ? -lim : v); };
    const Vec3<Mag> mag{clamp(magIn.x), clamp(magIn.y), clamp(magIn.z)};

    const Vec3<Mag> mE = rotate(s.qCorr, rotate(s.qGyr, mag));
    Vec3<Unit> u;
    if (!normalizeInto(mE, u)) {
        return;
    }
    const MagSq normSq = scalarCast<MagSq>(mag.x * mag.x + mag.y * mag.y + mag.z * mag.z);
    const Vec3<Gyr>& w = s.lastGyr;
    const bool moving = !detail::within(w, fromDouble<Gyr>(1.0), coeffs_.mag.minRateSq);
    const bool trusted = magClassify(coeffs_.mag, s.mag, normSq, u.z, moving);

    // Heading error: the rotation about +z that brings the horizontal field to north (+y):
    // sin = x / |h|, cos = y / |h|.
    Unit hx = u.x;
    Unit hy = u.y;
    if (!normalize2(hx, hy)) {
        return;  // field vertical: no heading information
    }
    if (!s.headingInit) {
        Quat<Unit> r{half(fromDouble<Unit>(1.0)) + half(hy), Unit{}, Unit{}, half(hx)};
        if (!normalizeInto(r, r)) {
            r = Quat<Unit>{Unit{}, Unit{}, Unit{}, fromDouble<Unit>(1.0)};  // pointing south
        }
        s.qCorr = renormalized(quatMul(r, s.qCorr));
        s.headingInit = true;
        s.magUsed = true;
        return;
    }
    if (!trusted) {
        return;
    }
    // Beyond 90 deg the sine turns back; use the full step in the right direction instead.
    const Unit one = fromDouble<Unit>(1.0);
    const Unit err = hy < Unit{} ? (hx < Unit{} ? -one : one) : hx;
    Coef k = coeffs_.kHead;
    if (s.mag.recoveryLeft > 0) {
        k = coeffs_.kHeadRecovery;
        --s.mag.recoveryLeft;
    }
    const Vec3<Unit> d{Unit{}, Unit{}, scalarCast<Unit>(k * err)};
    s.qCorr = renormalized(quatMul(smallRotation(d), s.qCorr));
    s.magUsed = true;
}

}  // namespace caphub::fusion
