#include "fusion/smoother.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <optional>

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

// How much of a clip a run still carries (rad^2, a prior: only the ratio between two runs is
// used). A clipped sample lost an unknown rotation; the run carries its turn about up until the
// field correction removes it, at the heading gain, and its tilt as long, through the gyroscope
// bias the lost turn teaches it (the gravity correction alone would remove a tilt in seconds:
// measured on synthetic clips, the tilt stays 1-2 deg for as long as the heading is wrong).
struct Excess {
    double incl = 0;
    double head = 0;
};

// The prior of a run that has just passed a clipped episode (only the ratio of two runs' priors
// is used), and the disagreement of two runs turned upside down from each other.
constexpr Excess kUnknownExcess{1.0, 1.0};

class ExcessDecay {
public:
    explicit ExcessDecay(const Filter& f)
        : perFieldSample_(std::pow(1.0 - static_cast<double>(f.coefficients().kHead), 2.0)) {}
    // One sample's corrections: at each magnetometer sample the filter trusted.
    void apply(Excess& e, bool magUsed) const {
        if (magUsed) {
            e.incl *= perFieldSample_;
            e.head *= perFieldSample_;
        }
    }

private:
    double perFieldSample_;
};

// The error `measured` makes against `reference`, split into its turn about up and its tilt,
// squared.
Excess excessOf(const Quatd& measured, const Quatd& reference) {
    Quatd d = measured * reference.conjugate();
    if (d.w() < 0) {
        d.coeffs() = -d.coeffs();
    }
    const double twistNorm = std::hypot(d.w(), d.z());
    if (twistNorm < 1e-9) {
        return kUnknownExcess;  // turned upside down
    }
    const Quatd twist(d.w() / twistNorm, 0, 0, d.z() / twistNorm);
    const double head = 2.0 * std::atan2(twist.z(), twist.w());
    const double tilt = (twist.conjugate() * d).normalized().angularDistance(Quatd::Identity());
    return {tilt * tilt, head * head};
}

// Angle (rad) of the turn about up that takes `from` to the heading of `to`.
double headingTurn(const Quatd& to, const Quatd& from) {
    const Quatd d = to * from.conjugate();
    return std::hypot(d.w(), d.z()) < 1e-9 ? 0.0 : 2.0 * std::atan2(d.z(), d.w());
}

// The turn by `angle` (rad) about up.
Quatd aboutUp(double angle) {
    return {std::cos(0.5 * angle), 0, 0, std::sin(0.5 * angle)};
}

double wrapPi(double a) {
    return std::remainder(a, 2.0 * std::numbers::pi);
}

bool lastOfEpisode(const std::vector<SmootherSample>& s, std::size_t k) {
    return s[k].gyrClipped && (k + 1 == s.size() || !s[k + 1].gyrClipped);
}

// What each clipped episode lost, on each of its samples (zero elsewhere): the causal run's
// disagreement, at the episode's last sample, with a run from the other side that has not
// passed the episode yet (backward from the causal run's state at the end). The same rotation
// is lost going either way. A full scale barely reached loses next to nothing; a hand spun at
// twice the full scale, tens of degrees.
std::vector<Excess> episodeLosses(const std::vector<SmootherSample>& samples,
                                  const std::vector<Quatd>& causal,
                                  const FilterState<FloatTypes>& end, const FilterParams& params) {
    const std::size_t n = samples.size();
    std::vector<Excess> loss(n);
    if (std::none_of(samples.begin(), samples.end(),
                     [](const SmootherSample& s) { return s.gyrClipped; })) {
        return loss;
    }
    Filter b(params);
    b.setState(turnedAround(end));
    Excess current;
    for (std::size_t k = n; k-- > 0;) {
        if (lastOfEpisode(samples, k)) {
            // Before sample k is fed the backward run holds the attitude at sample k.
            const Excess e = excessOf(causal[k], quatOf(b));
            current = {std::min(e.incl, 1.0), std::min(e.head, 1.0)};
        }
        if (samples[k].gyrClipped) {
            loss[k] = current;
        }
        feed(b, samples[k], true);
    }
    return loss;
}

