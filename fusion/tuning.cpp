#include "fusion/tuning.h"

#include <fmt/format.h>

namespace caphub::fusion {

std::vector<TuningCandidate> tuningSearchSpace() {
    const FilterParams base;
    const double taus[] = {base.tauAccS, 1.3, 2.5};
    const double dampings[] = {base.accLpDamping, 0.35, 0.707};
    const double headings[] = {base.headingNoiseDegRtHz, 5.0, 18.0};
    std::vector<TuningCandidate> out;
    for (double tau : taus) {
        for (double zeta : dampings) {
            for (double head : headings) {
                TuningCandidate c;
                c.params = base;
                c.params.tauAccS = tau;
                c.params.accLpDamping = zeta;
                c.params.headingNoiseDegRtHz = head;
                c.label = fmt::format("tauAccS={:g} accLpDamping={:g} headingNoiseDegRtHz={:g}",
                                      tau, zeta, head);
                out.push_back(c);
            }
        }
    }
    return out;
}

namespace {

// The candidate with the lowest sum over the trials, leaving out `skip` (none: npos).
std::size_t best(const std::vector<std::vector<double>>& scores, std::size_t skip) {
    std::size_t bestIndex = 0;
    double bestSum = 0.0;
    for (std::size_t c = 0; c < scores.size(); ++c) {
        double sum = 0.0;
        for (std::size_t t = 0; t < scores[c].size(); ++t) {
            if (t != skip) {
                sum += scores[c][t];
            }
        }
        if (c == 0 || sum < bestSum) {
            bestSum = sum;
            bestIndex = c;
        }
    }
    return bestIndex;
}

}  // namespace

std::vector<std::size_t> leaveOneOutChoice(const std::vector<std::vector<double>>& scores) {
    if (scores.empty() || scores.front().size() < 2) {
        return {};
    }
    std::vector<std::size_t> out;
    for (std::size_t t = 0; t < scores.front().size(); ++t) {
        out.push_back(best(scores, t));
    }
    return out;
}

std::size_t inSampleChoice(const std::vector<std::vector<double>>& scores) {
    return scores.empty() ? 0 : best(scores, static_cast<std::size_t>(-1));
}

}  // namespace caphub::fusion
