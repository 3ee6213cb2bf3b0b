// Honest tuning figures: a small search space of the filter's tunable parameters and the
// leave-one-out choice over trials (docs/fusion.md, "Leave-one-out tuning"). The scoring runs
// elsewhere (`caphub fusion cv`); this is the selection, so that it can be tested alone.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "fusion/orientation_filter.h"

namespace caphub::fusion {

struct TuningCandidate {
    std::string label;  // "tauAccS=1.8 accLpDamping=0.5 headingNoiseDegRtHz=9.5"
    FilterParams params;
};

// The search space: the defaults' gravity low-pass delay and damping and the heading noise
// density, each at the default and a step either side (factors of about 1.4 and 2): 27 sets.
// The default set is the first.
std::vector<TuningCandidate> tuningSearchSpace();

// scores[c][t]: the objective (lower is better) of candidate c on trial t. For each trial t,
// the candidate with the lowest mean over all trials but t (ties: the lower index). Empty
// scores, or fewer than two trials, give an empty result.
std::vector<std::size_t> leaveOneOutChoice(const std::vector<std::vector<double>>& scores);

// The candidate with the lowest mean over all trials (the in-sample choice).
std::size_t inSampleChoice(const std::vector<std::vector<double>>& scores);

}  // namespace caphub::fusion