// Whether a clip's excess, decayed by the causal run's corrections, is still above the steady
// state at the end of the take.
bool clipCarriedToTheEnd(const std::vector<SmootherSample>& samples,
                         const std::vector<Excess>& loss, const std::vector<char>& magUsed,
                         const ExcessDecay& decay, double steadyVarRad2) {
    Excess e;
    for (std::size_t k = 0; k < samples.size(); ++k) {
        decay.apply(e, magUsed[k] != 0);
        if (samples[k].gyrClipped) {
            e = loss[k];
        }
    }
    return std::max(e.incl, e.head) > steadyVarRad2;
}

// A state whose attitude starts again from the next accelerometer and magnetometer samples,
// as at power-on; the gyroscope bias, the rest detector and the field reference are kept.
FilterState<FloatTypes> realigned(FilterState<FloatTypes> s, const Vec3<float>& bias) {
    s.bias = bias;
    s.qGyr = Quat<float>::identity();
    s.qCorr = Quat<float>::identity();
    s.inclinationInit = false;
    s.headingInit = false;
    return s;
}

// A backward run's state at the end of the take that owes nothing to the causal run's attitude
// (only its rest detector and field reference; `bias` is the backward run's): aligned on the last
// sample, run backward over the stretch after the last clip and forward again, its heading
// aligned anew at the stretch's start, so that one sample of a moving limb (its acceleration
// taken for gravity, the field's heading turned by that tilt) does not set its attitude.
FilterState<FloatTypes> realignedAtTheEnd(const std::vector<SmootherSample>& samples,
                                          const FilterState<FloatTypes>& causalEnd,
                                          const Vec3<float>& bias, const FilterParams& params) {
    const std::size_t n = samples.size();
    Filter w(params);
    w.setState(realigned(turnedAround(causalEnd), bias));
    std::size_t firstClean = n;
    while (firstClean > 0 && !samples[firstClean - 1].gyrClipped) {
        --firstClean;
    }
    for (std::size_t k = n; k-- > firstClean;) {
        feed(w, samples[k], true);
    }
    FilterState<FloatTypes> there = turnedAround(w.state());
    there.headingInit = false;
    w.setState(there);
    for (std::size_t k = firstClean; k < n; ++k) {
        feed(w, samples[k], false);
    }
    return turnedAround(w.state());
}

// What an attitude aligned on one sample errs by: its tilt from one accelerometer sample in
// motion (a few degrees), its heading from one field sample (about one).
constexpr Excess kRealignedExcess{0.003, 0.0003};

// The part of a disagreement `d` between two runs that falls on the one whose clip excess
// (decayed since the clip) is `mine`, against the other's `theirs`: none where neither clipped.
double share(double d, double mine, double theirs) {
    const double both = mine + theirs;
    return both > 1e-30 ? d * mine / both : 0.0;
}

// A stretch of consecutive samples the causal run called at rest: [first, last].
struct RestStretch {
    std::size_t first = 0;
    std::size_t last = 0;
    Vec3d meanRate = Vec3d::Zero();  // the gyroscope's mean reading there: its bias
};

std::vector<RestStretch> restStretches(const std::vector<SmootherSample>& samples,
                                       const std::vector<char>& atRest, std::size_t minSamples) {
    std::vector<RestStretch> out;
    std::size_t k = 0;
    while (k < samples.size()) {
        if (atRest[k] == 0) {
            ++k;
            continue;
        }
        RestStretch r;
        r.first = k;
        Vec3d sum = Vec3d::Zero();
        while (k < samples.size() && atRest[k] != 0) {
            sum += samples[k].gyrRadS;
            ++k;
        }
        r.last = k - 1;
        const std::size_t count = r.last - r.first + 1;
        if (count >= minSamples) {
            r.meanRate = sum / static_cast<double>(count);
            out.push_back(r);
        }
    }
    return out;
}

