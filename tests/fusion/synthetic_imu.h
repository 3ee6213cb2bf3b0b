// Synthetic 9-axis recordings with an exactly known orientation, for the fusion tests: the
// orientation follows a body-rate profile, the sensors read it with chosen bias and noise.
#pragma once

#include <cmath>
#include <functional>
#include <random>
#include <vector>

#include "fusion/evaluation.h"

namespace caphub::fusion::test {

struct SynthConfig {
    double rateHz = 100.0;
    double gravityMps2 = 9.81;
    Vec3d magEarthUt{0.0, 19.0, -45.0};  // ENU: north and down, about Berlin's field
    Vec3d gyrBiasRadS = Vec3d::Zero();
    double gyrNoiseRadS = 0.003;  // per-sample standard deviations
    double accNoiseMps2 = 0.03;
    double magNoiseUt = 0.3;
    unsigned seed = 1;
    // Extra field in the earth frame at time t (a magnet near the sensor), uT.
    std::function<Vec3d(double)> magDisturbanceEarthUt;
    // Linear acceleration of the sensor in the earth frame at time t, m/s^2.
    std::function<Vec3d(double)> linearAccEarth;
};

struct SynthRun {
    std::vector<ImuSample> samples;
    std::vector<Quatd> truth;  // sensor -> earth
};

// The orientation starts at q0 and turns at omegaBody(t) (rad/s, sensor frame), held constant
// over each sample period, so the gyroscope's noiseless reading is exact.
inline SynthRun synthesize(const SynthConfig& c, const Quatd& q0, double durationS,
                           const std::function<Vec3d(double)>& omegaBody) {
    std::mt19937 rng(c.seed);
    std::normal_distribution<double> n01(0.0, 1.0);
    auto noise = [&](double s) -> Vec3d { return Vec3d(n01(rng), n01(rng), n01(rng)) * s; };
    SynthRun run;
    const double dt = 1.0 / c.rateHz;
    const int count = static_cast<int>(durationS * c.rateHz);
    Quatd q = q0.normalized();
    for (int k = 0; k < count; ++k) {
        const double t = k * dt;
        const Vec3d w = omegaBody(t);
        q = integrateBodyRate(q, w, dt);
        ImuSample s;
        s.tS = t;
        s.gyrRadS = w + c.gyrBiasRadS + noise(c.gyrNoiseRadS);
        const Eigen::Matrix3d rT = q.toRotationMatrix().transpose();
        Vec3d specificForce(0.0, 0.0, c.gravityMps2);
        if (c.linearAccEarth) {
            specificForce += c.linearAccEarth(t);
        }
        s.accMps2 = rT * specificForce + noise(c.accNoiseMps2);
        Vec3d mE = c.magEarthUt;
        if (c.magDisturbanceEarthUt) {
            mE += c.magDisturbanceEarthUt(t);
        }
        s.magUt = rT * mE + noise(c.magNoiseUt);
        run.samples.push_back(s);
        run.truth.push_back(q);
    }
    return run;
}

// A hand-held-like motion: three incommensurate sinusoids, peak rate about `peak` rad/s.
inline std::function<Vec3d(double)> wobble(double peak) {
    return [peak](double t) -> Vec3d {
        return Vec3d(std::sin(0.9 * t), std::sin(1.3 * t + 1.0), std::sin(0.7 * t + 2.0)) *
               (peak / std::sqrt(3.0));
    };
}

inline double headingDeg(const Quatd& a, const Quatd& b) {
    return broadSampleErrors(a, b).headingRad * 57.29577951308232;
}
inline double inclinationDeg(const Quatd& a, const Quatd& b) {
    return broadSampleErrors(a, b).inclinationRad * 57.29577951308232;
}

}  // namespace caphub::fusion::test
