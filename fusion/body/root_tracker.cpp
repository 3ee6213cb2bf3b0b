#include "fusion/body/root_tracker.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace caphub::body {

namespace {

using S = Segment;

// Where foot f's sensor is on a pose (relative to the root while the pose's root is at the
// origin).
Vec3d footSensorOnPose(const Pose& pose, const FootSensorMotion& feet, std::size_t f) {
    return pointOnSegment(pose, idx(f == 0 ? S::LHindfoot : S::RHindfoot), feet.onFootM[f]);
}

}  // namespace

void footState(const Dimensions& d, const Pose& pose, const ChainJacobian& left,
               const ChainJacobian& right, const JointRates& rates, FootState& out) {
    for (int foot = 0; foot < 2; ++foot) {
        const int seg = idx(foot == 0 ? S::LHindfoot : S::RHindfoot);
        const auto& pts = foot == 0 ? d.leftFootPointM : d.rightFootPointM;
        const ChainJacobian& jac = foot == 0 ? left : right;
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

Vec3d centreOfMassOffsetM(const Dimensions& d, const Pose& pose) {
    Vec3d sum = Vec3d::Zero();
    double total = 0;
    for (std::size_t i = 0; i < static_cast<std::size_t>(kSegmentCount); ++i) {
        const double f = d.massFraction[i];
        if (f > 0) {
            sum += f * (pose.positionM[i] + pose.qWorld[i] * d.centreOfMassM[i]);
            total += f;
        }
    }
    return total > 0 ? Vec3d(sum / total - pose.positionM[0]) : Vec3d::Zero();
}

void footState(const Dimensions& d, const Pose& pose, const JointRates& rates, FootState& out) {
    ChainJacobian left;
    ChainJacobian right;
    spatialJacobian(pose, idx(S::LHindfoot), d.leftFootPointM[1], left);
    spatialJacobian(pose, idx(S::RHindfoot), d.rightFootPointM[1], right);
    footState(d, pose, left, right, rates, out);
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
    smoothVelocity_.setZero();
    fusedVelocity_.setZero();
    phase_ = lowestIndex < 3 ? ContactPhase::LeftStance : ContactPhase::RightStance;
    point_ = lowestIndex;
    freeFallCount_ = 0;
    stanceChanges_ = 0;
    comHistoryCount_ = 0;
    comOffset_ = centreOfMassOffsetM(d, pose);
    comOffsetRate_.setZero();
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
                         const std::optional<Vec3d>& rootSpecificForceMps2,
                         const FootSensorMotion* footSensors) {
    if (!started_) {
        reset(d, pose);
        return;
    }
    const auto& r = feet.pointM;  // relative to the root
    double minY = std::numeric_limits<double>::max();
    for (const Vec3d& p : r) {
        minY = std::min(minY, p.y());
    }

    const auto& force = rootSpecificForceMps2;
    // Free fall: the vertical specific force is about zero. Not its whole size: in the air a
    // pelvis sensor still reads several m/s^2 across (the pelvis turns about the centre of mass
    // as the legs tuck and swing), which no support gives.
    freeFallCount_ = force && force->y() < options_.freeFallMps2 ? freeFallCount_ + 1 : 0;
    const Vec3d comOffset = centreOfMassOffsetM(d, pose);
    if (freeFallCount_ == 1) {
        // The take-off was during this frame, so the root's state at its start (the feet, now
        // unloaded, stop carrying the root, and they rarely leave the floor at a frame's start).
        // Up, the root's velocity (the pelvis accelerometer's over the push-off's end) plus the
        // centre of mass' own move about the root then; across, the centre of mass' mean.
        freeFallS_ = 0;
        takeoffComVelocity_ = takeoffHorizontalComVelocity();
        takeoffComVelocity_.y() = fusedVelocity_.y() + comOffsetRate_.y();
        takeoffCom_ = comHistoryCount_ > 0 ? comHistory_[comHistoryHead_].positionM
                                           : Vec3d(root_ + comOffset_);
    }
    // Flight starts once per free fall: a landing while the accelerometer still reads free fall
    // (a take-off velocity a little low) stays landed. It starts where the ballistic path from
    // the take-off has got to by the previous frame: the frames that confirmed the free fall
    // held the root on the feet, which no longer carry it.
    if (phase_ != ContactPhase::Flight && freeFallCount_ == options_.flightFrames) {
        phase_ = ContactPhase::Flight;
        point_ = -1;
        const Vec3d g(0, options_.gravityMps2, 0);
        com_ = takeoffCom_ + (takeoffComVelocity_ - 0.5 * g * freeFallS_) * freeFallS_;
        comVerticalVelocity_ = takeoffComVelocity_.y() - options_.gravityMps2 * freeFallS_;
        root_ = com_ - comOffset_;
    }

    Vec3d next = root_;
    if (phase_ == ContactPhase::Flight) {
        // Exact for constant gravity: the centre of mass' path is a parabola (horizontally it
        // keeps its take-off velocity), and the root is where the body's shape puts it from
        // there: legs tucked in the air lift the centre of mass towards the root.
        com_.x() += takeoffComVelocity_.x() * dtS;
        com_.z() += takeoffComVelocity_.z() * dtS;
        com_.y() += comVerticalVelocity_ * dtS - 0.5 * options_.gravityMps2 * dtS * dtS;
        comVerticalVelocity_ -= options_.gravityMps2 * dtS;
        next = com_ - comOffset;
        // Across, the feet's own sensors, while their dead reckoning holds, say where the body
        // goes better than the take-off velocity: the root moves as each foot sensor moves in
        // the world, less its move relative to the root (the pose's), averaged over the feet.
        if (footSensors != nullptr && footSensorsKnown_) {
            Vec3d step = Vec3d::Zero();
            int feetValid = 0;
            for (std::size_t f = 0; f < 2; ++f) {
                if (footSensors->valid[f]) {
                    step += footSensors->velocityMps[f] * dtS -
                            (footSensorOnPose(pose, *footSensors, f) - footSensorRelM_[f]);
                    ++feetValid;
                }
            }
            if (feetValid > 0) {
                next.x() = root_.x() + step.x() / feetValid;
                next.z() = root_.z() + step.z() / feetValid;
                com_.x() = next.x() + comOffset.x();
                com_.z() = next.z() + comOffset.z();
            }
        }
        if (dtS > 0) {
            velocity_ = (next - root_) / dtS;
        }
        if (next.y() + minY <= floorYM && comVerticalVelocity_ <= 0) {
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
            ++stanceChanges_;
        }
    } else {
        // The anchored point is the one predicted to move least in the world. Its velocity
        // relative to the root plus the (low-passed) root velocity predicts its world velocity;
        // only points near the floor qualify. The anchor is continuous across a change of point
        // (the new point is held where it is now), so a change never makes the root jump: drift
        // comes only from holding a point that in truth moves, which this choice minimises.
        const Vec3d here = anchor_ - r[static_cast<std::size_t>(point_)];
        auto predictedSpeed = [&](int k) {
            return (smoothVelocity_ + feet.velocityMps[static_cast<std::size_t>(k)]).norm();
        };
        int best = -1;
        double bestSpeed = std::numeric_limits<double>::max();
        for (int k = 0; k < 6; ++k) {
            if (r[static_cast<std::size_t>(k)].y() - minY > options_.heightM) {
                continue;
            }
            const double v = predictedSpeed(k);
            if (v < bestSpeed) {
                bestSpeed = v;
                best = k;
            }
        }
        const bool currentQualifies =
            r[static_cast<std::size_t>(point_)].y() - minY <= options_.heightM;
        if (best != point_ &&
            (!currentQualifies || bestSpeed < predictedSpeed(point_) - options_.switchMarginMps)) {
            if ((best < 3) != (point_ < 3)) {
                ++stanceChanges_;
            }
            point_ = best;
            phase_ = best < 3 ? ContactPhase::LeftStance : ContactPhase::RightStance;
            anchor_ = here + r[static_cast<std::size_t>(best)];
        }
        // The anchored point slips when its foot, rolling off the floor, moves in the world:
        // the foot's dead reckoning says by how much (the foot is rigid: the point's velocity
        // is the sensor's plus the rate crossed with the lever from the sensor to the point).
        const int foot = point_ < 3 ? 0 : 1;
        const auto uf = static_cast<std::size_t>(foot);
        if (footSensors != nullptr && footSensors->valid[uf] && !footSensors->still[uf] &&
            dtS > 0) {
            const Vec3d sensor = footSensorOnPose(pose, *footSensors, uf);
            const Vec3d slip =
                footSensors->velocityMps[uf] +
                footSensors->rateRadS[uf].cross(r[static_cast<std::size_t>(point_)] - sensor);
            anchor_.x() += slip.x() * dtS;  // along the floor
            anchor_.z() += slip.z() * dtS;
        }
        next = anchor_ - r[static_cast<std::size_t>(point_)];
        next.y() = floorYM - minY;  // the lowest foot point stands on the floor
        velocity_ = dtS > 0 ? Vec3d((next - root_) / dtS) : Vec3d::Zero();
    }
    if (dtS > 0) {
        const double a = dtS / (options_.velocityTimeConstantS + dtS);
        smoothVelocity_ += a * (velocity_ - smoothVelocity_);
    }
    if (force && dtS > 0) {
        // Complementary: the accelerometer over short times, the contacts over long ones.
        fusedVelocity_ += (*force - Vec3d(0, options_.gravityMps2, 0)) * dtS;
        fusedVelocity_ +=
            dtS / (options_.takeoffTimeConstantS + dtS) * (velocity_ - fusedVelocity_);
    } else {
        fusedVelocity_ = velocity_;
    }
    root_ = next;
    if (dtS > 0) {
        comOffsetRate_ = (comOffset - comOffset_) / dtS;
    }
    comOffset_ = comOffset;
    footSensorsKnown_ = footSensors != nullptr;
    if (footSensorsKnown_) {
        for (std::size_t f = 0; f < 2; ++f) {
            footSensorRelM_[f] = footSensorOnPose(pose, *footSensors, f);
        }
    }
    if (phase_ == ContactPhase::Flight) {
        comHistoryCount_ = 0;
    } else {
        comHistoryHead_ = (comHistoryHead_ + 1) % kComHistory;
        comHistory_[comHistoryHead_] = ComSample{root_ + comOffset, dtS};
        comHistoryCount_ = std::min(comHistoryCount_ + 1, kComHistory);
    }
    if (freeFallCount_ > 0) {
        freeFallS_ += dtS;
    }
    const Vec3d shift = root_ - pose.positionM[0];
    for (auto& p : pose.positionM) {
        p += shift;
    }
}

Vec3d RootTracker::takeoffHorizontalComVelocity() const {
    // The mean over the window: the centre of mass' way from the frame that starts it to the
    // latest one in stance. Too short a stance for a frame's difference: the root's velocity.
    auto back = [&](std::size_t k) -> const ComSample& {
        return comHistory_[(comHistoryHead_ + kComHistory - k) % kComHistory];
    };
    double spanS = 0;
    std::size_t k = 1;
    for (; k < comHistoryCount_; ++k) {
        spanS += back(k - 1).dtS;
        if (spanS >= options_.takeoffWindowS - 1e-9) {
            break;
        }
    }
    if (k >= comHistoryCount_) {
        --k;
    }
    if (k == 0 || spanS <= 0) {
        return Vec3d(fusedVelocity_.x(), 0, fusedVelocity_.z());
    }
    const Vec3d v = (back(0).positionM - back(k).positionM) / spanS;
    return Vec3d(v.x(), 0, v.z());
}

}  // namespace caphub::body
