#include "fusion/body/root_tracker.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

#include "hal/core/angles.h"

namespace caphub::body {

namespace {

using S = Segment;

// Foot f's speed in the world by its own sensor, or -1 when its dead reckoning is not known.
double footSpeed(const FootSensorMotion& feet, std::size_t f) {
    return feet.known[f] ? feet.velocityMps[f].norm() : -1.0;
}

// Where foot f's sensor is on a pose (relative to the root while the pose's root is at the
// origin).
Vec3d footSensorOnPose(const Pose& pose, const FootSensorMotion& feet, std::size_t f) {
    return pointOnSegment(pose, idx(f == 0 ? S::LHindfoot : S::RHindfoot), feet.onFootM[f]);
}

// Where the seat point is on a pose: on the pelvis, below the middle of the hip joints.
Vec3d seatOnPose(const Pose& pose, const ContactOptions& options) {
    const Vec3d hips = 0.5 * (pose.positionM[idx(S::LThigh)] + pose.positionM[idx(S::RThigh)]);
    return hips + pose.qWorld[idx(S::Pelvis)] * options.seatBelowHipsM;
}

using Vec2d = Eigen::Vector2d;

double cross(const Vec2d& o, const Vec2d& a, const Vec2d& b) {
    return (a - o).x() * (b - o).y() - (a - o).y() * (b - o).x();
}

double distanceToSegment(const Vec2d& p, const Vec2d& a, const Vec2d& b) {
    const Vec2d ab = b - a;
    const double len2 = ab.squaredNorm();
    const double t = len2 > 0 ? std::clamp((p - a).dot(ab) / len2, 0.0, 1.0) : 0.0;
    return (p - (a + t * ab)).norm();
}

// How far p is from the convex hull of the n points (0 inside it).
double distanceToHull(const Vec2d& p, std::array<Vec2d, 8> pts, std::size_t n) {
    n = std::min(n, pts.size());
    if (n == 0) {
        return std::numeric_limits<double>::infinity();
    }
    const auto end = pts.begin() + static_cast<std::ptrdiff_t>(n);
    std::sort(pts.begin(), end, [](const Vec2d& a, const Vec2d& b) {
        return a.x() < b.x() || (a.x() == b.x() && a.y() < b.y());
    });
    // Andrew's monotone chain, counter-clockwise.
    std::array<Vec2d, 16> hull{};
    std::size_t h = 0;
    for (std::size_t i = 0; i < n; ++i) {
        while (h >= 2 && cross(hull[h - 2], hull[h - 1], pts[i]) <= 0) {
            --h;
        }
        hull[h++] = pts[i];
    }
    for (std::size_t i = n - 1, lower = h + 1; i-- > 0;) {
        while (h >= lower && cross(hull[h - 2], hull[h - 1], pts[i]) <= 0) {
            --h;
        }
        hull[h++] = pts[i];
    }
    if (h > 1) {
        --h;  // the last point is the first
    }
    if (h == 1) {
        return (p - hull[0]).norm();
    }
    bool inside = h >= 3;
    double nearest = std::numeric_limits<double>::infinity();
    for (std::size_t i = 0; i < h; ++i) {
        const Vec2d& a = hull[i];
        const Vec2d& b = hull[(i + 1) % h];
        inside = inside && cross(a, b, p) >= 0;
        nearest = std::min(nearest, distanceToSegment(p, a, b));
    }
    return inside ? 0.0 : nearest;
}

constexpr int kSeatPoint = 6;
constexpr int kLeftKneePoint = 7;
constexpr int kRightKneePoint = 8;

// The lowest of the feet's six points (heel, ball, toe tip of each).
int lowestPoint(const std::array<Vec3d, 6>& points) {
    int lowest = 0;
    for (int k = 1; k < 6; ++k) {
        if (points[static_cast<std::size_t>(k)].y() <
            points[static_cast<std::size_t>(lowest)].y()) {
            lowest = k;
        }
    }
    return lowest;
}

bool isSeat(int point) {
    return point == kSeatPoint;
}

bool isKnee(int point) {
    return point == kLeftKneePoint || point == kRightKneePoint;
}

bool isFoot(int point) {
    return point >= 0 && point < 6;
}

// Where the knees' contact points are on a pose (relative to the root while the pose's root is
// at the origin), left then right.
std::array<Vec3d, 2> kneesOnPose(const Pose& pose, const ContactOptions& options) {
    return {pointOnSegment(pose, idx(S::LCalf), options.kneeFrontM),
            pointOnSegment(pose, idx(S::RCalf), options.kneeFrontM)};
}

ContactPhase sideOf(int point) {
    const bool left = point < 3 || point == kLeftKneePoint;
    return left ? ContactPhase::LeftStance : ContactPhase::RightStance;
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
    const std::array<Vec3d, 2> knees = kneesOnPose(pose, options_);
    for (std::size_t i = 0; i < 2; ++i) {
        const double y = (knees[i] - old).y();
        if (y < lowest) {
            lowest = y;
            lowestIndex = i == 0 ? kLeftKneePoint : kRightKneePoint;
        }
    }
    root_ = Vec3d(rootXM, -lowest, rootZM);
    levels_[0] = 0;  // the floor
    levelCount_ = 1;
    takeoffLevelM_ = 0;
    stillForS_ = {0, 0};
    plantedFoot_ = -1;
    footSlow_ = {false, false};
    landedLevelM_ = {};
    velocity_.setZero();
    smoothVelocity_.setZero();
    fusedVelocity_.setZero();
    phase_ = sideOf(lowestIndex);
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
    if (isKnee(lowestIndex)) {
        anchor_ = knees[lowestIndex == kLeftKneePoint ? 0 : 1] + (root_ - old);
    } else {
        const int seg = idx(lowestIndex < 3 ? S::LHindfoot : S::RHindfoot);
        const auto& pts = lowestIndex < 3 ? d.leftFootPointM : d.rightFootPointM;
        anchor_ = pointOnSegment(pose, seg, pts[static_cast<std::size_t>(lowestIndex % 3)]);
    }
    anchor_.y() = 0;
    seatRelM_ = seatOnPose(pose, options_) - root_;
    for (std::size_t i = 0; i < 2; ++i) {
        kneeRelM_[i] = knees[i] - old;
    }
    offFeetS_ = 0;
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
    const Vec3d comRate = dtS > 0 ? Vec3d((comOffset - comOffset_) / dtS) : Vec3d::Zero();
    for (std::size_t f = 0; f < 2; ++f) {
        const bool still = footSensors != nullptr && footSensors->still[f];
        stillForS_[f] = still ? stillForS_[f] + dtS : 0;
    }
    // The seat relative to the root, and its velocity.
    const Vec3d seat = seatOnPose(pose, options_);
    const Vec3d seatVelocity = dtS > 0 ? Vec3d((seat - seatRelM_) / dtS) : Vec3d::Zero();
    const std::array<Vec3d, 2> knees = kneesOnPose(pose, options_);
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
    // held the root on the feet, which no longer carry it. Not from the seat: a body shifting
    // or bouncing on a seat reads free fall for a few hundredths of a second (on cmu_14_27's
    // stool, at 100 poses a second two frames of it), and the seat stays under it; the body
    // leaves the seat onto its feet (the seat stops qualifying), not into the air.
    if (phase_ != ContactPhase::Flight && !isSeat(point_) &&
        freeFallCount_ == options_.flightFrames) {
        phase_ = ContactPhase::Flight;
        point_ = -1;
        takeoffLevelM_ = anchor_.y();
        const Vec3d g(0, options_.gravityMps2, 0);
        com_ = takeoffCom_ + (takeoffComVelocity_ - 0.5 * g * freeFallS_) * freeFallS_;
        comVerticalVelocity_ = takeoffComVelocity_.y() - options_.gravityMps2 * freeFallS_;
        root_ = com_ - comOffset_;
    }

    Vec3d next = root_;
    if (phase_ == ContactPhase::Flight) {
        offFeetS_ = 0;
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
        if (next.y() + minY <= takeoffLevelM_ && comVerticalVelocity_ <= 0) {
            // Landing: the lowest foot point touches the level it took off from and becomes
            // the anchor.
            const int lowest = lowestPoint(r);
            next.y() = takeoffLevelM_ - minY;
            point_ = lowest;
            phase_ = lowest < 3 ? ContactPhase::LeftStance : ContactPhase::RightStance;
            anchor_ = next + r[static_cast<std::size_t>(lowest)];
            anchor_.y() = takeoffLevelM_;
            ++stanceChanges_;
        }
    } else {
        next = stanceStep(pose, feet, minY, footSensors, dtS, comOffset, comRate, seat,
                          seatVelocity, knees);
        if (force && dtS > 0 && !isSeat(point_)) {
            // Across, no faster a change of velocity than the pelvis accelerometer measures
            // allows (ContactOptions::contactStepMps): the excess is the held point slipping.
            // While the pelvis reads free fall the feet carry nothing, whatever touches the
            // floor: the accelerometer's prediction is taken whole.
            const Vec3d predicted = velocity_ + (*force - Vec3d(0, options_.gravityMps2, 0)) * dtS;
            Vec3d excess = (next - root_) / dtS - predicted;
            excess.y() = 0;
            const double size = excess.norm();
            const double bound = freeFallCount_ > 0 ? 0.0 : options_.contactStepMps;
            if (size > bound) {
                const Vec3d slip = excess * ((1 - bound / size) * dtS);
                next -= slip;
                anchor_ -= slip;
            }
        }
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
        comOffsetRate_ = comRate;
    }
    comOffset_ = comOffset;
    seatRelM_ = seat;
    kneeRelM_ = knees;
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

Vec3d RootTracker::stanceStep(const Pose& pose, const FootState& feet, double minY,
                              const FootSensorMotion* footSensors, double dtS,
                              const Vec3d& comOffset, const Vec3d& comRate, const Vec3d& seat,
                              const Vec3d& seatVelocity, const std::array<Vec3d, 2>& knees) {
    // The anchored point is the one predicted to move least in the world. Its velocity
    // relative to the root plus the (low-passed) root velocity predicts its world velocity;
    // only points near the floor qualify, and the seat while the subject sits. The anchor
    // is continuous across a change of point (the new point is held where it is now), so a
    // change never makes the root jump: drift comes only from holding a point that in truth
    // moves, which this choice minimises.
    const auto& r = feet.pointM;  // relative to the root
    // The knees' velocities relative to the root, and the lowest point of the feet and knees.
    std::array<Vec3d, 2> kneeVelocity{Vec3d::Zero(), Vec3d::Zero()};
    std::array<Vec3d, 8> points{};
    std::copy(r.begin(), r.end(), points.begin());
    double lowY = minY;
    for (std::size_t i = 0; i < 2; ++i) {
        if (dtS > 0) {
            kneeVelocity[i] = (knees[i] - kneeRelM_[i]) / dtS;
        }
        points[6 + i] = knees[i];
        lowY = std::min(lowY, knees[i].y());
    }
    auto kneeOf = [](int k) { return static_cast<std::size_t>(k - kLeftKneePoint); };
    const bool offFeet = seated(pose, points, lowY, comOffset, comRate);
    offFeetS_ = offFeet ? offFeetS_ + dtS : 0;
    const bool seatQualifies = offFeet && offFeetS_ >= options_.seatedForS - 1e-9;
    auto relative = [&](int k) -> Vec3d {
        return isSeat(k) ? seat : isKnee(k) ? knees[kneeOf(k)] : r[static_cast<std::size_t>(k)];
    };
    auto predictedSpeed = [&](int k) {
        const Vec3d v = isSeat(k)   ? seatVelocity
                        : isKnee(k) ? kneeVelocity[kneeOf(k)]
                                    : feet.velocityMps[static_cast<std::size_t>(k)];
        return (smoothVelocity_ + v).norm();
    };
    // While the seat carries the body no foot point does: the feet may hang or rest on a
    // rung, and the floor would pull the root down to them. Once the body is back over the
    // feet the seat no longer qualifies and the feet take over as before.
    const bool onSeat = isSeat(point_) && seatQualifies;
    // A foot point qualifies near the lowest foot point, or near the lowest point of a foot
    // at rest on something a level's step above it (a tread, a step).
    std::array<double, 2> footMinY{std::numeric_limits<double>::max(),
                                   std::numeric_limits<double>::max()};
    for (std::size_t k = 0; k < r.size(); ++k) {
        footMinY[k / 3] = std::min(footMinY[k / 3], r[k].y());
    }
    // Each foot's sole, the lower of its heel and ball: what the foot carrying the body stands
    // on its tread with. The rigid model's toe tip is left out: a loaded foot whose heel has
    // lifted stands on its ball with its toes bent along the tread or hanging over its edge,
    // where the rigid toe tip dips below the tread by centimetres (docs/skeleton.md, "Steps
    // and stairs").
    std::array<double, 2> soleY{};
    for (std::size_t f = 0; f < 2; ++f) {
        soleY[f] = std::min(r[3 * f].y(), r[3 * f + 1].y());
    }
    auto resting = [&](int k) {
        return stillForS_[static_cast<std::size_t>(k / 3)] >= options_.restingS - 1e-9;
    };
    const bool plantedNow =
        footSensors != nullptr && updatePlantedFoot(*footSensors, footMinY, soleY);
    auto qualifies = [&](int k) {
        if (isSeat(k)) {
            return seatQualifies;
        }
        if (isKnee(k)) {
            return !onSeat && knees[kneeOf(k)].y() - lowY <= options_.heightM &&
                   minY - lowY > options_.heightM;
        }
        if (plantedFoot_ == k / 3 && !onSeat &&
            r[static_cast<std::size_t>(k)].y() - footMinY[static_cast<std::size_t>(k / 3)] <=
                options_.heightM) {
            return true;
        }
        // A foot at rest takes the body on its own level when that is a step above the
        // lowest point, and keeps it there while it rests.
        const auto u = static_cast<std::size_t>(k);
        const bool onOtherLevel =
            footMinY[u / 3] - minY > options_.levelSnapM || (isFoot(point_) && point_ / 3 == k / 3);
        return !onSeat &&
               (r[u].y() - lowY <= options_.heightM ||
                (resting(k) && onOtherLevel && r[u].y() - footMinY[u / 3] <= options_.heightM));
    };
    // Where the held point puts the root: on the seat, where the seat is; on a foot, the
    // lowest foot point on the anchor's level, leaving out a foot below it (the other
    // foot below a tread's edge).
    auto placeOn = [&](int k) {
        Vec3d at = anchor_ - relative(k);
        if (!isSeat(k)) {
            // The lowest of the points on the held one's support (not below it by more
            // than heightM) stands on its level: the feet's and the knees'.
            const double y = relative(k).y();
            double lowest = y;
            for (std::size_t j = 0; j < points.size(); ++j) {
                // A planted foot is its own support: the other foot, swinging up past it, and
                // the knees are not.
                const bool ownFoot = !isFoot(k) || plantedFoot_ != k / 3 ||
                                     (j < r.size() && static_cast<int>(j / 3) == k / 3);
                if (ownFoot && points[j].y() >= y - options_.heightM) {
                    lowest = std::min(lowest, points[j].y());
                }
            }
            at.y() = anchor_.y() - lowest;
        }
        return at;
    };
    if (point_ < 0) {
        // Nothing held (a skeleton whose points came out not finite left none qualifying): the
        // lowest point, as at a landing.
        point_ = lowestPoint(r);
    }
    const Vec3d here = placeOn(point_);
    // The qualifying point among [from, to] predicted to move least, and its speed.
    auto leastMoving = [&](int from, int to) {
        std::pair<int, double> least{-1, std::numeric_limits<double>::max()};
        for (int k = from; k <= to; ++k) {
            if (qualifies(k) && predictedSpeed(k) < least.second) {
                least = {k, predictedSpeed(k)};
            }
        }
        return least;
    };
    auto [best, bestSpeed] = leastMoving(0, kRightKneePoint);
    // The body off its feet in a sitting posture is on the seat: the seat takes it at once,
    // whatever the feet do (one lifted to a rung moves less in the world than the seat
    // predicted from a root that the floor is pulling down with it).
    if (seatQualifies && !isSeat(point_)) {
        best = kSeatPoint;
        bestSpeed = -1;
    } else if (plantedNow) {
        // The planted foot takes the body now: its least moving point near its sole.
        best = leastMoving(3 * plantedFoot_, 3 * plantedFoot_ + 2).first;
        bestSpeed = -1;
    }
    // best < 0: no point qualifies (not finite): the held one stays.
    if (best >= 0 && best != point_ &&
        (!qualifies(point_) || bestSpeed < predictedSpeed(point_) - options_.switchMarginMps)) {
        if (isFoot(best) && isFoot(point_) && (best < 3) != (point_ < 3)) {
            ++stanceChanges_;
        }
        const int held = point_;
        point_ = best;
        phase_ = isSeat(best) ? ContactPhase::Seated : sideOf(best);
        // The new point's level: its height under the held point itself, not under the
        // lowest foot point (in a push-off the rigid foot's toe tip dips below the floor it
        // stands on, and would put a foot that is on the floor above it).
        double height = isSeat(held) ? here.y() + relative(best).y()
                                     : anchor_.y() - relative(held).y() + relative(best).y();
        // A foot that came to rest on another level (a tread above or below) while a foot
        // carried the body: the level it was measured on then (by the hand-over the held foot
        // has begun to lift, and the root with it).
        const std::optional<double>& landed =
            isFoot(best) ? landedLevelM_[static_cast<std::size_t>(best / 3)]
                         : std::optional<double>();
        const bool onOtherTread = isFoot(held) && isFoot(best) && best / 3 != held / 3 && landed &&
                                  std::abs(*landed - anchor_.y()) > options_.heightM;
        if (onOtherTread) {
            height = *landed;
        }
        anchor_ = here + relative(best);
        if (isKnee(best)) {
            // A knee takes the body where it is: on a known level within levelSnapM of it (the
            // floor, a step), else on a level of its own (a bench, a chair's seat).
            anchor_.y() = supportLevel(height, true, false);
        } else if (isFoot(best)) {
            // Landing: the new point's foot, by its own sensor, is not swinging.
            const double v = footSensors != nullptr
                                 ? footSpeed(*footSensors, static_cast<std::size_t>(best / 3))
                                 : -1.0;
            const bool landing = v >= 0 && v <= options_.swingMps;
            anchor_.y() = supportLevel(
                height, resting(best) || plantedFoot_ == best / 3 || onOtherTread, landing);
        }
        if (plantedFoot_ >= 0 && (!isFoot(best) || best / 3 != plantedFoot_)) {
            plantedFoot_ = -1;  // the body left it
        }
    }
    // The anchored point slips when its foot, rolling off the floor, moves in the world:
    // the foot's dead reckoning says by how much (the foot is rigid: the point's velocity
    // is the sensor's plus the rate crossed with the lever from the sensor to the point).
    const int foot = point_ < 3 ? 0 : 1;
    const auto uf = static_cast<std::size_t>(foot);
    if (isFoot(point_) && footSensors != nullptr &&
        (footSensors->valid[uf] || slidingLate(*footSensors, uf)) && !footSensors->still[uf] &&
        dtS > 0) {
        const Vec3d sensor = footSensorOnPose(pose, *footSensors, uf);
        const Vec3d slip =
            footSensors->velocityMps[uf] +
            footSensors->rateRadS[uf].cross(r[static_cast<std::size_t>(point_)] - sensor);
        anchor_.x() += slip.x() * dtS;  // along the floor
        anchor_.z() += slip.z() * dtS;
    }
    return placeOn(point_);
}

bool RootTracker::seated(const Pose& pose, const std::array<Vec3d, 8>& points, double minY,
                         const Vec3d& com, const Vec3d& comVelocityAboutRoot) const {
    const double cosMax = std::cos(options_.seatedThighDeg * hal::kDegToRad);
    for (const S thigh : {S::LThigh, S::RThigh}) {
        // The thigh's axis points down its segment frame's -y.
        const Vec3d axis = pose.qWorld[static_cast<std::size_t>(idx(thigh))] * Vec3d(0, -1, 0);
        if (-axis.y() > cosMax) {
            return false;
        }
    }
    // Off its feet: the centre of mass further across from the support of the feet and knees
    // (the hull of their points near the floor) than half a foot's width. Standing, squatting,
    // crouching or kneeling, the body keeps its centre of mass over its support or it falls.
    std::array<Vec2d, 8> support{};
    std::size_t n = 0;
    for (const Vec3d& p : points) {
        if (p.y() - minY <= options_.heightM && p.allFinite()) {
            support[n++] = Vec2d(p.x(), p.z());
        }
    }
    // Moving, the extrapolated centre of mass (Hof 2005: the centre of mass plus its velocity
    // over the pendulum's eigenfrequency sqrt(g / l)) is what must stay over the feet: landing a
    // forward jump the centre of mass is behind the feet but on its way over them.
    const Vec3d comVelocity = smoothVelocity_ + comVelocityAboutRoot;
    const double legM = std::max(com.y() - minY, 0.1);
    const Vec3d xcom = com + comVelocity * std::sqrt(legM / options_.gravityMps2);
    if (n == 0 || !xcom.allFinite()) {
        return false;  // nothing to say (a pose that is not finite)
    }
    return distanceToHull(Vec2d(xcom.x(), xcom.z()), support, n) > options_.offFeetM;
}

bool RootTracker::slidingLate(const FootSensorMotion& footSensors, std::size_t f) const {
    const Vec3d& v = footSensors.velocityMps[f];
    return footSensors.known[f] && std::hypot(v.x(), v.z()) > options_.swingMps &&
           std::abs(v.y()) < options_.slideVerticalMps &&
           std::hypot(smoothVelocity_.x(), smoothVelocity_.z()) < options_.slideBodyMps;
}

bool RootTracker::updatePlantedFoot(const FootSensorMotion& footSensors,
                                    const std::array<double, 2>& footMinY,
                                    const std::array<double, 2>& soleY) {
    auto speed = [&](std::size_t f) { return footSpeed(footSensors, f); };
    const bool onFoot = isFoot(point_);
    // Each foot's level as it comes to rest while the other carries the body: the held foot's,
    // and the rise from the held foot's sole to the resting foot's lowest point (it has just
    // come down on it), a tread's height, before the held foot lifts.
    for (std::size_t f = 0; f < 2; ++f) {
        const double v = speed(f);
        const bool slow = v >= 0 && v < options_.plantedMps;
        if (slow && !footSlow_[f] && onFoot && static_cast<std::size_t>(point_ / 3) != f) {
            landedLevelM_[f] = anchor_.y() + footMinY[f] - soleY[1 - f];
        } else if (!slow) {
            landedLevelM_[f].reset();
        }
        footSlow_[f] = slow;
    }
    if (plantedFoot_ >= 0 && speed(static_cast<std::size_t>(plantedFoot_)) > options_.swingMps) {
        plantedFoot_ = -1;
    }
    if (!onFoot) {
        return false;
    }
    // The held foot swinging while the other, on another level, stands still: a step onto a
    // tread (the trailing foot leaves the one below).
    const auto held = static_cast<std::size_t>(point_ / 3);
    const std::size_t other = 1 - held;
    const double standing = speed(other);
    if (plantedFoot_ == static_cast<int>(other) || speed(held) <= options_.swingMps ||
        standing < 0 || standing >= options_.plantedMps ||
        std::abs(footMinY[other] - footMinY[held]) <= options_.heightM) {
        return false;
    }
    plantedFoot_ = static_cast<int>(other);
    return true;
}

double RootTracker::supportLevel(double heightM, bool resting, bool landing) {
    std::size_t nearest = 0;
    std::size_t below = 0;  // the floor when no other is below (and is above: see below)
    for (std::size_t i = 0; i < levelCount_; ++i) {
        if (std::abs(levels_[i] - heightM) < std::abs(levels_[nearest] - heightM)) {
            nearest = i;
        }
        if (levels_[i] <= heightM && (levels_[below] > heightM || levels_[i] > levels_[below])) {
            below = i;
        }
    }
    if (std::abs(levels_[nearest] - heightM) <= options_.levelSnapM) {
        return levels_[nearest];
    }
    if (!resting && levels_[below] <= heightM) {
        return levels_[below];  // no evidence of a support where it is
    }
    // Below every known level (walking down from where the capture began): a foot landing
    // there, by its own sensor, stands on a new level; without that evidence the lowest known
    // one, never one above it.
    if (!resting && !landing) {
        return levels_[nearest];
    }
    // A new level; when they are all taken the oldest but the floor makes room.
    if (levelCount_ == kLevels) {
        std::rotate(levels_.begin() + 1, levels_.begin() + 2, levels_.end());
        --levelCount_;
    }
    levels_[levelCount_++] = heightM;
    return heightM;
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
