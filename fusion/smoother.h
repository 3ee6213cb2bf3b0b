// A non-causal orientation estimate over a whole recording (`caphub reprocess --smooth`,
// `caphub fusion replay --smooth`): the orientation filter (orientation_filter.h, used through
// its public interface only) run forward, then backward in time over the reversed samples
// (rates negated, the bias estimate negated: what the reversed motion looks like to the
// gyroscope), each run started from the other's converged state, and the two estimates combined
// per sample. The forward filter's error at a sample comes from the samples before it, the
// backward one's from those after: their halfway rotation (slerp 0.5) averages two nearly
// independent errors, and neither has a start-up transient (each begins where the other ended).
// By default only the inclination is averaged, the heading is the causal run's (below).
// A gyroscope that clips loses an unknown rotation, which the run that passed the clip carries
// until its corrections remove it (tens of seconds for a turn about up): around a clip each
// stretch is taken from the run that has not passed it yet (docs/reprocess.md).
#pragma once

#include <string_view>
#include <vector>

#include "fusion/orientation_filter.h"
#include "hal/core/quaternion.h"

namespace caphub::fusion {

// One sample of one sensor, calibrated, sensor frame.
struct SmootherSample {
    Vec3d gyrRadS = Vec3d::Zero();
    Vec3d accMps2 = Vec3d::Zero();
    Vec3d magUt = Vec3d::Zero();
    bool magFresh = false;    // feed the magnetometer (a new, not overflowed reading)
    bool gyrClipped = false;  // the driver flagged the gyroscope saturated
    // The sensor's known linear acceleration (ENU, m/s^2), as the causal filter is told it; zero:
    // unknown.
    Vec3d linAccEnu = Vec3d::Zero();
};

struct SmootherStats {
    double meanDisagreementDeg = 0;  // forward vs backward, over the samples
    double maxDisagreementDeg = 0;
};

struct SmootherOptions {
    // The backward run's share of the combination (0: the forward run alone, which still starts
    // converged: no start-up transient).
    double backwardWeight = 0.5;
    // Combine the inclinations only; the heading (the turn about up) is the causal run's (the
    // first forward run, from power-on, as live). Combining the headings too removes the heading
    // gain's lag (the two runs lag in opposite directions) and follows the field without it:
    // better where the field is the same everywhere, worse on BROAD, whose field during the
    // motion is a few degrees off its rest direction (docs/reprocess.md).
    bool forwardHeading = true;
    // Between two rests (the filter's rest detector, each at least minAnchorRestS long and at
    // most maxBridgeS apart), the heading from the gyroscope alone: integrated forward from the
    // first rest and backward from the second, each with the bias measured at its rest (the
    // mean rate there, interpolated between them), combined with weights falling linearly with
    // the time from each (the variance of integrated rate noise grows linearly), each rest's
    // heading the field's mean over it. The field a sensor reads as it moves is not the one it
    // reads at rest (a room's field varies from place to place: BROAD's during the motion lies
    // 2-6 deg off its rest direction, docs/reprocess.md); still, the field is averaged over
    // seconds in one place. Elsewhere (a take without two rests) the heading is as above.
    bool restAnchoredHeading = false;
    double minAnchorRestS = 2.0;
    double maxBridgeS = 300.0;
    // Each run's steady-state error variance (rad^2): where the runs disagree after a clip, the
    // disagreement beyond this is laid on the run that passed the clip.
    double steadyVarRad2 = 3.0e-4;
};

// The heading choice by its name on the command line ("causal": forwardHeading, "both": the
// two runs' headings combined like the inclinations, "rest": the causal heading bridged by the
// gyroscope between rests, restAnchoredHeading); false for any other name.
bool setSmoothHeading(SmootherOptions& o, std::string_view name);

// One orientation (sensor -> ENU) per sample, from the filter with `params` (its rates: the
// samples' rate). Empty in, empty out.
std::vector<Quatd> smoothOrientations(const std::vector<SmootherSample>& samples,
                                      const FilterParams& params,
                                      const SmootherOptions& options = {},
                                      SmootherStats* stats = nullptr);

}  // namespace caphub::fusion
