#include "fusion/body/root_tracker.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace caphub::body {

namespace {

using S = Segment;

// The lowest of one foot's three points (0-2 left, 3-5 right) in the given positions.
int lowestPoint(const std::array<Vec3d, 6>& p, int foot) {
    int best = 3 * foot;
    for (int k = 3 * foot + 1; k < 3 * foot + 3; ++k) {
        if (p[static_cast<std::size_t>(k)].y() < p[static_cast<std::size_t>(best)].y()) {
            best = k;
        }
    }
    return best;
}

}  // namespace

void footState(const Dimensions& d, const Pose& pose, const JointRates& rates, FootState& out) {
    for (int foot = 0; foot < 2; ++foot) {
        const int seg = idx(foot == 0 ? S::LHindfoot : S::RHindfoot);
        const auto& pts = foot == 0 ? d.leftFootPointM : d.rightFootPointM;
        ChainJacobian jac;
        spatialJacobian(pose, seg, pts[1], jac);
        const Twist tw = endEffectorTwist(jac, Vec3d::Zero(), rates);
        const Vec3d v = tw.head<3>();
        const Vec3d w = tw.tail<3>();
        for (int k = 0; k < 3; ++k) {
            const auto u = static_cast<std::size_t>(3 * foot + k);
            out.pointM[u] = pointOnSegment(pose, seg, pts[static_cast<std::size_t>(k)]);
            out.velocityMps[u] = v + w.cross(out.pointM[u] - jac.pointM);
        }
    }
}

void RootTracker::reset(const Dimensions& d, Pose& pose, double rootXM, double rootZM) {
    const Vec3d old = pose.positionM[0];
    double lowest = std::numeric_limits<double>::max();
    int lowestIndex = 0;
    for (int foot = 0; foot < 2; ++foot) {
        const int seg = idx(foot == 0 ? S::LHindfoot : S::RHindfoot);
        const auto& pts = foot == 0 ? d.leftFootPointM : d.rightFootPointM;
        for (int k = 0; k < 3; ++k) {
            const double y =
                (pointOnSegment(pose, seg, pts[static_cast<std::size_t>(k)]) - old).y();
            if (y < lowest) {
                lowest = y;
                lowestIndex = 3 * foot + k;
            }
        }
    }
    root_ = Vec3d(rootXM, -lowest, rootZM);
    floorYM = 0;
    velocity_.setZero();
    phase_ = lowestIndex < 3 ? ContactPhase::LeftStance : ContactPhase::RightStance;
    point_ = lowestIndex;
    freeFallCount_ = 0;
    stanceChanges_ = 0;
    for (auto& p : pose.positionM) {
        p += root_ - old;
    }
    // The anchor is the contact point's world position.
    const int seg = idx(lowestIndex < 3 ? S::LHindfoot : S::RHindfoot);
    const auto& pts = lowestIndex < 3 ? d.leftFootPointM : d.rightFootPointM;
    anchor_ = pointOnSegment(pose, seg, pts[static_cast<std::size_t>(lowestIndex % 3)]);
    anchor_.y() = floorYM;
    started_ = true;
}

void RootTracker::update(const Dimensions& d, Pose& pose, const FootState& feet, double dtS,
                         std::optional<double> rootSpecificForceMps2) {
    if (!started_) {
        reset(d, pose);
        return;
    }
    const auto& r = feet.pointM;  // relative to the root
    double minY = std::numeric_limits<double>::max();
    for (const Vec3d& p : r) {
        minY = std::min(minY, p.y());
    }

    freeFallCount_ = rootSpecificForceMps2 && *rootSpecificForceMps2 < options_.freeFallMps2
                         ? freeFallCount_ + 1
                         : 0;
    if (freeFallCount_ == 1) {
        takeoffVelocity_ = velocity_;  // before the feet, now unloaded, stop moving the root
    }
    if (phase_ != ContactPhase::Flight && freeFallCount_ >= options_.flightFrames) {
        phase_ = ContactPhase::Flight;
        point_ = -1;
        velocity_ = takeoffVelocity_;
    }

    Vec3d next = root_;
    if (phase_ == ContactPhase::Flight) {
        velocity_.y() -= options_.gravityMps2 * dtS;
        next = root_ + velocity_ * dtS;
        if (next.y() + minY <= floorYM && velocity_.y() <= 0) {
            // Landing: the lowest foot point touches the floor and becomes the anchor.
            int lowest = 0;
            for (int k = 1; k < 6; ++k) {
                if (r[static_cast<std::size_t>(k)].y() < r[static_cast<std::size_t>(lowest)].y()) {
                    lowest = k;
                }
            }
            next.y() = floorYM - minY;
            point_ = lowest;
            phase_ = lowest < 3 ? ContactPhase::LeftStance : ContactPhase::RightStance;
            anchor_ = next + r[static_cast<std::size_t>(lowest)];
            anchor_.y() = floorYM;
            freeFallCount_ = 0;
            ++stanceChanges_;
        }
    } else {
        const int current = phase_ == ContactPhase::LeftStance ? 0 : 1;
        const int other = 1 - current;
        // The stance foot's world velocity is ~0 by construction (the root follows it), so the
        // other foot is judged by its vertical velocity relative to the stance foot (it has
        // stopped coming down), which does not depend on the root velocity estimate; the
        // horizontal part is not used because the old stance foot, already pushing off, drags
        // the relative velocity up.
        const int pCur = lowestPoint(r, current);
        const int pOther = lowestPoint(r, other);
        const auto uc = static_cast<std::size_t>(pCur);
        const auto uo = static_cast<std::size_t>(pOther);
        const double hCur = r[uc].y() - minY;
        const double hOther = r[uo].y() - minY;
        const bool otherStill =
            std::abs(feet.velocityMps[uo].y() - feet.velocityMps[uc].y()) < options_.speedMps;
        // Where the root is this frame if the old contact point has not moved.
        const Vec3d here = anchor_ - r[static_cast<std::size_t>(point_)];
        if (otherStill && hOther < options_.heightM && hCur > hOther + options_.switchMarginM) {
            // The other foot has landed and this one lifts: it becomes the stance foot, held
            // where it is now.
            phase_ = other == 0 ? ContactPhase::LeftStance : ContactPhase::RightStance;
            point_ = pOther;
            anchor_ = here + r[static_cast<std::size_t>(pOther)];
            anchor_.y() = floorYM;
            ++stanceChanges_;
        } else if (pCur != point_) {
            // The foot rolls (heel to ball to toe): the new lowest point takes over where it is.
            anchor_ = here + r[static_cast<std::size_t>(pCur)];
            anchor_.y() = floorYM;
            point_ = pCur;
        }
        next = anchor_ - r[static_cast<std::size_t>(point_)];
        next.y() = floorYM - r[static_cast<std::size_t>(point_)].y();
        velocity_ = dtS > 0 ? Vec3d((next - root_) / dtS) : Vec3d::Zero();
    }
    root_ = next;
    const Vec3d shift = root_ - pose.positionM[0];
    for (auto& p : pose.positionM) {
        p += shift;
    }
}

}  // namespace caphub::body
