#include "board/sim/imu_model.h"

#include <array>
#include <cmath>
#include <numbers>

#include <fmt/format.h>

namespace caphub::board::sim {

namespace {

constexpr double kRadPerDeg = std::numbers::pi / 180.0;
constexpr double kMps2PerG = 9.80665;  // standard gravity, for datasheet figures in g
constexpr double kUtPerGauss = 100.0;

// mu0 / (4 pi) in uT m^3 / (A m^2): 1e-7 T m/A, times 1e6 uT/T.
constexpr double kDipoleUt = 0.1;
// Closer than this to a dipole the point model is meaningless; the distance is clamped so that
// the field stays finite.
constexpr double kMinDipoleDistanceM = 0.01;

// Random streams: each kind of random quantity has its own, so that changing one figure does
// not reshuffle the others.
enum Stream : std::uint64_t {
    kGyroNoise = 1,
    kAccelNoise,
    kMagNoise,
    kGyroWalk,
    kAccelWalk,
    kMagWalk,
    kGyroBias = 16,
    kGyroScale,
    kGyroCrossA,
    kGyroCrossB,
    kAccelBias,
    kAccelScale,
    kAccelCrossA,
    kAccelCrossB,
    kMagOffset,
    kMagScale,
    kMagCrossA,
    kMagCrossB,
    kHardIron,
    kSoftIronDiag,
    kSoftIronOff,
};

// The SplitMix64 finaliser: a bijective mixer with good avalanche, so that hashing (seed,
// stream, instant) gives independent-looking uniform bits for every instant.
std::uint64_t mix(std::uint64_t x) {
    x += 0x9E3779B97F4A7C15ull;
    x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
    x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
    return x ^ (x >> 31);
}

// A uniform in (0, 1] from 53 random bits.
double unit(std::uint64_t bits) {
    return static_cast<double>((bits >> 11) + 1) * 0x1.0p-53;
}

// Datasheet rules (docs/virtual-suit.md): typical figures are one sigma; a worst case where
// the datasheet gives no maximum is three times the typical figure, and noise 1.5 times.
constexpr double kHarshConstant = 3.0;
constexpr double kHarshNoise = 1.5;
constexpr double kHarshWalk = 5.0;

TriadErrors harsh(TriadErrors t) {
    t.noiseDensity *= kHarshNoise;
    t.noiseRms *= kHarshNoise;
    t.biasRandomWalk *= kHarshWalk;
    t.turnOnBias *= kHarshConstant;
    t.scaleError *= kHarshConstant;
    t.crossAxis *= kHarshConstant;
    return t;
}

// Bias drift: the datasheets give the change of bias with temperature; a strapped sensor
// warming by about 1 degC over a 10-minute take drifts by that coefficient, spread as a random
// walk over 600 s.
constexpr double kDriftWindowS = 600.0;
double walkFromTempco(double perDegC) {
    return perDegC / std::sqrt(kDriftWindowS);
}

ImuErrorSpec icm20948Typical() {
    ImuErrorSpec s;
    // DS-000189 Table 1 (gyroscope): rate noise spectral density 0.015 dps/sqrt(Hz); initial ZRO
    // tolerance +-5 dps; sensitivity scale factor tolerance +-1.5 %; cross-axis +-2 %;
    // ZRO variation over temperature +-0.05 dps/degC.
    s.gyro.noiseDensity = 0.015 * kRadPerDeg;
    s.gyro.turnOnBias = 5.0 * kRadPerDeg;
    s.gyro.scaleError = 0.015;
    s.gyro.crossAxis = 0.02;
    s.gyro.biasRandomWalk = walkFromTempco(0.05 * kRadPerDeg);
    // Table 2 (accelerometer): noise 230 ug/sqrt(Hz); zero-g initial tolerance +-50 mg
    // board-level; sensitivity initial tolerance +-0.5 %; cross-axis +-2 %; zero-g change
    // +-0.80 mg/degC.
    s.accel.noiseDensity = 230e-6 * kMps2PerG;
    s.accel.turnOnBias = 50e-3 * kMps2PerG;
    s.accel.scaleError = 0.005;
    s.accel.crossAxis = 0.02;
    s.accel.biasRandomWalk = walkFromTempco(0.80e-3 * kMps2PerG);
    // Table 3 (AK09916 magnetometer): zero-field output -2000..+2000 LSB at 0.15 uT/LSB, a
    // bound of 300 uT (sigma = bound / 3). No noise figure: 0.5 uT rms assumed (about 3 LSB).
    s.mag.noiseRms = 0.5;
    s.mag.turnOnBias = 300.0 / 3.0;
    return s;
}

ImuErrorSpec lsm6dsoxLis3mdlTypical() {
    ImuErrorSpec s;
    // LSM6DSOX DS13210 Table 2: gyro rate noise density 3.8 mdps/sqrt(Hz) (high-performance
    // mode); zero-rate level +-1 dps; sensitivity tolerance +-1 %; zero-rate change
    // +-0.01 dps/degC. No cross-axis figure: 1 % assumed.
    s.gyro.noiseDensity = 3.8e-3 * kRadPerDeg;
    s.gyro.turnOnBias = 1.0 * kRadPerDeg;
    s.gyro.scaleError = 0.01;
    s.gyro.crossAxis = 0.01;
    s.gyro.biasRandomWalk = walkFromTempco(0.01 * kRadPerDeg);
    // Accelerometer: noise density 70 ug/sqrt(Hz) (+-2 g, high-performance); zero-g level
    // +-20 mg; sensitivity tolerance +-1 %; zero-g change +-0.1 mg/degC. Cross-axis 1 % assumed.
    s.accel.noiseDensity = 70e-6 * kMps2PerG;
    s.accel.turnOnBias = 20e-3 * kMps2PerG;
    s.accel.scaleError = 0.01;
    s.accel.crossAxis = 0.01;
    s.accel.biasRandomWalk = walkFromTempco(0.1e-3 * kMps2PerG);
    // LIS3MDL DS10540 Table 2 (+-4 gauss, ultra-high-performance): RMS noise 3.2 mgauss (X, Y),
    // 4.1 mgauss (Z), the larger used on all axes; zero-gauss level +-1 gauss.
    s.mag.noiseRms = 4.1e-3 * kUtPerGauss;
    s.mag.turnOnBias = 1.0 * kUtPerGauss;
    return s;
}

// Not chip figures: the magnetisation and field distortion of a board and strap near the
// sensor. Assumed: 5 uT hard iron and 2 % soft iron typically.
constexpr double kHardIronTypicalUt = 5.0;
constexpr double kSoftIronTypical = 0.02;

Vec3d sensorFrame(const Quatd& qWorldSensor, const Vec3d& world) {
    return qWorldSensor.conjugate() * world;
}

}  // namespace

Quatd qEnuWorld() {
    Eigen::Matrix3d r;
    r << -1, 0, 0, 0, 0, 1, 0, 1, 0;
    return Quatd(r);
}

Vec3d Environment::earthFieldWorldUt() const {
    const double dip = dipDeg * kRadPerDeg;
    const double dec = declinationDeg * kRadPerDeg;
    const Vec3d enu(std::cos(dip) * std::sin(dec), std::cos(dip) * std::cos(dec), -std::sin(dip));
    return qEnuWorld().conjugate() * (enu * fieldUt);
}

Vec3d Environment::fieldWorldUt(const Vec3d& pointM) const {
    Vec3d b = earthFieldWorldUt();
    for (const MagneticDipole& d : dipoles) {
        Vec3d r = pointM - d.positionM;
        double dist = r.norm();
        if (dist < kMinDipoleDistanceM) {
            r = (dist > 0 ? Vec3d(r / dist) : Vec3d(Vec3d::UnitY())) * kMinDipoleDistanceM;
            dist = kMinDipoleDistanceM;
        }
        const Vec3d rHat = r / dist;
        b += kDipoleUt * (3 * rHat * rHat.dot(d.momentAm2) - d.momentAm2) / (dist * dist * dist);
    }
    return b;
}

ImuSignals idealSignals(const SegmentState& seg, const SensorPlacement& placement,
                        const Environment& env) {
    const Quatd qWorldSensor = seg.qWorldSegment * placement.mounting;
    const Vec3d& r = placement.leverArmM;
    // The mounting point moves with the segment: a = a0 + R (alpha x r + omega x (omega x r)),
    // with omega and alpha in the segment frame.
    const Vec3d relAccelSeg = seg.alphaRadS2.cross(r) + seg.omegaRadS.cross(seg.omegaRadS.cross(r));
    const Vec3d accelWorld = seg.accelerationMps2 + seg.qWorldSegment * relAccelSeg;
    const Vec3d gravityWorld(0, -env.gravityMps2, 0);
    const Vec3d pointWorld = seg.positionM + seg.qWorldSegment * r;

    ImuSignals s;
    s.gyroRadS = placement.mounting.conjugate() * seg.omegaRadS;
    s.accelMps2 = sensorFrame(qWorldSensor, accelWorld - gravityWorld);
    s.magUt = sensorFrame(qWorldSensor, env.fieldWorldUt(pointWorld));
    return s;
}

std::string_view toString(ErrorProfile p) {
    switch (p) {
        case ErrorProfile::Ideal:
            return "ideal";
        case ErrorProfile::Typical:
            return "typical";
        case ErrorProfile::Harsh:
            return "harsh";
    }
    return "?";
}

std::optional<ErrorProfile> parseErrorProfile(std::string_view name) {
    for (ErrorProfile p : {ErrorProfile::Ideal, ErrorProfile::Typical, ErrorProfile::Harsh}) {
        if (toString(p) == name) {
            return p;
        }
    }
    return std::nullopt;
}

Result<ImuErrorSpec> errorSpec(std::string_view chipName, ErrorProfile profile) {
    ImuErrorSpec typical;
    if (chipName == "icm20948") {
        typical = icm20948Typical();
    } else if (chipName == "lsm6dsox+lis3mdl") {
        typical = lsm6dsoxLis3mdlTypical();
    } else {
        return Error{EINVAL, fmt::format("no error figures for chip '{}' (known: icm20948, "
                                         "lsm6dsox+lis3mdl)",
                                         chipName)};
    }
    typical.hardIronUt = kHardIronTypicalUt;
    typical.softIron = kSoftIronTypical;
    switch (profile) {
        case ErrorProfile::Ideal:
            return ImuErrorSpec{};
        case ErrorProfile::Typical:
            return typical;
        case ErrorProfile::Harsh: {
            ImuErrorSpec h = typical;
            h.gyro = harsh(typical.gyro);
            h.accel = harsh(typical.accel);
            h.mag = harsh(typical.mag);
            h.hardIronUt = typical.hardIronUt * kHarshConstant;
            h.softIron = typical.softIron * kHarshConstant;
            h.worstCase = true;
            return h;
        }
    }
    return Error{EINVAL, "unknown error profile"};
}

Environment environmentFor(ErrorProfile profile, const Vec3d& areaCentreM) {
    Environment env;
    if (profile == ErrorProfile::Harsh) {
        // A steel cabinet beside the capture area at about hip height, and reinforcement under
        // the floor; areaCentreM is taken to be at pelvis height, about 1 m above the floor.
        env.dipoles.push_back({areaCentreM + Vec3d(1.0, -0.2, 0.0), Vec3d(0, 0, 20)});
        env.dipoles.push_back({areaCentreM + Vec3d(0.3, -1.5, 0.4), Vec3d(0, 30, 0)});
    }
    return env;
}

VirtualImu::VirtualImu(const SegmentTrajectory& trajectory, const Environment& env,
                       const SensorPlacement& placement, const ImuErrorSpec& spec,
                       std::uint64_t seed, double imuOdrHz, double magOdrHz)
    : trajectory_(trajectory), env_(env), placement_(placement), spec_(spec), seed_(seed) {
    auto sigma = [](const TriadErrors& t, double odrHz) {
        if (t.noiseRms > 0) {
            return t.noiseRms;
        }
        return odrHz > 0 ? t.noiseDensity * std::sqrt(odrHz / 2) : 0.0;
    };
    gyroSigma_ = sigma(spec.gyro, imuOdrHz);
    accelSigma_ = sigma(spec.accel, imuOdrHz);
    magSigma_ = sigma(spec.mag, magOdrHz);

    // A constant error: Gaussian with the figure as sigma, or the figure with a random sign.
    auto draw = [&](std::uint64_t stream, double figure) -> Vec3d {
        const Vec3d g = gaussian3(stream, 0);
        if (!spec.worstCase) {
            return g * figure;
        }
        return Vec3d(std::copysign(figure, g.x()), std::copysign(figure, g.y()),
                     std::copysign(figure, g.z()));
    };
    // (I + cross-axis) * diag(1 + scale): off-diagonal elements couple the axes.
    auto matrix = [&](const TriadErrors& t, std::uint64_t scale, std::uint64_t crossA,
                      std::uint64_t crossB) {
        const Vec3d s = draw(scale, t.scaleError);
        const Vec3d a = draw(crossA, t.crossAxis);
        const Vec3d b = draw(crossB, t.crossAxis);
        Eigen::Matrix3d c = Eigen::Matrix3d::Identity();
        c(0, 1) = a.x();
        c(0, 2) = a.y();
        c(1, 2) = a.z();
        c(1, 0) = b.x();
        c(2, 0) = b.y();
        c(2, 1) = b.z();
        return Eigen::Matrix3d(c * (Vec3d::Ones() + s).asDiagonal());
    };
    constants_.gyroMatrix = matrix(spec.gyro, kGyroScale, kGyroCrossA, kGyroCrossB);
    constants_.accelMatrix = matrix(spec.accel, kAccelScale, kAccelCrossA, kAccelCrossB);
    const Vec3d d = draw(kSoftIronDiag, spec.softIron);
    const Vec3d o = draw(kSoftIronOff, spec.softIron);
    Eigen::Matrix3d soft;
    soft << 1 + d.x(), o.x(), o.y(), o.x(), 1 + d.y(), o.z(), o.y(), o.z(), 1 + d.z();
    constants_.magMatrix = matrix(spec.mag, kMagScale, kMagCrossA, kMagCrossB) * soft;
    constants_.gyroBiasRadS = draw(kGyroBias, spec.gyro.turnOnBias);
    constants_.accelBiasMps2 = draw(kAccelBias, spec.accel.turnOnBias);
    constants_.magOffsetUt =
        draw(kMagOffset, spec.mag.turnOnBias) + draw(kHardIron, spec.hardIronUt);
}

Vec3d VirtualImu::gaussian3(std::uint64_t stream, std::int64_t tNs) const {
    const std::uint64_t h = mix(mix(mix(seed_) ^ stream) ^ static_cast<std::uint64_t>(tNs));
    Vec3d g;
    for (int a = 0; a < 3; ++a) {
        // Box-Muller: two uniforms make one standard normal.
        const auto ua = static_cast<std::uint64_t>(2 * a + 1);
        const double u1 = unit(mix(h ^ ua));
        const double u2 = unit(mix(h ^ (ua + 1)));
        g[a] = std::sqrt(-2 * std::log(u1)) * std::cos(2 * std::numbers::pi * u2);
    }
    return g;
}

void VirtualImu::advance(Walk& w, std::uint64_t stream, double rateU, std::int64_t tNs) const {
    if (!w.started) {
        w.started = true;
        w.lastNs = tNs;
        return;
    }
    if (tNs <= w.lastNs || rateU == 0) {
        w.lastNs = std::max(w.lastNs, tNs);
        return;
    }
    const double dtS = static_cast<double>(tNs - w.lastNs) * 1e-9;
    w.biasU += gaussian3(stream, tNs) * (rateU * std::sqrt(dtS));
    w.lastNs = tNs;
}

void VirtualImu::readGyroAccel(std::int64_t tNs, Vec3d& gyroRadS, Vec3d& accelMps2) {
    addGyroAccelErrors(ideal(tNs), tNs, gyroRadS, accelMps2);
}

void VirtualImu::readMag(std::int64_t tNs, Vec3d& magUt) {
    addMagErrors(ideal(tNs), tNs, magUt);
}

ImuSignals VirtualImu::read(std::int64_t tNs) {
    // One evaluation of the trajectory for all three (each stream's errors are its own).
    const ImuSignals truth = ideal(tNs);
    ImuSignals s;
    addGyroAccelErrors(truth, tNs, s.gyroRadS, s.accelMps2);
    addMagErrors(truth, tNs, s.magUt);
    return s;
}

void VirtualImu::addGyroAccelErrors(const ImuSignals& truth, std::int64_t tNs, Vec3d& gyroRadS,
                                    Vec3d& accelMps2) {
    advance(gyroWalk_, kGyroWalk, spec_.gyro.biasRandomWalk, tNs);
    advance(accelWalk_, kAccelWalk, spec_.accel.biasRandomWalk, tNs);
    gyroRadS = constants_.gyroMatrix * truth.gyroRadS + constants_.gyroBiasRadS + gyroWalk_.biasU;
    accelMps2 =
        constants_.accelMatrix * truth.accelMps2 + constants_.accelBiasMps2 + accelWalk_.biasU;
    if (gyroSigma_ > 0) {
        gyroRadS += gaussian3(kGyroNoise, tNs) * gyroSigma_;
    }
    if (accelSigma_ > 0) {
        accelMps2 += gaussian3(kAccelNoise, tNs) * accelSigma_;
    }
}

void VirtualImu::addMagErrors(const ImuSignals& truth, std::int64_t tNs, Vec3d& magUt) {
    advance(magWalk_, kMagWalk, spec_.mag.biasRandomWalk, tNs);
    magUt = constants_.magMatrix * truth.magUt + constants_.magOffsetUt + magWalk_.biasU;
    if (magSigma_ > 0) {
        magUt += gaussian3(kMagNoise, tNs) * magSigma_;
    }
}

ImuSignals VirtualImu::ideal(std::int64_t tNs) const {
    SegmentState st;
    trajectory_.evaluate(placement_.segment, tNs, st);
    return idealSignals(st, placement_, env_);
}

}  // namespace caphub::board::sim
