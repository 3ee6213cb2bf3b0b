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
    FollowParent  // its joint stays in the reference pose (toes, or a limb with no sensor)
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
    // both its ends are, a follower when what it follows is. A segment of a missing sensor is
    // still solved (from the identity orientation), so this is what tells it apart.
    SegmentMask validSegments(SegmentMask present) const;

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
};

// Joint limit check of one joint rotation: the excess in degrees (0 inside). With clamp, q is
// replaced by the nearest rotation (per component of the rotation vector) inside the limits.
double applyJointLimits(const JointLimits& limits, Quatd& qLocal, bool clamp);

}  // namespace caphub::body
