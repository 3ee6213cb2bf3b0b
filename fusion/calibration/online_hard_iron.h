// Online hard- and soft-iron estimation for one magnetometer while the suit moves: no
// calibration session, no I/O. The readings of a sensor that turns lie on an ellipsoid about the
// offset h (hard iron plus the chip's zero-field offset): (m - h)^T M (m - h) = B^2, where M = S^2
// and S, symmetric and near the identity, is the soft iron's correction (docs/fusion.md, "No
// magnetometer calibration"). With M normalised to a trace of 3 the fit is linear in M's five
// other numbers, M h and a constant. The estimator keeps only the sums of that least-squares fit
// with exponential forgetting (OnlineHardIronState: the 10 x 10 moments of the regressors and the
// target, about the first reading), and solves it in closed form when asked: the sphere
// (M = I, hard iron alone) and the ellipsoid, whose soft iron has a prior of a few per cent per
// element (a ridge), so that the directions the turns have not explored stay at the sphere's
// answer. The fit does not depend on the filter's heading, so the sums of one run carry over to
// the next. Observability needs turns: only the part of h across the directions the field has
// taken in the sensor frame can be told; `spread` measures it.
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
    // The soft iron's prior: each element of S - I is about this large (a board's and strap's
    // soft iron and the chip's scale errors, a few per cent), and a reading scatters about the
    // ellipsoid by about readingSigmaUt (noise and what the model leaves). Their ratio weighs the
    // prior against the data: a direction the turns have not explored keeps S = I there.
    double softIronSigma = 0.05;
    double readingSigmaUt = 1.0;  // uT
    // An ellipsoid whose M has an eigenvalue outside [1 / maxSoftIronScale^2, maxSoftIronScale^2]
    // is not a plausible soft iron: the sphere's answer is given instead.
    double maxSoftIronScale = 1.25;
    // The soft iron is fitted only from readings spread this well (0..1, `spread`): turns that
    // leave the readings near a plane (a leg swinging about one axis) let the algebraic fit take
    // the noise for shape (docs/fusion.md: a 0.5 uT noise gave S off by 0.11 at a spread of
    // 0.045, 0.014 at 0.14 and 0.006 at 0.23); the sphere's answer serves below.
    double minSoftIronSpread = 0.15;
    bool fitSoftIron = true;  // false: the sphere alone (hard iron only)
    // The alignment (addAlignment): its prior (each component of r about this large, the chips'
    // axes' misalignment), how far a reading's dip scatters (the filter's tilt error and the
    // noise), and how much aligned data it needs. It is learnt only while the soft iron is
    // (the same spread) and from readings within alignNormFraction of the field's norm.
    double alignSigmaDeg = 3.0;
    double dipScatterUt = 1.0;
    double minAlignWeightS = 10.0;
    double alignNormFraction = 0.05;
    bool fitAlignment = true;
};

// The fit's sums, weighted by the forgetting: what a run hands to the next to start from. With
// d = m - anchor (the first reading taken, for conditioning) and the regressors and target
// psi = [x^2 - z^2, y^2 - z^2, 2xy, 2xz, 2yz, x, y, z, 1, |d|^2] of d = (x, y, z), `moments` is
// sum w psi psi^T: every sum either fit needs (its (8, 8) element is the weight, sum w).
// The alignment's sums (addAlignment): with c the corrected reading before the alignment, u the
// sensor's up and a = c x u, `alignMoments` is sum w chi chi^T, chi = [a, -1, -(c.u)]: the
// least-squares fit of (R c).u = c.u + r.(c x u) = const for the small rotation r.
struct OnlineHardIronState {
    static constexpr int kTerms = 10;
    static constexpr int kAlignTerms = 5;
    using Moments = Eigen::Matrix<double, kTerms, kTerms>;
    using AlignMoments = Eigen::Matrix<double, kAlignTerms, kAlignTerms>;
    Vec3d anchor = Vec3d::Zero();
    Moments moments = Moments::Zero();
    AlignMoments alignMoments = AlignMoments::Zero();
    std::uint64_t samples = 0;  // readings taken (not weighted)
    double weight() const { return moments(8, 8); }
    double alignWeight() const { return alignMoments(3, 3); }
};

// One line of text (the anchor, the 55 moments and the 15 alignment moments, each an upper
// triangle row by row, the samples: 74 numbers) and back; parse gives nullopt for a line that is
// not exactly that, or holds a non-finite number or a negative weight. (A line of the
// hard-iron-only estimator before 2026-11-26 had 19 numbers: it is not this.)
std::string formatHardIronState(const OnlineHardIronState& s);
std::optional<OnlineHardIronState> parseHardIronState(std::string_view line);
constexpr int kHardIronStateNumbers = 3 + 55 + 15 + 1;

struct HardIronEstimate {
    bool valid = false;              // enough data to solve (not yet a judgement of quality)
    bool good = false;               // valid, well spread, small residual, plausible field
    Vec3d offsetUt = Vec3d::Zero();  // h: subtract from the reading
    // S: the soft iron's correction, symmetric (the identity from the sphere fit)
    Eigen::Matrix3d softIron = Eigen::Matrix3d::Identity();
    bool ellipsoid = false;  // S was fitted (else the sphere's: hard iron alone)
    // R: the small rotation that takes the corrected field into the frame of the accelerometer
    // and gyroscope (the chips' axes are not exactly parallel), from the field's constant dip
    // (the identity until enough aligned readings are in: `aligned`)
    Eigen::Matrix3d alignment = Eigen::Matrix3d::Identity();
    bool aligned = false;
    double fieldNormUt = 0.0;  // B, the corrected readings' norm
    double residualPct = 0.0;  // RMS distance of the readings from the fitted surface, % of B
    double spread = 0.0;       // 0 (one direction) .. 1 (directions spread evenly over the sphere)
    // The reading corrected: R S (m - h).
    Vec3d corrected(const Vec3d& magUt) const {
        return alignment * (softIron * (magUt - offsetUt));
    }
};

class OnlineHardIron {
public:
    // magRateHz: the rate of the readings add() is given.
    explicit OnlineHardIron(double magRateHz, const OnlineHardIronParams& params = {});

    // One reading (uT, sensor frame). Non-finite input, a norm beyond maxReadingUt and, while
    // the last refresh() was good, a reading off its sphere are not taken (outliers()).
    void add(const Vec3d& magUt);
    // The same reading with the sensor's up direction in its own frame (unit, from the
    // orientation filter's tilt: no heading), for the alignment of the magnetometer's axes to the
    // accelerometer's. Taken only while the last refresh() was good with a fitted soft iron and
    // the corrected reading is of the field's norm.
    void addAlignment(const Vec3d& magUt, const Vec3d& upSensor);
    // Whether addAlignment takes readings now (the caller may skip computing the up direction).
    bool learnsAlignment() const { return params_.fitAlignment && last_.good && last_.ellipsoid; }
    // Solves the current sums (a 4x4 and a 9x9 system; call it at a slower rate than add()).
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
    // The readings taken so far as seconds of the magnetometer's rate, weighted by the
    // forgetting: what minWeightS is compared with.
    double readingsS() const { return state_.weight() / magRateHz_; }

private:
    // The alignment R of a good estimate with a fitted soft iron, from the alignment's sums.
    void solveAlignment(HardIronEstimate& e) const;

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
