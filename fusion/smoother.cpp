#include "fusion/smoother.h"

#include <algorithm>
#include <cmath>

namespace caphub::fusion {

namespace {

using Filter = OrientationFilter<FloatTypes>;

Vec3<float> toF(const Vec3d& v) {
    return {static_cast<float>(v.x()), static_cast<float>(v.y()), static_cast<float>(v.z())};
}

Vec3<float> negated(const Vec3<float>& v) {
    return {-v.x, -v.y, -v.z};
}

Quatd quatOf(const Filter& f) {
    const auto q = f.quat();
    return Quatd(q.w, q.x, q.y, q.z).normalized();
}

// One sample into the filter, as FusionStage feeds it; `reversed`: time runs backward, so the
// rotation rate is negated (the accelerometer's and magnetometer's readings are what they are).
void feed(Filter& f, const SmootherSample& s, bool reversed) {
    const Vec3<float> gyr = toF(s.gyrRadS);
    f.updateGyr(reversed ? negated(gyr) : gyr, s.gyrClipped);
    f.updateAcc(toF(s.accMps2), toF(s.linAccEnu));
    if (s.magFresh) {
        f.updateMag(toF(s.magUt));
    }
}

// The filter's state as the filter running the other way in time sees it: the same attitude and
// filtered gravity; the rates (bias, the last rate, the gravity low-pass's rate) negated.
FilterState<FloatTypes> turnedAround(const FilterState<FloatTypes>& s) {
    FilterState<FloatTypes> out = s;
    out.bias = negated(s.bias);
    out.lastGyr = negated(s.lastGyr);
    out.accBand = negated(s.accBand);
    out.rest.gyrLp = negated(s.rest.gyrLp);  // the rest detector's low-passed rate
    return out;
}

}  // namespace

std::vector<Quatd> smoothOrientations(const std::vector<SmootherSample>& samples,
                                      const FilterParams& params, const SmootherOptions& options,
                                      SmootherStats* stats) {
    const std::size_t n = samples.size();
    std::vector<Quatd> out(n, Quatd::Identity());
    if (n == 0) {
        return out;
    }
    // 1. Forward from power-on, as the capture ran it: only to reach a converged state (the
    // attitude and the gyroscope bias) at the end of the take.
    Filter f(params);
    std::vector<Quatd> causal(n);
    for (std::size_t k = 0; k < n; ++k) {
        feed(f, samples[k], false);
        causal[k] = quatOf(f);
    }
    // 2. Backward from there. Before sample i is fed (reversed), the filter has integrated the
    // rates of samples n-1 .. i+1: it holds the attitude at sample i.
    Filter b(params);
    b.setState(turnedAround(f.state()));
    std::vector<Quatd> backward(n);
    for (std::size_t k = n; k-- > 0;) {
        backward[k] = quatOf(b);
        feed(b, samples[k], true);
    }
    // 3. Forward again from the backward run's state at the start (converged there), and the
    // combination: halfway between the two at each sample.
    Filter g(params);
    g.setState(turnedAround(b.state()));
    double sumDeg = 0;
    double maxDeg = 0;
    for (std::size_t k = 0; k < n; ++k) {
        feed(g, samples[k], false);
        const Quatd fw = quatOf(g);
        Quatd bw = backward[k];
        if (fw.dot(bw) < 0) {
            bw.coeffs() = -bw.coeffs();
        }
        out[k] = fw.slerp(options.backwardWeight, bw).normalized();
        if (options.forwardHeading) {
            // The heading (the turn about up) of the causal run, the inclination of both.
            const Quatd d = causal[k] * out[k].conjugate();
            Quatd twist(d.w(), 0, 0, d.z());
            if (twist.norm() > 1e-9) {
                twist.normalize();
                out[k] = (twist * out[k]).normalized();
            }
        }
        const double deg = fw.angularDistance(bw) * 180.0 / 3.14159265358979323846;
        sumDeg += deg;
        maxDeg = std::max(maxDeg, deg);
    }
    if (stats != nullptr) {
        stats->meanDisagreementDeg = sumDeg / static_cast<double>(n);
        stats->maxDisagreementDeg = maxDeg;
    }
    return out;
}

}  // namespace caphub::fusion