// The field over a rest, in the sensor's frame at each of its samples (empty: none). The
// samples whose field the causal run trusted are carried into the frame of the rest's first
// sample by the rates (less the rest's mean, the bias) and averaged there: a rest is a sensor
// turning slower than the rest detector's 2 deg/s, not one held by a vice, and the estimate's
// own heading may still be moving there (the causal run converging), so neither the raw readings
// nor the estimate's frame hold the field still.
std::vector<Vec3d> restField(const std::vector<SmootherSample>& samples,
                             const std::vector<char>& magUsed, const RestStretch& r, double dt) {
    const std::size_t n = r.last - r.first + 1;
    std::vector<Quatd> fromFirst(n, Quatd::Identity());  // sensor at sample -> at the first
    Vec3d sum = Vec3d::Zero();
    for (std::size_t j = 0; j < n; ++j) {
        const SmootherSample& s = samples[r.first + j];
        if (j > 0) {
            fromFirst[j] = integrateBodyRate(fromFirst[j - 1], Vec3d(s.gyrRadS - r.meanRate), dt);
        }
        if (s.magFresh && magUsed[r.first + j] != 0 && s.magUt.norm() > 0) {
            sum += fromFirst[j] * s.magUt.normalized();
        }
    }
    if (sum.norm() < 1e-9) {
        return {};
    }
    const Vec3d mean = sum.normalized();
    std::vector<Vec3d> out(n);
    for (std::size_t j = 0; j < n; ++j) {
        out[j] = fromFirst[j].conjugate() * mean;
    }
    return out;
}

// restAnchoredHeading (SmootherOptions): the heading of `out` between consecutive rests from
// the gyroscope, anchored at each rest on the mean field there.
void bridgeHeadingsBetweenRests(const std::vector<SmootherSample>& samples,
                                const std::vector<char>& atRest, const std::vector<char>& magUsed,
                                const FilterParams& params, const SmootherOptions& options,
                                std::vector<Quatd>& out) {
    const double dt = 1.0 / params.gyrRateHz;
    const auto minSamples =
        static_cast<std::size_t>(std::max(1.0, std::ceil(options.minAnchorRestS / dt)));
    const std::vector<RestStretch> rests = restStretches(samples, atRest, minSamples);
    // The bridges: consecutive rests close enough in time, with every rate between them one
    // the gyroscope measured (not clipped, within the filter's input limit: a glitch the
    // filter rejects would turn the integration by whatever it holds).
    const double limitRadS = params.gyrLimitDps * hal::kDegToRad;
    const auto measured = [&](std::size_t from, std::size_t to) {
        for (std::size_t k = from; k <= to; ++k) {
            const SmootherSample& s = samples[k];
            if (s.gyrClipped || !s.gyrRadS.allFinite() ||
                s.gyrRadS.cwiseAbs().maxCoeff() > limitRadS) {
                return false;
            }
        }
        return true;
    };
    std::vector<char> bridged(rests.size(), 0);  // bridged[i]: rests i and i+1
    std::vector<char> anchors(rests.size(), 0);
    for (std::size_t i = 0; i + 1 < rests.size(); ++i) {
        if (static_cast<double>(rests[i + 1].first - rests[i].last) * dt <= options.maxBridgeS &&
            measured(rests[i].first, rests[i + 1].last)) {
            bridged[i] = 1;
            anchors[i] = anchors[i + 1] = 1;
        }
    }
    // Each anchor's heading: the field's there.
    std::vector<Quatd> anchored = out;
    for (std::size_t i = 0; i < rests.size(); ++i) {
        const RestStretch& r = rests[i];
        if (anchors[i] == 0) {
            continue;
        }
        // Each sample of the rest turned so that the rest's field points north in it (the
        // filter's heading correction): the estimate's own heading may still move there.
        const std::vector<Vec3d> field = restField(samples, magUsed, r, dt);
        for (std::size_t j = 0; j < field.size(); ++j) {
            const std::size_t k = r.first + j;
            const Vec3d h = out[k] * field[j];
            if (std::hypot(h.x(), h.y()) > 1e-9) {
                anchored[k] = (aboutUp(std::atan2(h.x(), h.y())) * out[k]).normalized();
            }
        }
    }
    for (std::size_t i = 0; i + 1 < rests.size(); ++i) {
        if (bridged[i] == 0) {
            continue;
        }
        const RestStretch& a = rests[i];
        const RestStretch& b = rests[i + 1];
        const std::size_t span = b.first - a.last;  // samples from one anchor to the other
        // The rate of sample a.last + j less the bias, interpolated between the rests' means.
        const auto rate = [&](std::size_t j) -> Vec3d {
            const double frac = static_cast<double>(j) / static_cast<double>(span);
            return samples[a.last + j].gyrRadS - ((1.0 - frac) * a.meanRate + frac * b.meanRate);
        };
        // Forward: the attitude at sample k from the anchor at a.last and the rates of samples
        // a.last+1 .. k (each rate the turn over the period that ends at its sample).
        std::vector<Quatd> forward(span + 1);
        forward[0] = anchored[a.last];
        for (std::size_t j = 1; j <= span; ++j) {
            forward[j] = integrateBodyRate(forward[j - 1], rate(j), dt);
        }
        // Backward from the anchor at b.first, undoing the same rates.
        Quatd backward = anchored[b.first];
        for (std::size_t j = span; j-- > 1;) {
            backward = integrateBodyRate(backward, Vec3d(-rate(j + 1)), dt);
            const std::size_t k = a.last + j;
            const double frac = static_cast<double>(j) / static_cast<double>(span);
            const double turnF = headingTurn(forward[j], out[k]);
            const double turnB = wrapPi(headingTurn(backward, out[k]) - turnF);
            out[k] = (aboutUp(turnF + frac * turnB) * out[k]).normalized();
        }
    }
    for (std::size_t i = 0; i < rests.size(); ++i) {
        if (anchors[i] != 0) {
            for (std::size_t k = rests[i].first; k <= rests[i].last; ++k) {
                out[k] = anchored[k];
            }
        }
    }
}

}  // namespace

