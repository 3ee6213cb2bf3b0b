// The body tracked from the suit's sensor orientations: each sensor's latest orientations held
// and interpolated to the pose grid's time, body calibration (a reference pose averaged over a
// window, T+N from two moments, heading reset) at any time, the pelvis accelerometer and the
// feet's dead reckoning for the root, the body's acceleration to aid the filters with, and which
// segments a pose may be trusted for. No I/O and no clock: time is what the updates carry.
// docs/skeleton.md, "The body tracker".
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "fusion/body/body_calibration.h"
#include "fusion/body/body_solver.h"
#include "fusion/body/foot_inertial.h"
#include "fusion/body/joint_heading.h"
#include "fusion/body/knee_heading.h"
#include "hal/core/angles.h"
#include "hal/core/time.h"

namespace caphub::body {

// One sensor of the suit as the tracker sees it. Sensors are numbered by their place in the
// list the tracker is built with (the board's order); one sensor per segment.
struct TrackedSensor {
    Segment segment = Segment::Pelvis;
    Quatd nominalMounting = Quatd::Identity();  // q_segment_sensor, from the board file
    Vec3d positionM = Vec3d::Zero();            // on the segment, in its frame (the feet's)
};

// Offline: both feet's stretch logs (FootStretchLog) and what a pass does with them.
struct FootStretchLogs {
    std::array<FootStretchLog, 2> feet;  // left, right
    FootStretchUse use = FootStretchUse::Record;
};

struct BodyTrackerOptions {
    double rateHz = 60;  // the pose grid: poses per second
    // Before any body calibration: solve poses on the nominal mountings, the subject facing
    // north; false: no pose until a calibration succeeds.
    bool solveUncalibrated = true;
    // A calibration pose is averaged over this window from the moment it is asked for.
    Duration calibrationAverage = std::chrono::seconds(1);
    // Return the body's horizontal acceleration from the root's tracked velocity with each pose
    // (TrackedPose::aidEnuMps2), for the filters to take as known linear acceleration.
    bool aidFilters = true;
    // Track each foot sensor's velocity from the foot's latest still instant (FootInertial).
    bool footInertial = true;
    FootInertialOptions footInertialOptions;
    // Offline (reprocess --smooth): record the feet's stretches, or correct them from a pass
    // before with the same samples and orientations. Null live.
    std::shared_ptr<FootStretchLogs> footStretches;
    // A sensor whose latest update is older than this at a pose's time has stopped reporting
    // without being declared offline: its segment is not valid in that pose. 0.25 s is 25
    // sample periods at 100 Hz, far beyond the skew between buses.
    Duration staleAfter = std::chrono::milliseconds(250);
    // The capture heading from the knees' hinge axes (KneeHeading, fusion/body/knee_heading.h),
    // for a T- or N-pose calibration whose sensors' headings were all magnetic: estimated
    // (kneeHeadingError()), or also corrected live once known (once per calibration: the world
    // turns by it then, mid-capture; docs/body-calibration.md).
    KneeHeadingMode kneeHeading = KneeHeadingMode::Estimate;
    KneeHeadingOptions kneeHeadingOptions;
    // The headings of sensors that are free (gyroscope-only) at a one-pose calibration, set
    // against their parent segment's sensor from the joint between them while the body moves
    // (JointHeading, fusion/body/joint_heading.h): the strap's turn about the vertical that the
    // still pose could not show.
    bool jointHeading = true;
    JointHeadingOptions jointHeadingOptions;
    // No sensor is turned from its nominal mounting by more than this (rad) in all: a strap is
    // not worn that far off (the body calibration's bound for a raw heading is 25 deg); beyond,
    // the joint's answer is a clip's or a joint's fault, and that joint waits for more.
    double maxJointTurnRad = 30.0 * hal::kDegToRad;
    // Offline: the error known from a pass over the whole take, corrected at the first
    // calibration (reprocess --smooth).
    std::optional<double> knownHeadingErrorRad;
    BodySolverOptions solver;
};

// One sensor's fused sample: the filter's orientation and the calibrated readings it came from.
struct SensorUpdate {
    int sensor = 0;
    Timestamp t{};                                                   // the sample's time
    Eigen::Quaternionf qEnuSensor = Eigen::Quaternionf::Identity();  // sensor -> ENU
    Eigen::Vector3f specificForceMps2 = Eigen::Vector3f::Zero();     // sensor frame
    Eigen::Vector3f rateRadS = Eigen::Vector3f::Zero();              // sensor frame
    // The orientation's heading is the gyroscope's alone (no magnetometer correction yet): it
    // holds over time but is off north by an angle of the sensor's own, which realignHeading()
    // gives once it is measured. A calibration that takes such a sensor is re-expressed then.
    bool headingFree = false;
    // The heading is magnetic but from a magnetometer nothing has corrected (nor found right): a
    // calibration estimates the capture heading from the sensors whose headings are corrected
    // (neither free nor unchecked) when there are any, else from all, and checks an unchecked
    // heading against the sensor's strap: one no strap could explain is taken as unknown, like a
    // free one (the nominal heading, a turn); either is re-expressed when the fusion stage
    // measures and steps it (realignHeading).
    bool headingUnchecked = false;
};

// The latest calibration request and how far it got.
struct CalibrationStatus {
    enum class State : std::uint8_t { NotStarted, Averaging, Done, Failed };
    State state = State::NotStarted;
    CalibrationMethod method = CalibrationMethod::None;  // what was asked for
    double progress = 0;  // averaging: the share of the window(s) passed, 0..1
    std::string message;  // failed: why
};
std::string_view toString(CalibrationStatus::State s);

// The latest heading reset asked for, for a control page: waiting for the capture to reach its
// moment, done (the capture's heading then), or failed and why.
struct HeadingResetStatus {
    enum class State : std::uint8_t { NotAsked, Pending, Done, Failed };
    State state = State::NotAsked;
    double headingDeg = 0;  // done: the capture heading it set
    std::string message;    // failed: why
};
std::string_view toString(HeadingResetStatus::State s);

// What an update did besides holding the orientation, for the caller to record.
struct TrackerEvents {
    bool calibrated = false;         // calibration() is a new one, taken at the update's time
    bool calibrationFailed = false;  // calibrationStatus().message says why
    bool headingReset = false;       // calibration().headingRad changed
    bool headingResetFailed = false;
    // calibration() was re-expressed: a sensor calibrated with a free heading had it measured
    // (realignHeading), and the calibration is now what it would have been with that sensor's
    // heading magnetic then.
    bool reexpressed = false;
    // The capture heading was corrected from the knees' axes (BodyTrackerOptions::kneeHeading):
    // calibration().headingRad turned by kneeHeadingRad and the mountings with it.
    bool kneeHeading = false;
    double kneeHeadingRad = 0;
    std::string message;  // a failure's reason
};

// One solved pose.
struct TrackedPose {
    Timestamp t{};
    const Pose* pose = nullptr;  // the tracker's: valid until its next solve
    // The segments whose orientation rests on sensors that are online and reporting (see
    // PoseSolver::validSegments). A segment outside it is still filled in, but not measured.
    SegmentMask valid = 0;
    // The body's acceleration (ENU, m/s^2) for the filters to be aided with from now on; none:
    // leave their aiding as it is (the first pose after a calibration).
    std::optional<Vec3d> aidEnuMps2;
};

class BodyTracker {
public:
    BodyTracker(const Skeleton& skeleton, std::vector<TrackedSensor> sensors,
                const BodyTrackerOptions& options = {});

