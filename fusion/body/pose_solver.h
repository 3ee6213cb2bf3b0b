// Pose solving: segment orientations from sensor orientations and mountings, the rules for
// segments without a sensor (docs/skeleton.md), joint rotations and soft joint limits.
#pragma once

#include <array>

#include "fusion/body/body_calibration.h"
#include "fusion/body/kinematics.h"

namespace caphub::body {

// How a segment's orientation is found, decided once from which segments carry a sensor.
enum class SegmentRule : std::uint8_t {
    Sensor,       // its own sensor
    SpineShare,   // a share of the rotation between the spine sensors above and below it
    FollowParent  // its joint stays in the reference pose (toes, a clavicle), or a limb or the
                  // trunk with no sensor on it in the neutral standing pose (coveredSegments)
};

struct JointLimitReport {
    // Per joint: how far the rotation vector lies outside the limits, degrees (0: inside).
    std::array<double, kSegmentCount> excessDeg{};
    int violations = 0;
};

struct PoseSolverOptions {
    bool clampToLimits = false;  // false: report violations only
};

class PoseSolver {
public:
    PoseSolver(SegmentMask sensors, const PoseSolverOptions& options = {});

    void setCalibration(const BodyCalibration& cal);
    const BodyCalibration& calibration() const { return cal_; }
    SegmentRule rule(Segment s) const { return rules_[static_cast<std::size_t>(idx(s))]; }
    SegmentMask sensors() const { return sensors_; }

    // Fills qWorld and qLocal (not positions). Sensors outside the mask are ignored. With a
    // report, joint limits are checked (and applied when clampToLimits).
    void solve(const SensorFrame& frame, Pose& pose, JointLimitReport* report = nullptr) const;
    // The segments whose solved orientation rests only on sensors in `present` (those with an
    // orientation in the frame): a sensor's own segment when it is present, a spine share when
    // both its ends are, a follower when what it follows is - and only segments the suit covers
    // at all (coveredSegments). A segment of a missing sensor is still solved (from the identity
    // orientation), so this is what tells it apart.
    SegmentMask validSegments(SegmentMask present) const;
    // The segments the suit's sensors give an orientation for when all are present: those with
    // a sensor, spine segments between two sensors, a segment without a sensor that is the one
    // link missing between its parent's sensor and a child's (a clavicle between the chest and
    // an upper arm), and an end segment (toes, a hand) whose parent has a sensor. The rest - a limb
    // or the trunk with no sensor on it (the legs of the 10-sensor upper body, the trunk and arms
    // of the 7-sensor lower body) - is held in the reference pose under its parent and never
    // measured (docs/sparse.md).
    SegmentMask coveredSegments() const { return covered_; }

private:
    struct Share {
        int from = -1;  // sensor-driven spine segment above (towards the root)
        int to = -1;    // sensor-driven spine segment below it in the chain, further up
        double fraction = 0;
    };
    SegmentMask sensors_;
    PoseSolverOptions options_;
    BodyCalibration cal_;
    Quatd qWorldEnu_ = Quatd::Identity();
    std::array<Quatd, kSegmentCount> inverseMounting_;
    std::array<SegmentRule, kSegmentCount> rules_{};
    std::array<Share, kSegmentCount> shares_{};
    int rootSource_ = -1;  // when the pelvis has no sensor: the spine segment it follows
    SegmentMask covered_ = 0;
    // A follower's joint rotation: the identity, or for a segment not covered the neutral
    // standing pose's (the arms hanging).
    std::array<Quatd, kSegmentCount> held_ = filledIdentity();
    static std::array<Quatd, kSegmentCount> filledIdentity() {
        std::array<Quatd, kSegmentCount> a;
        a.fill(Quatd::Identity());
        return a;
    }
};

// Joint limit check of one joint rotation: the excess in degrees (0 inside). With clamp, q is
// replaced by the nearest rotation (per component of the rotation vector) inside the limits.
double applyJointLimits(const JointLimits& limits, Quatd& qLocal, bool clamp);

}  // namespace caphub::body
