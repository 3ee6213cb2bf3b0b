// Calibration of the sensors to the body: each sensor's mounting on its segment from a known
// pose (T-pose, N-pose), from two poses (T+N, which needs no per-sensor heading for the arms),
// and the yaw-only heading reset. The maths and the procedure: docs/body-calibration.md.
#pragma once

#include <array>
#include <cstdint>
#include <numbers>
#include <optional>
#include <string>
#include <string_view>

#include "fusion/body/kinematics.h"
#include "hal/core/error.h"

namespace caphub::body {

enum class CalibrationMethod : std::uint8_t { None, TPose, NPose, TPlusN };
std::string_view toString(CalibrationMethod m);

// Which segments carry a sensor: bit i for segment i.
using SegmentMask = std::uint32_t;
constexpr SegmentMask bit(Segment s) {
    return SegmentMask{1} << idx(s);
}
constexpr bool has(SegmentMask m, int segment) {
    return (m >> segment) & 1U;
}
// Whether the root's translation is measured: it rests on the foot contacts, so both feet.
constexpr bool rootTranslationMeasured(SegmentMask m) {
    return has(m, idx(Segment::LHindfoot)) && has(m, idx(Segment::RHindfoot));
}

// Sensor orientations (q_ENU_sensor, from fusion), one per segment that has a sensor.
struct SensorFrame {
    std::array<Quatd, kSegmentCount> qEnuSensor;
    SegmentMask mask = 0;
    SensorFrame() { qEnuSensor.fill(Quatd::Identity()); }
};

// The result of a calibration; it is written into recordings (toText / parseBodyCalibration).
struct BodyCalibration {
    CalibrationMethod method = CalibrationMethod::None;
    std::int64_t tNs = 0;                       // when it was taken, capture clock
    SegmentMask mask = 0;                       // the segments calibrated
    std::array<Quatd, kSegmentCount> mounting;  // q_segment_sensor
    // The capture world: the skeleton world frame turned about up by headingRad, so that the
    // subject faced +Z at calibration. q_ENU_world = R_ENU_world * Ry(headingRad).
    double headingRad = 0;
    // The segments whose sensors' headings were free at the calibration (the gyroscope's alone,
    // off north by an angle of each sensor's own): each such sensor's orientations are taken
    // turned by headingTurnRad about up (ENU +z, on the left: Rz(turn) q_ENU_sensor), so that
    // its segment moves in the capture world with the others. Of these, nominalHeading: the
    // mounting's rotation about the vertical is the nominal mounting's (the turn chosen to make
    // it closest to it), the other two degrees of freedom from gravity; the others (T+N's arms)
    // are measured, the turn fitted to them. docs/body-calibration.md, "Free headings".
    SegmentMask freeHeading = 0;
    SegmentMask nominalHeading = 0;
    std::array<double, kSegmentCount> headingTurnRad{};
    BodyCalibration() { mounting.fill(Quatd::Identity()); }
    Quatd qEnuWorld() const;
};

// R_ENU_world of docs/frames.md (world X west, Y up, Z north).
Quatd enuFromSkeletonWorld();

// The segment orientations of the reference poses, in the capture world.
enum class ReferencePoseKind : std::uint8_t { T, N };
Quatd referenceOrientation(ReferencePoseKind pose, Segment s);
// Every segment's referenceOrientation: the pose a subject holds to calibrate.
std::array<Quatd, kSegmentCount> referencePose(ReferencePoseKind pose);

struct CalibrationOptions {
    // The subject's heading at calibration (rad about up, from north as world +Z). Unknown:
    // estimated from the sensors through their nominal mountings (the circular mean).
    std::optional<double> headingRad;
    std::array<Quatd, kSegmentCount> nominalMounting;  // from the board file
    // The segments whose sensors the heading is estimated from: those whose headings are
    // magnetic (a sensor whose heading is still the gyroscope's alone is off north by an angle
    // of its own). None of the frame's among them: all of the frame's.
    SegmentMask headingFrom = ~SegmentMask{0};
    // The segments whose sensors' headings are free (BodyCalibration::freeHeading): their
    // mountings take the heading about the vertical that is closest to the nominal mounting.
    SegmentMask freeHeading = 0;
    // The segments whose sensors' headings are magnetic but unchecked (a magnetometer read raw,
    // its offset unmeasured): each is checked against its strap. If the turn about the vertical
    // that brings its mounting closest to the nominal one (closestHeadingTurn) is within
    // plausibleTurnRad, the heading is taken as right and the mounting measured; otherwise the
    // heading is wrong and the sensor is taken as free (freeHeading, nominalHeading).
    SegmentMask checkHeading = 0;
    // How far a strap can turn a sensor about the vertical. 25 deg: the virtual suit's straps
    // (half-normal angle, scale 10 deg, capped at 30, about a uniform axis) turn a sensor about
    // the vertical by more than 20 deg once in 160, by more than 25 once in 900 (drawn from
    // that distribution), never by more than 30; 5 deg of the margin are for the pose held and
    // the capture heading. docs/body-calibration.md, "Unchecked headings".
    double plausibleTurnRad = 25.0 * std::numbers::pi / 180;
    CalibrationOptions() { nominalMounting.fill(Quatd::Identity()); }
};

// Single-pose calibration (the paper's T-pose; or the N-pose): q_segment_sensor =
// q_world_segment(pose)^-1 q_ENU_world^-1 q_ENU_sensor. Errors for no sensors or a quaternion
// that is not finite or not of unit length (within 1e-3).
Result<BodyCalibration> calibrateOnePose(ReferencePoseKind pose, const SensorFrame& frame,
                                         const CalibrationOptions& options, std::int64_t tNs = 0);

// T+N: arm segments (whose orientation differs between the poses) from the two gravity
// directions alone (TRIAD: the hanging arm's long axis from the N-pose, up from the T-pose);
// the other segments from the mean of the two single-pose results. Both frames must have the
// same sensors.
Result<BodyCalibration> calibrateTwoPose(const SensorFrame& tPose, const SensorFrame& nPose,
                                         const CalibrationOptions& options, std::int64_t tNs = 0);

// The turn about up (rad, ENU +z, on the left of qEnuSensor) that makes
// left * Rz(turn) * qEnuSensor closest to target (the least angle between the two rotations):
// a 1-D problem with a closed form. left is what turns ENU into the mounting's frame
// (q_world_segment(pose)^-1 q_ENU_world^-1). In (-pi, pi].
double closestHeadingTurn(const Quatd& left, const Quatd& qEnuSensor, const Quatd& target);

// Yaw-only heading reset, any time, no pose needed: turns the capture world about up so that
// the pelvis of the given (solved) pose faces +Z. Mountings are kept.
void headingReset(BodyCalibration& cal, const Pose& current);

// Text form for recordings: one "key value" per line (docs/body-calibration.md).
std::string toText(const BodyCalibration& cal);
// Errors read "<sourceName>:<line>: <what was expected>".
Result<BodyCalibration> parseBodyCalibration(std::string_view text, std::string_view sourceName);

}  // namespace caphub::body