    // One sensor's sample, in time order per sensor. Updates of a sensor that is offline, or
    // with an index out of range, are ignored.
    TrackerEvents update(const SensorUpdate& u);

    // The pose grid: the earliest grid time not yet solved when every sensor has reported up to
    // `through` (the watermark() of the newest update), or none. The grid starts at the first
    // update, or at the first body calibration when poses wait for one; after a gap of ten periods
    // it restarts at `through`. The update that completes the first calibration solves nothing: the
    // grid's first point, its time, is due from the next update on.
    std::optional<Timestamp> due(Timestamp through);
    // The pose at t, from every sensor's orientations interpolated to t (carried on past a
    // sensor's latest sample at its rate for at most one sample interval). Solving at or past the
    // next grid time moves the grid on past t. Needs calibrated().
    const TrackedPose& solveAt(Timestamp t);

    // Body calibration in a reference pose held from `from` for the averaging window; it
    // completes on the first update past the window. Replaces a request still averaging.
    void startCalibration(ReferencePoseKind pose, Timestamp from);
    // T+N: the T-pose held from tPoseFrom and the N-pose from nPoseFrom, each for the window.
    void startTwoPoseCalibration(Timestamp tPoseFrom, Timestamp nPoseFrom);
    // Turn the capture world about up so that the pelvis faces +Z as it did at t: applied on the
    // first update at or after t, from the orientations at t.
    void headingResetAt(Timestamp t);
    // The sensor's orientations turn by angleRad about up (ENU +z, on the left: q_new =
    // Rz(angleRad) q_old) from its next update on, because its heading, free until now (the
    // gyroscope's alone), was measured against magnetic north. What is held of the sensor (its
    // orientations, a calibration's averages) is turned with it; a calibration that took the
    // sensor while its heading was free is re-expressed: recomputed from the orientations it
    // averaged with this sensor's turned, the capture heading estimated anew from the sensors
    // that are magnetic now (and a heading reset done since kept). Call it before the sensor's
    // next update.
    TrackerEvents realignHeading(int sensor, double angleRad);
    // A sensor whose heading is free (or unchecked and no strap could explain it: wrong) when a
    // calibration takes it gets the mounting closest to its nominal one
    // (BodyCalibration::nominalHeading; T+N's arms: measured) and a turn about up
    // (BodyCalibration::headingTurnRad) that its orientations are taken with from then on, until
    // its heading is realigned (the turn dropped, the calibration re-expressed) or its filter
    // restarts. An unchecked heading a strap could explain keeps its measured mounting, and is
    // re-expressed when realigned. The segments whose sensors' headings were free or unchecked
    // when the calibration in use was taken and have not been realigned since (0 for the nominal
    // mountings).
    SegmentMask freeAtCalibration() const {
        return calibrationInput_ ? calibrationInput_->free | calibrationInput_->unchecked : 0;
    }

