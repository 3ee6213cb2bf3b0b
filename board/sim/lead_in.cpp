#include "board/sim/lead_in.h"

#include <cmath>

#include "board/sim/joint_map.h"

namespace caphub::board::sim {

namespace {

// A quintic from (y0, 0, 0) at tau = 0 to (y1, d1, dd1) at tau = 1, with its first and second
// derivatives (per unit tau): zero rate and acceleration where the T-pose ends, the clip's where
// it begins.
template <typename V>
void quintic(const V& y0, const V& y1, const V& d1, const V& dd1, double tau, V& y, V& dy, V& ddy) {
    const double t2 = tau * tau;
    const double t3 = t2 * tau;
    const double t4 = t3 * tau;
    const double t5 = t4 * tau;
    // Hermite basis: h0 (start value), h5 (end value), h4 (end slope), h3 (end curvature).
    const double h5 = 10 * t3 - 15 * t4 + 6 * t5;
    const double h4 = -4 * t3 + 7 * t4 - 3 * t5;
    const double h3 = 0.5 * t3 - t4 + 0.5 * t5;
    const double dh5 = 30 * t2 - 60 * t3 + 30 * t4;
    const double dh4 = -12 * t2 + 28 * t3 - 15 * t4;
    const double dh3 = 1.5 * t2 - 4 * t3 + 2.5 * t4;
    const double ddh5 = 60 * tau - 180 * t2 + 120 * t3;
    const double ddh4 = -24 * tau + 84 * t2 - 60 * t3;
    const double ddh3 = 3 * tau - 12 * t2 + 10 * t3;
    y = y0 + (y1 - y0) * h5 + d1 * h4 + dd1 * h3;
    dy = (y1 - y0) * dh5 + d1 * dh4 + dd1 * dh3;
    ddy = (y1 - y0) * ddh5 + d1 * ddh4 + dd1 * ddh3;
}

Vec3d logOf(const Quatd& q) {
    const Eigen::AngleAxisd aa(q.normalized());
    return aa.axis() * aa.angle();
}

Quatd expOf(const Vec3d& r) {
    const double angle = r.norm();
    return angle < 1e-15 ? Quatd::Identity() : Quatd(Eigen::AngleAxisd(angle, r / angle));
}

// Rates of the blend by central differences: the interpolation is in the rotation vector of
// the clip's first orientation, whose relation to the body rate has no short closed form. With
// h = 0.1 ms the error is ~h^2 times the third derivative: far below the gyro's LSB.
constexpr std::int64_t kDiffNs = 100'000;

}  // namespace

namespace {
std::array<Quatd, board::kSegmentCount> tPose() {
    std::array<Quatd, board::kSegmentCount> q;
    q.fill(Quatd::Identity());
    return q;
}
}  // namespace

LeadInMotion::LeadInMotion(std::shared_ptr<const Motion> clip, double holdS, double blendS)
    : LeadInMotion(std::move(clip), holdS, blendS, tPose()) {}

LeadInMotion::LeadInMotion(std::shared_ptr<const Motion> clip, double holdS, double blendS,
                           const std::array<Quatd, board::kSegmentCount>& pose)
    : clip_(std::move(clip)),
      holdNs_(static_cast<std::int64_t>(std::llround(holdS * 1e9))),
      blendNs_(static_cast<std::int64_t>(std::llround(std::max(blendS, 0.1) * 1e9))),
      pose_(pose) {
    for (int i = 0; i < board::kSegmentCount; ++i) {
        clip_->evaluate(static_cast<Segment>(i), 0, start_[static_cast<std::size_t>(i)]);
    }
    for (auto& q : pose_) {
        q.normalize();
    }
    // Segments come parents first (board/segment.h): each origin is its parent's plus the bone
    // vector of the clip's first pose, turned by the parent's orientation in the pose held.
    for (int i = 0; i < board::kSegmentCount; ++i) {
        const auto s = static_cast<Segment>(i);
        const auto u = static_cast<std::size_t>(i);
        const auto parent = parentSegment(s);
        if (!parent) {
            poseM_[u] = start_[u].positionM;
            continue;
        }
        const auto p = static_cast<std::size_t>(*parent);
        const Vec3d bone =
            start_[p].qWorldSegment.conjugate() * (start_[u].positionM - start_[p].positionM);
        poseM_[u] = poseM_[p] + pose_[p] * bone;
    }
}

void LeadInMotion::blendPose(Segment s, std::int64_t tNs, Quatd& q, Vec3d& p, Vec3d& v,
                             Vec3d& a) const {
    const auto u = static_cast<std::size_t>(s);
    const SegmentState& c = start_[u];
    if (tNs <= holdNs_) {
        q = pose_[u];
        p = poseM_[u];
        v = a = Vec3d::Zero();
        return;
    }
    const double blendS = static_cast<double>(blendNs_) * 1e-9;
    const double tau = std::min(1.0, static_cast<double>(tNs - holdNs_) * 1e-9 / blendS);
    Vec3d r;
    Vec3d dr;
    Vec3d ddr;
    // q = q0 exp(r): r goes from log(q0^-1 qPose) to 0, ending with the clip's body rate and
    // angular acceleration (at r = 0 they are r' and r'').
    quintic<Vec3d>(logOf(c.qWorldSegment.conjugate() * pose_[u]), Vec3d::Zero(),
                   c.omegaRadS * blendS, c.alphaRadS2 * blendS * blendS, tau, r, dr, ddr);
    q = (c.qWorldSegment * expOf(r)).normalized();
    Vec3d dp;
    Vec3d ddp;
    quintic<Vec3d>(poseM_[u], c.positionM, c.velocityMps * blendS,
                   c.accelerationMps2 * blendS * blendS, tau, p, dp, ddp);
    v = dp / blendS;
    a = ddp / (blendS * blendS);
}

void LeadInMotion::evaluate(Segment s, std::int64_t tNs, SegmentState& out) const {
    if (tNs >= leadInNs()) {
        clip_->evaluate(s, tNs - leadInNs(), out);
        return;
    }
    out = SegmentState{};
    blendPose(s, tNs, out.qWorldSegment, out.positionM, out.velocityMps, out.accelerationMps2);
    if (tNs <= holdNs_ - kDiffNs) {
        return;  // standing still
    }
    // Body rate from the orientations around tNs, and its rate of change likewise.
    const auto rateAt = [this, s](std::int64_t t) {
        const Quatd qa = orientationAt(s, t - kDiffNs);
        const Quatd qb = orientationAt(s, t + kDiffNs);
        return Vec3d(logOf(qa.conjugate() * qb) / (2e-9 * static_cast<double>(kDiffNs)));
    };
    out.omegaRadS = rateAt(tNs);
    out.alphaRadS2 =
        (rateAt(tNs + kDiffNs) - rateAt(tNs - kDiffNs)) / (2e-9 * static_cast<double>(kDiffNs));
}

Quatd LeadInMotion::orientationAt(Segment s, std::int64_t tNs) const {
    if (tNs >= leadInNs()) {
        SegmentState c;
        clip_->evaluate(s, tNs - leadInNs(), c);
        return c.qWorldSegment;
    }
    Quatd q;
    Vec3d p;
    Vec3d v;
    Vec3d a;
    blendPose(s, tNs, q, p, v, a);
    return q;
}

}  // namespace caphub::board::sim
