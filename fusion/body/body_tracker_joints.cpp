// The body tracker's headings from the joints (BodyTrackerOptions::jointHeading): the links
// between sensors, their samples into JointHeading, and the turns of the free headings they give.
// docs/body-calibration.md, "Headings from the joints".
#include <algorithm>
#include <cmath>
#include <numbers>

#include "fusion/body/body_tracker.h"

namespace caphub::body {

void BodyTracker::buildJointLinks(const Dimensions& dims) {
    for (std::size_t i = 0; i < sensors_.size(); ++i) {
        const int seg = idx(sensors_[i].segment);
        // The nearest segment above with a sensor; the joint is this segment's origin, where it
        // sits in that segment's frame through any segment between without one (the lumbar
        // and neck's derived joints: their turns taken as in the reference pose, which moves the
        // point by a centimetre or two in a walk, where the trunk turns slowly).
        Vec3d offset = dims.offsetM[static_cast<std::size_t>(seg)];
        int above = parentOf(seg);
        while (above >= 0 && sensorOfSegment_[static_cast<std::size_t>(above)] < 0) {
            offset += dims.offsetM[static_cast<std::size_t>(above)];
            above = parentOf(above);
        }
        if (above < 0) {
            continue;
        }
        const int parent = sensorOfSegment_[static_cast<std::size_t>(above)];
        JointLink l;
        l.parent = parent;
        l.child = static_cast<int>(i);
        l.rParentSegment = offset - sensors_[static_cast<std::size_t>(parent)].positionM;
        l.rChildSegment = -sensors_[i].positionM;
        l.heading = JointHeading(options_.jointHeadingOptions);
        links_.push_back(l);
    }
    linksOf_.assign(sensors_.size(), {});
    for (std::size_t k = 0; k < links_.size(); ++k) {
        linksOf_[static_cast<std::size_t>(links_[k].parent)].push_back(k);
        linksOf_[static_cast<std::size_t>(links_[k].child)].push_back(k);
    }
    jointGroup_.resize(sensors_.size());
    for (std::size_t i = 0; i < sensors_.size(); ++i) {
        jointGroup_[i] = static_cast<int>(i);
    }
    for (bool changed = true; changed;) {  // the least index of each connected group
        changed = false;
        for (const JointLink& l : links_) {
            auto& a = jointGroup_[static_cast<std::size_t>(l.parent)];
            auto& b = jointGroup_[static_cast<std::size_t>(l.child)];
            if (a != b) {
                a = b = std::min(a, b);
                changed = true;
            }
        }
    }
}

void BodyTracker::addJointSample(std::size_t sensor, const SensorUpdate& u,
                                 const Eigen::Quaternionf& q) {
    const CalibrationMethod method = calibration_.method;
    if (!calibrationInput_ ||
        (method != CalibrationMethod::TPose && method != CalibrationMethod::NPose)) {
        return;
    }
    JointInput& in = jointInputs_[sensor];
    const JointInput::Sample now{u.t, q.cast<double>(), u.specificForceMps2.cast<double>(),
                                 u.rateRadS.cast<double>()};
    const JointInput::Sample oldest = in.before[0];
    in.before[0] = in.before[1];
    in.before[1] = now;
    in.count = std::min(in.count + 1, 3);
    if (in.count < 3) {
        return;
    }
    // The middle sample, its angular acceleration the central difference about it.
    const JointInput::Sample& mid = in.before[0];
    const double span = toSeconds(now.t - oldest.t);
    if (span <= 0 || span > 0.1) {
        return;
    }
    const Vec3d& w = mid.rateRadS;
    const Vec3d wDot = (now.rateRadS - oldest.rateRadS) / span;
    const Vec3d& f = mid.forceMps2;
    const Quatd& qd = mid.q;
    const double tS = toSeconds(mid.t.time_since_epoch());
    const auto seg = static_cast<std::size_t>(idx(sensors_[sensor].segment));
    const Quatd sensorFromSegment = calibration_.mounting[seg].conjugate();
    for (const std::size_t k : linksOf_[sensor]) {
        JointLink& l = links_[k];
        const bool asChild = l.child == static_cast<int>(sensor);
        const Vec3d r = sensorFromSegment * (asChild ? l.rChildSegment : l.rParentSegment);
        // The specific force at the joint centre: the sensor's, and the rigid segment's turning
        // carried over the lever arm.
        const Vec3d joint = f + wDot.cross(r) + w.cross(w.cross(r));
        l.heading.add(asChild ? JointHeading::Child : JointHeading::Parent, tS, qd * joint);
        if (!asChild) {
            continue;
        }
        // Turned once the angle is known and more than a quarter degree (each turn re-sets the
        // solver's calibration).
        const std::optional<double> angle = l.heading.angleRad();
        if (!angle || std::abs(*angle) <= kMinJointTurnRad) {
            continue;
        }
        correctFromJoint(l, *angle);
    }
}

void BodyTracker::correctFromJoint(const JointLink& l, double angleRad) {
    // The child's heading is off the parent's by the angle: the free one of the two turns (the
    // child when both are).
    const auto freeNow = [this](std::size_t i) {
        return has(calibration_.freeHeading & calibration_.mask, idx(sensors_[i].segment));
    };
    const auto child = static_cast<std::size_t>(l.child);
    const auto parent = static_cast<std::size_t>(l.parent);
    std::size_t turned = child;
    double by = -angleRad;
    if (!freeNow(child)) {
        if (!freeNow(parent)) {
            return;
        }
        turned = parent;
        by = angleRad;
    }
    if (std::abs(jointTurn_[turned] + by) > options_.maxJointTurnRad) {
        return;
    }
    std::fill(turnScratch_.begin(), turnScratch_.end(), 0.0);
    turnScratch_[turned] = by;
    // A group whose headings are all free has no heading of its own: its mean stays where the
    // calibration put it (the nominal mountings', whose straps' turns about the vertical average
    // out over the group) rather than going to one sensor's strap.
    // The members are the group's sensors that report now: one that is out (lost) has a frame
    // of its own when it comes back, which its share would only move.
    const int group = jointGroup_[turned];
    const SegmentMask lost = calibrationInput_ ? calibrationInput_->lost : 0;
    const auto member = [&](std::size_t k) {
        return jointGroup_[k] == group && online_[k] && !has(lost, idx(sensors_[k].segment));
    };
    int members = 0;
    bool allFree = true;
    for (std::size_t k = 0; k < sensors_.size(); ++k) {
        if (member(k)) {
            ++members;
            allFree = allFree && freeNow(k);
        }
    }
    if (allFree && members > 1) {
        for (std::size_t k = 0; k < sensors_.size(); ++k) {
            if (member(k)) {
                turnScratch_[k] -= by / members;
            }
        }
    }
    turnFreeHeadings(turnScratch_);
}

void BodyTracker::resetJointHeadings() {
    for (JointLink& l : links_) {
        l.heading.reset();
    }
}

void BodyTracker::turnFreeHeadings(const std::vector<double>& turns) {
    for (std::size_t i = 0; i < sensors_.size(); ++i) {
        const double angleRad = turns[i];
        const Segment segment = sensors_[i].segment;
        if (angleRad == 0 || !has(calibration_.freeHeading & calibration_.mask, idx(segment))) {
            continue;
        }
        const auto seg = static_cast<std::size_t>(idx(segment));
        turnMounting(segment, angleRad);
        calibration_.headingTurnRad[seg] =
            std::remainder(calibration_.headingTurnRad[seg] + angleRad, 2 * std::numbers::pi);
        jointTurn_[i] += angleRad;
        for (const std::size_t k : linksOf_[i]) {
            JointLink& l = links_[k];
            l.heading.turn(
                l.child == static_cast<int>(i) ? JointHeading::Child : JointHeading::Parent,
                angleRad);
        }
    }
    applyHeadingTurns(FootOnTurn::Turn);
    solver_.setCalibration(calibration_);
}

}  // namespace caphub::body