    // A sensor out (lost, silent) or back. While out its updates are ignored and its segment is
    // not valid in any pose; it comes back with nothing held, its foot's dead reckoning
    // restarted.
    void setSensorOnline(int sensor, bool online);
    // Its filter restarted: what was held of it is stale. It stays online.
    void resetSensor(int sensor);
    bool sensorOnline(int sensor) const;
    // A sensor's latest update time, none before its first or while it is out (for a watermark).
    std::optional<Timestamp> latestUpdate(int sensor) const;
    // How far every live sensor has reported, given the newest update's time: the least of the
    // online sensors' latest update times, leaving out a sensor that is late (its latest update
    // more than 2.5 of its sample intervals, and at least 10 ms, behind `newest`: its bus
    // stalled) - the time up to which a pose can be solved from measured orientations on every
    // bus. None before any update, and none while an online sensor has not reported yet within
    // kStartWait of the first update (at the start every sensor's first sample is waited for, so
    // that the first pose is measured whole; one that has not come by then is left out).
    std::optional<Timestamp> watermark(Timestamp newest) const;
    static constexpr Duration kStartWait = std::chrono::milliseconds(200);

    // Poses are solved: a body calibration is in use, or the nominal mountings are allowed.
    bool calibrated() const { return calibrated_; }
    const BodyCalibration& calibration() const { return calibration_; }
    CalibrationStatus calibrationStatus() const;
    const HeadingResetStatus& headingResetStatus() const { return headingResetStatus_; }
    // Why the latest calibration request failed; empty when it did not (or is still averaging).
    const std::string& calibrationError() const { return calibrationMessage_; }
    std::uint64_t poses() const { return poses_; }
    const TrackedPose& latest() const { return out_; }
    const Pose& pose() const { return solver_.pose(); }
    const BodySolver& solver() const { return solver_; }
    const std::vector<TrackedSensor>& sensors() const { return sensors_; }
    // What the knees say the capture heading of the calibration in use is off by (rad, the turn
    // to add), from the samples since it; none before they have turned enough, or for a
    // calibration it does not apply to (KneeHeadingMode).
    std::optional<double> kneeHeadingError() const;
    // Body calibrations completed so far.
    int calibrations() const { return calibrations_; }
    // Per sensor the turn (rad, about up) its joints have given its free heading since the
    // calibration in use (BodyTrackerOptions::jointHeading); 0 for a sensor whose heading is
    // measured.
    const std::vector<double>& jointHeadingTurns() const { return jointTurn_; }
    Duration period() const { return period_; }

private:
    // Per sensor its two latest orientations and their sample times. Poses are solved on a fixed
    // grid that the sensors' samples do not fall on (60 Hz poses from 100 Hz sensors): taken as
    // they are, the orientations would be 0-10 ms old in a repeating pattern, and the joint
    // rates (the foot contacts' velocities) would swing by tens of percent from pose to pose.
    struct HeldOrientation {
        Eigen::Quaternionf previous = Eigen::Quaternionf::Identity();
        Eigen::Quaternionf latest = Eigen::Quaternionf::Identity();
        Eigen::Vector3f rateRadS = Eigen::Vector3f::Zero();  // the latest gyro, sensor frame
        Timestamp previousT{};
        Timestamp latestT{};
        int count = 0;  // orientations held: 0, 1 or 2
    };
    // The pelvis accelerometer's readings (ENU, m/s^2) not yet taken by a pose, by time.
    struct PelvisForce {
        Timestamp t{};
        Vec3d forceEnuMps2 = Vec3d::Zero();
    };
    static constexpr std::size_t kPelvisPending = 32;

