// Online hard-iron estimation for one magnetometer while the suit moves: no calibration session,
// no I/O. The readings of a sensor that turns lie on a sphere about the offset (hard iron plus
// the chip's zero-field offset) whose radius is the earth's field: |m - h|^2 = B^2, which is
// linear in h and c = B^2 - |h|^2 (|m|^2 = 2 m.h + c). The estimator keeps only the sums of that
// least-squares fit, with exponential forgetting (OnlineHardIronState, 19 numbers), and solves
// it in closed form when asked. The fit does not depend on the filter's heading, so the sums of
// one run carry over to the next (docs/fusion.md, "No magnetometer calibration").
// Observability needs turns: only the part of h across the directions the field has taken in the
// sensor frame can be told; `spread` measures it.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

#include <Eigen/Core>

#include "fusion/evaluation.h"

namespace caphub::fusion {

struct OnlineHardIronParams {
    double memoryS = 300.0;       // s, time constant of the forgetting (of the sample weights)
    double minSpread = 0.005;     // 0..1, smallest spread of the field directions for trust
    double maxResidualPct = 4.0;  // RMS distance from the sphere, % of B, above: not trusted
    double minFieldUt = 20.0;     // plausible magnitude of the earth's field, uT
    double maxFieldUt = 80.0;
    double minWeightS = 10.0;  // s of data (weighted) before an estimate is given
    // Outliers: once the estimate is good, a reading farther than this fraction of B from its
    // sphere is not taken (a glitch, a magnet passing by), and counted; when such readings
    // last gateResetS without a break the offset itself has changed: the sums are cleared.
    double gateFraction = 0.3;
    double gateResetS = 20.0;
    double maxReadingUt = 2000.0;  // a reading beyond this norm is never taken
};

// The fit's sums, weighted by the forgetting: what a run hands to the next to start from.
struct OnlineHardIronState {
    double weight = 0.0;                              // sum w
    Vec3d sumM = Vec3d::Zero();                       // sum w m
    Eigen::Matrix3d sumMM = Eigen::Matrix3d::Zero();  // sum w m m^T
    Vec3d sumM2M = Vec3d::Zero();                     // sum w |m|^2 m
    double sumM2 = 0.0;                               // sum w |m|^2
    double sumM4 = 0.0;                               // sum w |m|^4
    std::uint64_t samples = 0;                        // readings taken (not weighted)
};

// One line of text ("weight ... samples", 19 numbers) and back; parse gives nullopt for a line
// that is not exactly that, or holds a non-finite or negative weight.
std::string formatHardIronState(const OnlineHardIronState& s);
std::optional<OnlineHardIronState> parseHardIronState(std::string_view line);

struct HardIronEstimate {
    bool valid = false;              // enough data to solve (not yet a judgement of quality)
    bool good = false;               // valid, well spread, small residual, plausible field
    Vec3d offsetUt = Vec3d::Zero();  // h: subtract from the reading
    double fieldNormUt = 0.0;        // B
    double residualPct = 0.0;        // RMS distance of the readings from the sphere, % of B
    double spread = 0.0;  // 0 (one direction) .. 1 (directions spread evenly over the sphere)
};

class OnlineHardIron {
public:
    // magRateHz: the rate of the readings add() is given.
    explicit OnlineHardIron(double magRateHz, const OnlineHardIronParams& params = {});

    // One reading (uT, sensor frame). Non-finite input, a norm beyond maxReadingUt and, while
    // the last refresh() was good, a reading off its sphere are not taken (outliers()).
    void add(const Vec3d& magUt);
    // Solves the current sums (a 3x3 system; call it at a slower rate than add()).
    HardIronEstimate estimate() const;
    // estimate(), kept as the reference of the outlier gate; returns it.
    const HardIronEstimate& refresh();
    const HardIronEstimate& last() const { return last_; }
    std::uint64_t outliers() const { return outliers_; }
    std::uint32_t resets() const { return resets_; }

    const OnlineHardIronState& state() const { return state_; }
    // Restores what an earlier run saved; a state with non-finite or negative sums is refused
    // (false) and the estimator starts empty.
    bool setState(const OnlineHardIronState& s);
    const OnlineHardIronParams& params() const { return params_; }

private:
    OnlineHardIronParams params_;
    double decay_ = 1.0;  // per reading
    double magRateHz_ = 1.0;
    OnlineHardIronState state_;
    HardIronEstimate last_;
    std::uint64_t outliers_ = 0;
    std::uint32_t outlierRun_ = 0;
    std::uint32_t resets_ = 0;
};

}  // namespace caphub::fusion
