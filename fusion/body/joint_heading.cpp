#include "fusion/body/joint_heading.h"

#include <algorithm>
#include <cmath>

namespace caphub::body {

void JointHeading::add(Side side, double tS, const Vec3d& accEnuMps2) {
    if (!accEnuMps2.allFinite() || !std::isfinite(tS)) {
        return;
    }
    Filtered& s = sides_[side];
    if (!s.valid || tS <= s.tS || tS - s.tS > 0.5) {
        s.acc = accEnuMps2;  // the first sample, or after a gap: start from it
        s.hasPrevious = false;
    } else {
        s.previousAcc = s.acc;
        s.previousS = s.tS;
        s.hasPrevious = true;
        const double k = 1.0 - std::exp(-(tS - s.tS) / options_.filterTauS);
        s.acc += k * (accEnuMps2 - s.acc);
    }
    s.tS = tS;
    s.valid = true;
    const Filtered& parent = sides_[Parent];
    if (side != Child || !parent.valid || std::abs(parent.tS - tS) > options_.maxSkewS) {
        return;
    }
    // The parent's at the child's time: two sensors on two buses sample at instants of their own,
    // and a joint's acceleration turns in the horizontal plane (a walk's hips trace loops), so
    // that a constant lag between the two would read as a turn.
    const Vec3d p = parent.at(tS);
    const double dt = paired_ ? std::clamp(tS - lastPairS_, 0.0, 0.1) : 0.0;
    lastPairS_ = tS;
    paired_ = true;
    const double keep = std::exp(-dt / options_.memoryS);
    sumCross_ *= keep;
    sumDot_ *= keep;
    energy_ *= keep;
    const double px = p.x();
    const double py = p.y();
    const double cx = s.acc.x();
    const double cy = s.acc.y();
    const double ph = std::hypot(px, py);
    const double ch = std::hypot(cx, cy);
    if (std::abs(p.z() - s.acc.z()) > options_.maxMismatchMps2 ||
        std::abs(ph - ch) > options_.maxMismatchMps2 || ph > options_.maxAccelerationMps2 ||
        ch > options_.maxAccelerationMps2) {
        ++mismatched_;
        return;
    }
    ++pairs_;
    sumCross_ += dt * (px * cy - py * cx);
    sumDot_ += dt * (px * cx + py * cy);
    energy_ += dt * ph * ch;
}

Vec3d JointHeading::Filtered::at(double t) const {
    if (!hasPrevious || tS <= previousS) {
        return acc;
    }
    const double u = std::clamp((t - previousS) / (tS - previousS), 0.0, 2.0);
    return previousAcc + u * (acc - previousAcc);
}

double JointHeading::consistency() const {
    return energy_ > 0 ? std::hypot(sumCross_, sumDot_) / energy_ : 0.0;
}

std::optional<double> JointHeading::angleRad() const {
    if (energy_ < options_.minEnergy || consistency() < options_.minConsistency) {
        return std::nullopt;
    }
    return std::atan2(sumCross_, sumDot_);
}

void JointHeading::turn(Side side, double angleRad) {
    const double c = std::cos(angleRad);
    const double s = std::sin(angleRad);
    Filtered& f = sides_[side];
    const auto turned = [c, s](const Vec3d& v) {
        return Vec3d(c * v.x() - s * v.y(), s * v.x() + c * v.y(), v.z());
    };
    f.acc = turned(f.acc);
    f.previousAcc = turned(f.previousAcc);
    // The angle from parent to child grows by the child's turn and shrinks by the parent's.
    const double a = side == Child ? angleRad : -angleRad;
    const double ca = std::cos(a);
    const double sa = std::sin(a);
    const double cross = sumCross_;
    const double dot = sumDot_;
    sumCross_ = sa * dot + ca * cross;
    sumDot_ = ca * dot - sa * cross;
}

void JointHeading::reset() {
    sides_ = {};
    sumCross_ = 0;
    sumDot_ = 0;
    energy_ = 0;
    paired_ = false;
}

}  // namespace caphub::body