    // A calibration being averaged: per window and sensor the sum of sign-aligned quaternions.
    struct Window {
        Timestamp from{};
        std::vector<Eigen::Vector4d> sum;
        std::vector<int> count;
        std::vector<bool> free;       // an averaged update's heading was free
        std::vector<bool> unchecked;  // ... or unchecked
    };
    // What the calibration in use was computed from, to re-express it (realignHeading).
    struct CalibrationInput {
        CalibrationMethod method = CalibrationMethod::None;
        std::array<SensorFrame, 2> frames;  // the averaged orientations (T+N: the T-pose first)
        SegmentMask free = 0;               // segments whose sensors' headings were free
        SegmentMask unchecked = 0;          // ... or magnetic but unchecked
        // Of the unchecked: those whose headings no strap could explain, taken as free
        // (CalibrationOptions::checkHeading), decided by the first computation (checked) and
        // kept by the re-expressions.
        SegmentMask uncheckedFree = 0;
        bool checked = false;
        SegmentMask lost = 0;  // free, then the sensor's filter restarted: never re-expressed
        // Unchecked and taken as right, then the sensor's filter restarted: its measured mounting
        // kept, never re-expressed, not a source of the capture heading.
        SegmentMask stale = 0;
        double headingRad = 0;  // the capture heading the calibration estimated
    };
    struct Request {
        CalibrationMethod method = CalibrationMethod::None;
        std::array<Window, 2> windows;  // one per pose: the T-pose first for T+N
        int windowCount = 0;
        Timestamp latest{};  // the newest update seen while averaging
    };