bool setSmoothHeading(SmootherOptions& o, std::string_view name) {
    if (name != "causal" && name != "both" && name != "rest") {
        return false;
    }
    o.forwardHeading = name != "both";
    o.restAnchoredHeading = name == "rest";
    return true;
}

std::vector<Quatd> smoothOrientations(const std::vector<SmootherSample>& samples,
                                      const FilterParams& params, const SmootherOptions& options,
                                      SmootherStats* stats) {
    const std::size_t n = samples.size();
    std::vector<Quatd> out(n, Quatd::Identity());
    if (n == 0) {
        return out;
    }
    // 1. Forward from power-on, as the capture ran it: its heading, and a converged state (the
    // attitude and the gyroscope bias) at the end of the take.
    Filter f(params);
    const ExcessDecay decay(f);
    std::vector<Quatd> causal(n);
    std::vector<char> causalMag(n);
    std::vector<char> causalRest(n);
    // The bias before the first clip: what follows a clip can teach the bias the lost rotation.
    std::optional<Vec3<float>> preClipBias;
    for (std::size_t k = 0; k < n; ++k) {
        if (samples[k].gyrClipped && !preClipBias) {
            preClipBias = f.state().bias;
        }
        feed(f, samples[k], false);
        causal[k] = quatOf(f);
        causalMag[k] = f.state().magUsed ? 1 : 0;
        causalRest[k] = f.atRest() ? 1 : 0;
    }
    const std::vector<Excess> loss = episodeLosses(samples, causal, f.state(), params);
    // 2. Backward from there. Before sample i is fed (reversed), the filter has integrated the
    // rates of samples n-1 .. i+1: it holds the attitude at sample i.
    Filter b(params);
    Excess eb;
    if (clipCarriedToTheEnd(samples, loss, causalMag, decay, options.steadyVarRad2)) {
        // The causal run's attitude at the end still carries a clip's lost rotation: the
        // backward run aligns afresh there instead, with the bias from before the first clip.
        b.setState(realignedAtTheEnd(samples, f.state(),
                                     negated(preClipBias.value_or(f.state().bias)), params));
        eb = kRealignedExcess;
    } else {
        b.setState(turnedAround(f.state()));
    }
    std::vector<Quatd> backward(n);
    std::vector<Excess> bwExcess(n);
    Excess bwLost;  // what the clips the backward run passed lost, decayed as eb
    for (std::size_t k = n; k-- > 0;) {
        backward[k] = quatOf(b);
        bwExcess[k] = eb;
        feed(b, samples[k], true);
        decay.apply(eb, b.state().magUsed);
        decay.apply(bwLost, b.state().magUsed);
        if (samples[k].gyrClipped) {
            eb = kUnknownExcess;
            bwLost = loss[k];
        }
    }
    std::vector<Excess> fwExcess(n);
    Excess ef;
    for (std::size_t k = 0; k < n; ++k) {
        decay.apply(ef, causalMag[k] != 0);
        if (samples[k].gyrClipped) {
            ef = kUnknownExcess;
        }
        fwExcess[k] = ef;
    }
    // 3. Forward again from the backward run's state at the start (converged there), and the
    // combination: each run weighted by its error variance, alike (backwardWeight) where neither
    // clipped. Where the backward run reaches the start with a clip's excess, the forward run is
    // the causal one instead (from power-on, as live: it had not passed the clip).
    Filter g(params);
    Excess eg = bwExcess.front();
    const bool forwardIsCausal = std::max(bwLost.incl, bwLost.head) > options.steadyVarRad2;
    if (!forwardIsCausal) {
        g.setState(turnedAround(b.state()));
    }
    double sumDeg = 0;
    double maxDeg = 0;
    for (std::size_t k = 0; k < n; ++k) {
        if (forwardIsCausal) {
            eg = fwExcess[k];
        } else {
            feed(g, samples[k], false);
            decay.apply(eg, g.state().magUsed);
            if (samples[k].gyrClipped) {
                eg = kUnknownExcess;
            }
        }
        const Quatd fwRun = forwardIsCausal ? causal[k] : quatOf(g);
        Quatd fw = fwRun;
        Quatd bw = backward[k];
        // The inclinations are averaged with the headings made alike first: between two
        // orientations whose headings differ (a run that lost a turn in a clip), the halfway
        // rotation would tilt the axis of the tilt as well.
        fw = (aboutUp(headingTurn(bw, fw)) * fw).normalized();
        if (fw.dot(bw) < 0) {
            bw.coeffs() = -bw.coeffs();
        }
        // Each run's variance: its steady state, and the part of the two runs' disagreement
        // that falls on it (all of it on the one that passed a clip more recently).
        const double steady = options.steadyVarRad2;
        const double w = options.backwardWeight;
        const double tilt2 = excessOf(fw, bw).incl;
        const double vf = steady * w + share(tilt2, eg.incl, bwExcess[k].incl);
        const double vb = steady * (1.0 - w) + share(tilt2, bwExcess[k].incl, eg.incl);
        out[k] = fw.slerp(vf / (vf + vb), bw).normalized();
        // The heading: the causal run's (forwardHeading: its steady-state share is all of it)
        // or the forward run's, turned toward the backward run's by the same rule.
        const Quatd& headingRun = options.forwardHeading ? causal[k] : fwRun;
        const double headingPrior = options.forwardHeading ? fwExcess[k].head : eg.head;
        const double toRun = headingTurn(headingRun, out[k]);
        const double apart = wrapPi(headingTurn(bw, out[k]) - toRun);
        const double hr = (options.forwardHeading ? 0.0 : steady * w) +
                          share(apart * apart, headingPrior, bwExcess[k].head);
        const double hb = steady * (options.forwardHeading ? 1.0 : 1.0 - w) +
                          share(apart * apart, bwExcess[k].head, headingPrior);
        out[k] = (aboutUp(toRun + hr / (hr + hb) * apart) * out[k]).normalized();
        const double deg = fwRun.angularDistance(backward[k]) * 180.0 / std::numbers::pi;
        sumDeg += deg;
        maxDeg = std::max(maxDeg, deg);
    }
    if (options.restAnchoredHeading) {
        bridgeHeadingsBetweenRests(samples, causalRest, causalMag, params, options, out);
    }
    if (stats != nullptr) {
        stats->meanDisagreementDeg = sumDeg / static_cast<double>(n);
        stats->maxDisagreementDeg = maxDeg;
    }
    return out;
}

}  // namespace caphub::fusion
