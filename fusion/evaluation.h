// Running the orientation filter over recorded samples and scoring it with the BROAD metric
// (Laidig et al. 2021): the same code serves `caphub fusion replay` and the regression tests.
#pragma once

#include <cstddef>
#include <vector>

#include "fusion/orientation_filter.h"
#include "hal/core/quaternion.h"

namespace caphub::fusion {

// One 9-axis sample in SI units, sensor frame.
struct ImuSample {
    double tS = 0.0;
    Vec3d gyrRadS = Vec3d::Zero();
    Vec3d accMps2 = Vec3d::Zero();
    Vec3d magUt = Vec3d::Zero();
};

enum class FilterVariant { Float, Fixed };

// Runs a filter over samples recorded at rateHz, feeding every `decimation`-th sample (1 = all)
// at rateHz / decimation; the estimate is held for the rows in between. One quaternion (sensor ->
// earth, ENU) per input sample. `params` rates are overwritten with the fed rate. `rejections`,
// when given, receives what the filter refused (docs/fusion.md, "Input validation").
std::vector<Quatd> runFilter(const std::vector<ImuSample>& samples, double rateHz, int decimation,
                             FilterVariant variant, FilterParams params = {},
                             FilterRejections* rejections = nullptr);

// RMSE (deg) of the three BROAD errors over the movement samples with finite ground truth.
struct BroadErrors {
    double totalDeg = 0.0;
    double headingDeg = 0.0;
    double inclinationDeg = 0.0;
    std::size_t samples = 0;  // movement samples that counted
};

// The per-sample errors (rad) of an estimate against ground truth, both sensor -> earth:
// q_err = q_est * inverse(q_opt); total = 2 acos|w|, heading = 2 atan|z / w|,
// inclination = 2 acos sqrt(w^2 + z^2).
struct SampleErrors {
    double totalRad = 0.0;
    double headingRad = 0.0;
    double inclinationRad = 0.0;
};
SampleErrors broadSampleErrors(const Quatd& est, const Quatd& opt);

// Scores a run. `truth` holds w-x-y-z quaternions with NaN where the markers were not seen;
// movement flags which samples count. Sizes must match (checked by the caller).
BroadErrors broadMetric(const std::vector<Quatd>& estimate, const std::vector<Quatd>& truth,
                        const std::vector<bool>& movement);

}  // namespace caphub::fusion