    void forget(std::size_t sensor);
    // What is held of a sensor (its orientations, the pelvis' forces not yet taken) turned by
    // angleRad about ENU up; its foot's dead reckoning restarted (a heading measured anew), or
    // turned with it (a correction from the joints, small and frequent).
    enum class FootOnTurn : std::uint8_t { Restart, Turn };
    void turnHeld(std::size_t sensor, double angleRad, FootOnTurn foot = FootOnTurn::Restart);
    // Each sensor's heading turn from the calibration in use (BodyCalibration::headingTurnRad
    // for a free heading, none otherwise), what is held of it turned by the change.
    void applyHeadingTurns(FootOnTurn foot = FootOnTurn::Restart);
    void average(const SensorUpdate& u);
    SensorFrame averagedFrame(const Window& w, SegmentMask only) const;
    void completeCalibration(Timestamp t, TrackerEvents& events);
    // A knee's shank sample into the capture heading's estimate; the correction once it is known
    // (KneeHeadingMode::Live).
    void addKneeSample(std::size_t sensor, TrackerEvents& events);
    // The joints between segments with sensors (links_, jointGroup_), from the skeleton's offsets.
    void buildJointLinks(const Dimensions& dims);
    // A sensor's sample into its joints' relative headings; a free child turned to its parent's
    // once known.
    void addJointSample(std::size_t sensor, const SensorUpdate& u, const Eigen::Quaternionf& q);
    // Free sensors' headings turned by turns[sensor] (rad) about up from now on, and their
    // mountings with them so that the calibration pose is unchanged.
    void turnFreeHeadings(const std::vector<double>& turns);
    void resetJointHeadings();
    // The calibration in use can be corrected from the knees (one pose, magnetic headings).
    bool kneeHeadingApplies() const;
    // A segment's mounting turned by angleRad about the up of the calibration's reference pose
    // (ENU up, in the capture world), so that the reference pose stays what it was when its
    // sensor's orientations turn by that angle (q_segment_sensor = ref^-1 Ry(a) ref q).
    void turnMounting(Segment segment, double angleRad);
    // The capture heading turned by errorRad and every mounting with it, once per calibration
    // (the events say so).
    void turnCaptureHeading(double errorRad, TrackerEvents& events);
    // The calibration from its inputs (a heading reset done since, if any, added by the caller).
    Result<BodyCalibration> computeCalibration(const CalibrationInput& in, std::int64_t tNs) const;
    // The heading reset asked for, once t has reached its moment.
    void headingResetIfDue(Timestamp t, TrackerEvents& events);
    void applyHeadingReset(Timestamp t, TrackerEvents& events);
    // A sensor's orientation at t: between its two latest samples, or carried on past the latest
    // at its gyroscope's rate for at most one sample interval. False when it has none.
    bool orientationAt(std::size_t sensor, Timestamp t, Eigen::Quaternionf& q) const;
    // The sensors' orientations at t, and which segments they cover.
    SensorFrame frameAt(Timestamp t) const;
    // The body's horizontal acceleration from the root's tracked velocity, for the filters.
    std::optional<Vec3d> aidingAcceleration(double dtS);

