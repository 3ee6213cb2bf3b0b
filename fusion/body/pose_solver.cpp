#include "fusion/body/pose_solver.h"

#include <algorithm>
#include <cmath>

#include "hal/core/angles.h"

namespace caphub::body {

namespace {

using S = Segment;

// The spine from the root up: the chain whose unsensored members share the rotation between
// the nearest sensors around them.
constexpr std::array<S, 5> kSpineChain = {S::Pelvis, S::L5, S::T12, S::C7, S::Skull};

using hal::kRadToDeg;

}  // namespace

PoseSolver::PoseSolver(SegmentMask sensors, const PoseSolverOptions& options)
    : sensors_(sensors), options_(options) {
    inverseMounting_.fill(Quatd::Identity());
    for (int i = 0; i < kSegmentCount; ++i) {
        rules_[static_cast<std::size_t>(i)] =
            has(sensors, i) ? SegmentRule::Sensor : SegmentRule::FollowParent;
    }
    // Spine: each unsensored member between two sensored ones takes its share, in proportion to
    // the number of joints, of the rotation between them.
    for (std::size_t a = 0; a < kSpineChain.size(); ++a) {
        if (!has(sensors, idx(kSpineChain[a]))) {
            continue;
        }
        std::size_t b = a + 1;
        while (b < kSpineChain.size() && !has(sensors, idx(kSpineChain[b]))) {
            ++b;
        }
        if (b == kSpineChain.size()) {
            break;
        }
        for (std::size_t m = a + 1; m < b; ++m) {
            const auto u = static_cast<std::size_t>(idx(kSpineChain[m]));
            rules_[u] = SegmentRule::SpineShare;
            shares_[u] = {idx(kSpineChain[a]), idx(kSpineChain[b]),
                          static_cast<double>(m - a) / static_cast<double>(b - a)};
        }
    }
    if (!has(sensors, idx(S::Pelvis))) {
        for (S s : kSpineChain) {
            if (has(sensors, idx(s))) {
                rootSource_ = idx(s);
                break;
            }
        }
    }
    // Coverage: a segment without a sensor is measured when it is the one link missing between
    // two sensors (its parent's and a child's), or an end segment on a sensor's segment.
    std::array<bool, kSegmentCount> sensorChild{};
    std::array<bool, kSegmentCount> hasChild{};
    for (int i = 1; i < kSegmentCount; ++i) {
        const auto p = static_cast<std::size_t>(parentOf(i));
        hasChild[p] = true;
        sensorChild[p] = sensorChild[p] || has(sensors, i);
    }
    for (int i = 0; i < kSegmentCount; ++i) {
        const auto u = static_cast<std::size_t>(i);
        bool covered = false;
        if (i == 0) {
            covered = has(sensors, 0) || rootSource_ >= 0;
        } else if (rules_[u] != SegmentRule::FollowParent) {
            covered = true;
        } else {
            covered = has(sensors, parentOf(i)) && (sensorChild[u] || !hasChild[u]);
        }
        if (covered) {
            covered_ |= SegmentMask{1} << i;
        } else if (i > 0) {
            // Held in the neutral standing pose (the N-pose: arms hanging), not the T-pose.
            held_[u] = referenceOrientation(ReferencePoseKind::N, static_cast<Segment>(parentOf(i)))
                           .conjugate() *
                       referenceOrientation(ReferencePoseKind::N, static_cast<Segment>(i));
        }
    }
}

void PoseSolver::setCalibration(const BodyCalibration& cal) {
    cal_ = cal;
    qWorldEnu_ = cal.qEnuWorld().conjugate();
    for (int i = 0; i < kSegmentCount; ++i) {
        inverseMounting_[static_cast<std::size_t>(i)] =
            cal.mounting[static_cast<std::size_t>(i)].conjugate();
    }
}

void PoseSolver::solve(const SensorFrame& frame, Pose& pose, JointLimitReport* report) const {
    // Sensor-driven segments: q_world_segment = q_world_ENU q_ENU_sensor q_segment_sensor^-1.
    for (int i = 0; i < kSegmentCount; ++i) {
        const auto u = static_cast<std::size_t>(i);
        if (rules_[u] == SegmentRule::Sensor) {
            pose.qWorld[u] = (qWorldEnu_ * frame.qEnuSensor[u] * inverseMounting_[u]).normalized();
        }
    }
    if (rules_[0] != SegmentRule::Sensor) {
        pose.qWorld[0] = rootSource_ >= 0 ? pose.qWorld[static_cast<std::size_t>(rootSource_)]
                                          : Quatd::Identity();
    }
    // The rest, parents first.
    for (int i = 1; i < kSegmentCount; ++i) {
        const auto u = static_cast<std::size_t>(i);
        const auto p = static_cast<std::size_t>(parentOf(i));
        switch (rules_[u]) {
            case SegmentRule::Sensor:
                break;
            case SegmentRule::FollowParent:
                pose.qWorld[u] = pose.qWorld[p] * held_[u];
                break;
            case SegmentRule::SpineShare: {
                const Share& sh = shares_[u];
                const Quatd& qa = pose.qWorld[static_cast<std::size_t>(sh.from)];
                const Quatd rel = qa.conjugate() * pose.qWorld[static_cast<std::size_t>(sh.to)];
                pose.qWorld[u] = qa * fromRotationVector<double>(logUnit(rel) * sh.fraction);
                break;
            }
        }
    }
    localFromWorld(pose);
    if (report == nullptr) {
        return;
    }
    report->violations = 0;
    report->excessDeg[0] = 0;
    for (int i = 1; i < kSegmentCount; ++i) {
        const auto u = static_cast<std::size_t>(i);
        if (options_.clampToLimits) {
            // Clamping a parent changes its world orientation; the child's sensor still says
            // where the child is, so its joint rotation is taken against the clamped parent.
            pose.qLocal[u] =
                pose.qWorld[static_cast<std::size_t>(parentOf(i))].conjugate() * pose.qWorld[u];
        }
        const double e =
            applyJointLimits(joints()[u].limits, pose.qLocal[u], options_.clampToLimits);
        report->excessDeg[u] = e;
        report->violations += e > 0 ? 1 : 0;
        if (options_.clampToLimits && e > 0) {
            pose.qWorld[u] = pose.qWorld[static_cast<std::size_t>(parentOf(i))] * pose.qLocal[u];
        }
    }
}

SegmentMask PoseSolver::validSegments(SegmentMask present) const {
    SegmentMask valid = 0;
    const auto mark = [&valid](int i, bool v) {
        if (v) {
            valid |= SegmentMask{1} << i;
        }
    };
    // The root: its own sensor, the spine segment it follows, or (no spine sensor at all) the
    // fixed upright orientation, which no missing sensor affects.
    if (rules_[0] == SegmentRule::Sensor) {
        mark(0, has(present, 0));
    } else {
        mark(0, rootSource_ < 0 || has(present, rootSource_));
    }
    // Parents come first, so a follower's parent is decided before it.
    for (int i = 1; i < kSegmentCount; ++i) {
        const auto u = static_cast<std::size_t>(i);
        switch (rules_[u]) {
            case SegmentRule::Sensor:
                mark(i, has(present, i));
                break;
            case SegmentRule::FollowParent:
                mark(i, has(valid, parentOf(i)));
                break;
            case SegmentRule::SpineShare:
                mark(i, has(present, shares_[u].from) && has(present, shares_[u].to));
                break;
        }
    }
    return valid & covered_;
}

double applyJointLimits(const JointLimits& limits, Quatd& qLocal, bool clamp) {
    // Most joints are well inside their limits in most frames: bound the rotation vector and
    // skip the logarithm when the whole bound is inside. For a unit quaternion with w > 0 it is
    // the vector part times 2 atan(s / w) / s, a factor between 2 w and 2 / w (sin h cos h <=
    // h <= tan h for the half angle h); the bound is widened by 1e-9 for rounding (the
    // quaternion's norm is 1 within 1e-15).
    const double sign = qLocal.w() < 0 ? -1.0 : 1.0;
    const double w = qLocal.w() * sign;
    if (w > 0.5) {
        const Vec3d v = qLocal.vec() * (sign * kRadToDeg);
        const Vec3d a = v * (2.0 * w * (1 - 1e-9));
        const Vec3d b = v * (2.0 / w * (1 + 1e-9));
        if ((a.cwiseMin(b).array() >= limits.minDeg.array()).all() &&
            (a.cwiseMax(b).array() <= limits.maxDeg.array()).all()) {
            return 0.0;
        }
    }
    const Vec3d rvDeg = logUnit(qLocal) * kRadToDeg;  // logUnit does not depend on the norm
    const Vec3d clamped = rvDeg.cwiseMax(limits.minDeg).cwiseMin(limits.maxDeg);
    const double excess = (rvDeg - clamped).norm();
    if (clamp && excess > 0) {
        qLocal = fromRotationVector<double>(clamped / kRadToDeg);
    }
    return excess;
}

}  // namespace caphub::body
