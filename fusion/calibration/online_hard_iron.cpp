#include "fusion/calibration/online_hard_iron.h"

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <sstream>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <fmt/format.h>

#include "hal/core/angles.h"

namespace caphub::fusion {

namespace {

using Moments = OnlineHardIronState::Moments;
constexpr int kTerms = OnlineHardIronState::kTerms;
// Where each term sits in psi (OnlineHardIronState).
constexpr int kFirstLinear = 5;  // x, y, z at 5, 6, 7
constexpr int kOne = 8;
constexpr int kTarget = 9;  // |d|^2

Eigen::Matrix<double, kTerms, 1> terms(const Vec3d& d) {
    const double x = d.x();
    const double y = d.y();
    const double z = d.z();
    Eigen::Matrix<double, kTerms, 1> psi;
    psi << x * x - z * z, y * y - z * z, 2 * x * y, 2 * x * z, 2 * y * z, x, y, z, 1.0,
        d.squaredNorm();
    return psi;
}

// Sums of squares (the moments' diagonals) are never negative: a state that says one is has
// been damaged, whatever the rest of it says.
bool usable(const OnlineHardIronState& s) {
    return s.anchor.allFinite() && s.moments.allFinite() && s.weight() >= 0.0 &&
           (s.moments.diagonal().array() >= 0.0).all() && s.alignMoments.allFinite() &&
           s.alignWeight() >= 0.0 && (s.alignMoments.diagonal().array() >= 0.0).all();
}

// Writes and reads the upper triangle of a symmetric matrix, row by row.
template <typename M>
void appendUpper(std::string& out, const M& m) {
    for (int r = 0; r < m.rows(); ++r) {
        for (int c = r; c < m.cols(); ++c) {
            out += fmt::format(" {:.17g}", m(r, c));
        }
    }
}
template <typename M>
void readUpper(M& m, const double* v, int& k) {
    for (int r = 0; r < m.rows(); ++r) {
        for (int c = r; c < m.cols(); ++c) {
            m(r, c) = v[k];
            m(c, r) = v[k++];
        }
    }
}

// The small rotation exp([r]x) as a matrix.
Eigen::Matrix3d rotationOf(const Vec3d& r) {
    const double angle = r.norm();
    if (angle < 1e-12) {
        return Eigen::Matrix3d::Identity();
    }
    return Eigen::AngleAxisd(angle, r / angle).toRotationMatrix();
}

template <int N>
struct LsFit {
    Eigen::Matrix<double, N, 1> coef;
    double sse = 0.0;
};

// The least-squares fit of the target (the moments' last term) on the terms `idx`, from the
// normal equations in the moments `m` (sum w t t^T of the terms and the target), with `ridge`
// added to the diagonal of the first `ridged` of them: the coefficients in the order of idx and
// the sum of squared residuals on the data (weighted); nullopt when the system is singular.
template <int N, typename M>
std::optional<LsFit<N>> solveFit(const M& m, const std::array<int, N>& idx, int ridged,
                                 double ridge) {
    const int target = static_cast<int>(m.cols()) - 1;
    Eigen::Matrix<double, N, N> g;
    Eigen::Matrix<double, N, 1> r;
    for (int i = 0; i < N; ++i) {
        r(i) = m(idx[i], target);
        for (int j = 0; j < N; ++j) {
            g(i, j) = m(idx[i], idx[j]);
        }
    }
    Eigen::Matrix<double, N, N> gr = g;
    for (int i = 0; i < ridged; ++i) {
        gr(i, i) += ridge;
    }
    const Eigen::LDLT<Eigen::Matrix<double, N, N>> ldlt(gr);
    if (ldlt.info() != Eigen::Success) {
        return std::nullopt;
    }
    LsFit<N> f;
    f.coef = ldlt.solve(r);
    if (!f.coef.allFinite()) {
        return std::nullopt;
    }
    // sum (y - t.c)^2 = sum y^2 - 2 c.r + c^T G c, on the data (not the prior).
    f.sse = std::max(0.0, m(target, target) - 2.0 * f.coef.dot(r) + f.coef.dot(g * f.coef));
    return f;
}

}  // namespace

std::string formatHardIronState(const OnlineHardIronState& s) {
    std::string out =
        fmt::format("{:.17g} {:.17g} {:.17g}", s.anchor.x(), s.anchor.y(), s.anchor.z());
    appendUpper(out, s.moments);
    appendUpper(out, s.alignMoments);
    out += fmt::format(" {}", s.samples);
    return out;
}

std::optional<OnlineHardIronState> parseHardIronState(std::string_view line) {
    std::istringstream in{std::string(line)};
    in.imbue(std::locale::classic());
    OnlineHardIronState s;
    double v[kHardIronStateNumbers - 1];
    for (double& x : v) {
        if (!(in >> x)) {
            return std::nullopt;
        }
    }
    // The sample count: digits only (a stream reads "-5" as 2^64 - 5).
    std::string count;
    std::uint64_t n = 0;
    if (!(in >> count) || count.find_first_not_of("0123456789") != std::string::npos ||
        std::from_chars(count.data(), count.data() + count.size(), n).ec != std::errc{}) {
        return std::nullopt;
    }
    std::string rest;
    if (in >> rest) {
        return std::nullopt;  // more numbers than a state has
    }
    int k = 0;
    for (int i = 0; i < 3; ++i) {
        s.anchor(i) = v[k++];
    }
    readUpper(s.moments, v, k);
    readUpper(s.alignMoments, v, k);
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
        const double off = std::abs(last_.corrected(m).norm() - last_.fieldNormUt);
        if (off > params_.gateFraction * last_.fieldNormUt) {
            ++outliers_;
            if (++outlierRun_ >= static_cast<std::uint32_t>(params_.gateResetS * magRateHz_)) {
                // Off the surface for that long: not a glitch but a new offset. Start over.
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
    if (s.samples == 0 && s.weight() == 0.0) {
        s.anchor = m;
    }
    const auto psi = terms(m - s.anchor);
    s.moments = s.moments * decay_ + psi * psi.transpose();
    ++s.samples;
}

void OnlineHardIron::addAlignment(const Vec3d& m, const Vec3d& up) {
    if (!learnsAlignment() || !m.allFinite() || !up.allFinite() ||
        std::abs(up.norm() - 1.0) > 1e-3) {
        return;
    }
    const Vec3d c = last_.softIron * (m - last_.offsetUt);
    if (std::abs(c.norm() - last_.fieldNormUt) > params_.alignNormFraction * last_.fieldNormUt) {
        return;  // disturbed, or a glitch: its dip says nothing of the axes
    }
    const Vec3d a = c.cross(up);
    Eigen::Matrix<double, OnlineHardIronState::kAlignTerms, 1> chi;
    chi << a.x(), a.y(), a.z(), -1.0, -c.dot(up);
    state_.alignMoments = state_.alignMoments * decay_ + chi * chi.transpose();
}

HardIronEstimate OnlineHardIron::estimate() const {
    HardIronEstimate e;
    const OnlineHardIronState& s = state_;
    const double w = s.weight();
    if (!(w >= params_.minWeightS * magRateHz_)) {
        return e;
    }
    const Moments& m = s.moments;
    const Vec3d mean = m.block<3, 1>(kFirstLinear, kOne) / w;
    const Eigen::Matrix3d cov =
        m.block<3, 3>(kFirstLinear, kFirstLinear) / w - mean * mean.transpose();
    if (!(cov.trace() > 0.0)) {
        return e;
    }
    // The sphere: |d|^2 = 2 d.k + c, so h = anchor + k and B^2 = c + |k|^2.
    const auto sphere =
        solveFit<4>(m, {kFirstLinear, kFirstLinear + 1, kFirstLinear + 2, kOne}, 0, 0.0);
    if (!sphere) {
        return e;
    }
    const Vec3d k = sphere->coef.head<3>() / 2.0;
    const double b2 = sphere->coef(3) + k.squaredNorm();
    if (!(b2 > 0.0)) {
        return e;
    }
    e.valid = true;
    e.offsetUt = s.anchor + k;
    e.fieldNormUt = std::sqrt(b2);
    // The algebraic residual |d|^2 - 2 d.k - c is about 2B times the distance from the surface.
    e.residualPct = 100.0 * std::sqrt(sphere->sse / w) / (2.0 * b2);
    // Spread: the smallest variance of the directions about the centre, as a fraction of the
    // even spread (B^2 / 3 per axis), against at least the smallest plausible field (a sensor
    // held still fits a tiny sphere to its noise).
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov, Eigen::EigenvaluesOnly);
    const double scale = std::max(b2, params_.minFieldUt * params_.minFieldUt);
    e.spread = std::clamp(3.0 * eig.eigenvalues()(0) / scale, 0.0, 1.0);

    if (params_.fitSoftIron && e.spread >= params_.minSoftIronSpread) {
        // The ellipsoid: |d|^2 = a.[x^2 - z^2, y^2 - z^2, 2xy, 2xz, 2yz] + b.d + c, that is
        // d^T M d - b.d - c = 0 with M = I - A (A symmetric, traceless, from a). Its prior: the
        // ridge (sigma_y / sigma_A)^2, sigma_y = 2 B readingSigmaUt the target's scatter and
        // sigma_A = 2 softIronSigma (M = S^2, so A is about twice S - I).
        const double sigmaY = 2.0 * e.fieldNormUt * params_.readingSigmaUt;
        const double sigmaA = 2.0 * params_.softIronSigma;
        const double ridge = (sigmaY / sigmaA) * (sigmaY / sigmaA);
        const auto fit = solveFit<9>(m, {0, 1, 2, 3, 4, 5, 6, 7, 8}, 5, ridge);
        if (fit) {
            const auto& a = fit->coef;
            Eigen::Matrix3d bigA;
            bigA << a(0), a(2), a(3), a(2), a(1), a(4), a(3), a(4), -a(0) - a(1);
            const Eigen::Matrix3d bigM = Eigen::Matrix3d::Identity() - bigA;
            const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> em(bigM);
            const double lo = 1.0 / (params_.maxSoftIronScale * params_.maxSoftIronScale);
            const double hi = params_.maxSoftIronScale * params_.maxSoftIronScale;
            if (em.info() == Eigen::Success && em.eigenvalues().minCoeff() >= lo &&
                em.eigenvalues().maxCoeff() <= hi) {
                const Vec3d ke = bigM.ldlt().solve(fit->coef.segment<3>(5)) / 2.0;
                const double r2 = fit->coef(8) + ke.dot(bigM * ke);
                if (ke.allFinite() && r2 > 0.0) {
                    e.ellipsoid = true;
                    e.offsetUt = s.anchor + ke;
                    e.softIron = em.eigenvectors() * em.eigenvalues().cwiseSqrt().asDiagonal() *
                                 em.eigenvectors().transpose();
                    e.fieldNormUt = std::sqrt(r2);
                    e.residualPct = 100.0 * std::sqrt(fit->sse / w) / (2.0 * r2);
                }
            }
        }
    }
    e.good = e.spread >= params_.minSpread && e.residualPct <= params_.maxResidualPct &&
             e.fieldNormUt >= params_.minFieldUt && e.fieldNormUt <= params_.maxFieldUt;
    if (e.good && e.ellipsoid) {
        solveAlignment(e);
    }
    return e;
}

void OnlineHardIron::solveAlignment(HardIronEstimate& e) const {
    if (!params_.fitAlignment || !(state_.alignWeight() >= params_.minAlignWeightS * magRateHz_)) {
        return;
    }
    // c.u + r.(c x u) = s: the fit of -(c.u) on [c x u, -1] with the prior on r as a ridge
    // (dipScatter / alignSigma)^2.
    const double sigmaR = params_.alignSigmaDeg * hal::kDegToRad;
    const double ridge = (params_.dipScatterUt / sigmaR) * (params_.dipScatterUt / sigmaR);
    const auto fit = solveFit<4>(state_.alignMoments, {0, 1, 2, 3}, 3, ridge);
    if (!fit) {
        return;
    }
    // The fit's unknowns are r and s = B sin(dip) (-(c.u) = r.(c x u) - s); (R c).u =
    // c.u + r.(c x u) holds for a small r, and a rotation beyond a few of sigmaR is not a chip's
    // misalignment.
    const Vec3d r = fit->coef.head<3>();
    if (r.norm() > 4.0 * sigmaR) {
        return;
    }
    e.alignment = rotationOf(r);
    e.aligned = true;
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