    std::vector<TrackedSensor> sensors_;
    BodyTrackerOptions options_;
    Duration period_;
    BodySolver solver_;
    std::array<int, kSegmentCount> sensorOfSegment_;  // -1 when none
    std::array<Quatd, kSegmentCount> nominal_;
    std::vector<HeldOrientation> held_;
    std::vector<bool> online_;
    // Per sensor: its orientations are taken turned by this about ENU up (a free heading's turn
    // from the calibration in use; 0: as they come).
    std::vector<double> headingTurn_;
    int pelvisSensor_ = -1;
    // The feet's sensors (-1 when none) and their dead reckoning.
    std::array<int, 2> footSensor_{-1, -1};
    // The thighs' and shanks' sensors (-1 when none), left then right, and the capture heading
    // from their knees: done once per calibration.
    std::array<int, 2> thighSensor_{-1, -1};
    std::array<int, 2> shankSensor_{-1, -1};
    KneeHeading kneeHeading_;
    bool kneeHeadingDone_ = false;
    // Each joint between two segments with sensors, and its sensors' relative heading.
    struct JointLink {
        int parent = -1;  // sensors
        int child = -1;
        Vec3d rParentSegment = Vec3d::Zero();  // sensor to joint centre, in each segment's frame
        Vec3d rChildSegment = Vec3d::Zero();
        JointHeading heading;
    };
    std::vector<JointLink> links_;
    // Per sensor the links it is on (two or three of links_: its own to the sensor above, and
    // those of the sensors below it), so that a sample visits only those.
    std::vector<std::vector<std::size_t>> linksOf_;
    // A joint's relative heading into its free sensor (both free: the child; the group's mean
    // kept when all of it is free).
    void correctFromJoint(const JointLink& l, double angleRad);
    // Per sensor the group of sensors its joints connect it to (the trunk's and limbs' trees).
    std::vector<int> jointGroup_;
    // Per sensor its two samples before the latest, for the joints: the gyroscope is
    // differentiated about the middle one of three, and the joint's acceleration taken there.
    struct JointInput {
        struct Sample {
            Timestamp t{};
            Quatd q = Quatd::Identity();  // sensor -> ENU, turned as held
            Vec3d forceMps2 = Vec3d::Zero();
            Vec3d rateRadS = Vec3d::Zero();
        };
        std::array<Sample, 2> before;  // [0] the oldest
        int count = 0;
    };
    std::vector<JointInput> jointInputs_;
    // Per sensor a correction applied (rad): its heading turned so far from its joints.
    std::vector<double> jointTurn_;
    std::vector<double> turnScratch_;  // per sensor, for turnFreeHeadings
    static constexpr double kMinJointTurnRad = 0.25 * hal::kDegToRad;
    int calibrations_ = 0;  // completed
    std::array<FootInertial, 2> footInertial_;

    // Each foot's state after its latest samples: a pose is solved at the watermark, up to a
    // sample interval after its grid time, and takes the feet as they were at the grid time.
    std::array<FootStateHistory, 2> footHistory_;
    // The pelvis accelerometer's readings up to each pose's grid time, each turned into ENU
    // (m/s^2); their mean goes to the skeleton world frame once per pose. Readings past the grid
    // time wait in pelvisPending_ (a ring) for the next pose.
    Vec3d pelvisForceSumEnu_ = Vec3d::Zero();
    int pelvisForceCount_ = 0;
    std::array<PelvisForce, kPelvisPending> pelvisPending_;
    std::size_t pelvisHead_ = 0;  // the oldest pending
    std::size_t pelvisCount_ = 0;
    // The latest pose's mean (ENU) and its time: a pose that no new reading reached (poses
    // faster than the pelvis sensor) takes it again, while the sensor is not silent for longer
    // than kPelvisHoldS.
    Vec3d lastPelvisForceEnu_ = Vec3d::Zero();
    std::optional<Timestamp> lastPelvisForceT_;
    static constexpr double kPelvisHoldS = 0.05;

    BodyCalibration calibration_;
    std::optional<CalibrationInput> calibrationInput_;  // none: the nominal mountings
    bool calibrated_ = false;
    std::optional<Request> request_;
    CalibrationStatus::State state_ = CalibrationStatus::State::NotStarted;
    CalibrationMethod requested_ = CalibrationMethod::None;
    std::string calibrationMessage_;
    std::optional<Timestamp> headingResetAt_;
    HeadingResetStatus headingResetStatus_;

    bool gridStarted_ = false;
    std::optional<Timestamp> firstUpdate_;  // of any sensor, since the tracker was made
    bool gridWaits_ = false;  // the update that completed the first calibration: nothing due
    Timestamp nextGrid_{};
    Timestamp lastPose_{};
    std::uint64_t poses_ = 0;
    TrackedPose out_;
    Vec3d rootVelocityLp_ = Vec3d::Zero();  // m/s, skeleton world, horizontal
    bool rootVelocityValid_ = false;
};

}  // namespace caphub::body
