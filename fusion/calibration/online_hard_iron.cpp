#include "fusion/calibration/online_hard_iron.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <fmt/format.h>

namespace caphub::fusion {

namespace {

bool usable(const OnlineHardIronState& s) {
    return std::isfinite(s.weight) && s.weight >= 0.0 && s.sumM.allFinite() &&
           s.sumMM.allFinite() && s.sumM2M.allFinite() && std::isfinite(s.sumM2) &&
           std::isfinite(s.sumM4) && s.sumM2 >= 0.0 && s.sumM4 >= 0.0;
}

}  // namespace

std::string formatHardIronState(const OnlineHardIronState& s) {
    std::string out = fmt::format("{:.17g}", s.weight);
    for (int i = 0; i < 3; ++i) {
        out += fmt::format(" {:.17g}", s.sumM(i));
    }
    for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) {
            out += fmt::format(" {:.17g}", s.sumMM(r, c));
        }
    }
    for (int i = 0; i < 3; ++i) {
        out += fmt::format(" {:.17g}", s.sumM2M(i));
    }
    out += fmt::format(" {:.17g} {:.17g} {}", s.sumM2, s.sumM4, s.samples);
    return out;
}

std::optional<OnlineHardIronState> parseHardIronState(std::string_view line) {
    std::istringstream in{std::string(line)};
    in.imbue(std::locale::classic());
    OnlineHardIronState s;
    double v[18];
    for (double& x : v) {
        if (!(in >> x)) {
            return std::nullopt;
        }
    }
    std::uint64_t n = 0;
    if (!(in >> n)) {
        return std::nullopt;
    }
    std::string rest;
    if (in >> rest) {
        return std::nullopt;  // more than 19 numbers
    }
    int k = 0;
    s.weight = v[k++];
    for (int i = 0; i < 3; ++i) {
        s.sumM(i) = v[k++];
    }
    for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) {
            s.sumMM(r, c) = v[k++];
        }
    }
    for (int i = 0; i < 3; ++i) {
        s.sumM2M(i) = v[k++];
    }
    s.sumM2 = v[k++];
    s.sumM4 = v[k++];
    s.samples = n;
    if (!usable(s)) {
        return std::nullopt;
    }
    return s;
}

OnlineHardIron::OnlineHardIron(double magRateHz, const OnlineHardIronParams& params)
    : params_(params), magRateHz_(magRateHz > 0.0 ? magRateHz : 1.0) {
    decay_ = params_.memoryS > 0.0 ? std::exp(-1.0 / (magRateHz_ * params_.memoryS)) : 1.0;
}

void OnlineHardIron::add(const Vec3d& m) {
    if (!m.allFinite() || !(m.norm() <= params_.maxReadingUt)) {
        ++outliers_;
        return;
    }
    if (last_.good) {
        const double off = std::abs((m - last_.offsetUt).norm() - last_.fieldNormUt);
        if (off > params_.gateFraction * last_.fieldNormUt) {
            ++outliers_;
            if (++outlierRun_ >= static_cast<std::uint32_t>(params_.gateResetS * magRateHz_)) {
                // Off the sphere for that long: not a glitch but a new offset. Start over.
                state_ = OnlineHardIronState{};
                last_ = HardIronEstimate{};
                outlierRun_ = 0;
                ++resets_;
            }
            return;
        }
    }
    outlierRun_ = 0;
    OnlineHardIronState& s = state_;
    const double m2 = m.squaredNorm();
    s.weight = s.weight * decay_ + 1.0;
    s.sumM = s.sumM * decay_ + m;
    s.sumMM = s.sumMM * decay_ + m * m.transpose();
    s.sumM2M = s.sumM2M * decay_ + m2 * m;
    s.sumM2 = s.sumM2 * decay_ + m2;
    s.sumM4 = s.sumM4 * decay_ + m2 * m2;
    ++s.samples;
}

HardIronEstimate OnlineHardIron::estimate() const {
    HardIronEstimate e;
    const OnlineHardIronState& s = state_;
    if (!(s.weight >= params_.minWeightS * magRateHz_)) {
        return e;
    }
    const double w = s.weight;
    // Centred about the mean reading, for conditioning: with d = m - mean, |m|^2 = 2 m.h + c
    // becomes a fit of y = |m|^2 on [2 d, 1] with h unchanged.
    const Vec3d mean = s.sumM / w;
    const Eigen::Matrix3d cov = s.sumMM / w - mean * mean.transpose();
    // Normal equations of |m|^2 = 2 d.h + c' (c' absorbs 2 mean.h + c): the d-block is 4 cov,
    // decoupled from c' because d has zero mean.
    const Vec3d cross = s.sumM2M / w - (s.sumM2 / w) * mean;  // E[|m|^2 d]
    const Eigen::LDLT<Eigen::Matrix3d> ldlt(4.0 * cov);
    if (ldlt.info() != Eigen::Success || !(cov.trace() > 0.0)) {
        return e;
    }
    const Vec3d h = ldlt.solve(2.0 * cross);
    if (!h.allFinite()) {
        return e;
    }
    const double cPrime = s.sumM2 / w;  // E[|m|^2] (the mean of 2 d.h is zero)
    // B^2 = c + |h|^2 with c = c' - 2 mean.h.
    const double b2 = cPrime - 2.0 * mean.dot(h) + h.squaredNorm();
    if (!(b2 > 0.0)) {
        return e;
    }
    e.valid = true;
    e.offsetUt = h;
    e.fieldNormUt = std::sqrt(b2);
    // Residual of y: E[y^2] - E[y]^2 - (2h)^T E[y d] over the fit, as |m - h| - B is about
    // (|m|^2 - 2 m.h - c) / 2B.
    const double varY = s.sumM4 / w - cPrime * cPrime;
    const double sse = std::max(0.0, varY - 2.0 * h.dot(cross));
    e.residualPct = 100.0 * std::sqrt(sse) / (2.0 * b2);
    // Spread: the smallest variance of the directions about the centre, as a fraction of the
    // even spread (B^2 / 3 per axis).
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov, Eigen::EigenvaluesOnly);
    // (Against at least the smallest plausible field: a sensor held still fits a tiny sphere to
    // its noise.)
    const double scale = std::max(b2, params_.minFieldUt * params_.minFieldUt);
    e.spread = std::clamp(3.0 * eig.eigenvalues()(0) / scale, 0.0, 1.0);
    e.good = e.spread >= params_.minSpread && e.residualPct <= params_.maxResidualPct &&
             e.fieldNormUt >= params_.minFieldUt && e.fieldNormUt <= params_.maxFieldUt;
    return e;
}

const HardIronEstimate& OnlineHardIron::refresh() {
    last_ = estimate();
    return last_;
}

bool OnlineHardIron::setState(const OnlineHardIronState& s) {
    outlierRun_ = 0;
    if (!usable(s)) {
        state_ = OnlineHardIronState{};
        last_ = HardIronEstimate{};
        return false;
    }
    state_ = s;
    last_ = estimate();
    return true;
}

}  // namespace caphub::fusion
