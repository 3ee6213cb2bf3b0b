// Root translation from foot contacts: the foot point that is still (heel, ball or toe of either
// foot; a knee when kneeling, the seat when sitting) is held where it is and the root follows it;
// with both feet off the floor (a jump) the root flies ballistically.
// The floor is at the height the feet had at reset; a foot at rest on a tread or a step above or
// below it makes a level of its own (docs/skeleton.md).
#pragma once

#include <array>
#include <optional>

#include "fusion/body/kinematics.h"

namespace caphub::body {

struct ContactOptions {
    // A foot point can carry the body when it is within this of the lowest foot point, or of
    // the lowest point of a foot at rest on something (m).
    double heightM = 0.04;
    // At rest: the foot's own sensor still for this long (s). A swinging foot is still for an
    // instant at its turning points; one standing on a step, a stair's tread or the floor for
    // longer.
    double restingS = 0.1;
    // Where a foot point takes over the body, its height joins the support level it is within
    // this of (the floor, a tread, a step); a foot at rest further from every known level
    // starts a new one (m); any other point is taken to stand on the highest known level below,
    // and below every known level (down a stair from where the capture began) on a new one when
    // its foot's sensor says it is not swinging (slower than swingMps), else on the lowest.
    double levelSnapM = 0.10;
    // A step onto a tread: the held foot's own sensor moving faster than swingMps (m/s; a
    // swing, not a slip) while the other foot's, more than heightM above or below the held
    // one, moves slower than plantedMps: the other foot is planted and carries the body on a
    // level of its own, until its sensor says it moves again. Its sensor need not be at rest
    // for restingS: on a real stair a loaded foot hardly ever is (docs/skeleton.md, "Steps and
    // stairs"). A foot whose sensor came to rest (below plantedMps) more than heightM above or
    // below the held foot takes over, whichever rule hands it the body, on a level at that rise.
    double swingMps = 0.5;
    double plantedMps = 0.2;
    // The point that carries the body is the one that moves least in the world: each point's
    // world velocity is predicted from its velocity relative to the root (the Jacobian and the
    // joint rates) plus the root velocity, low-passed with this time constant (s) so that the
    // prediction does not simply restate which point is anchored now.
    double velocityTimeConstantS = 0.05;
    // Another point takes over when its predicted speed is below the anchored one's by this
    // (m/s): hysteresis against chatter between points that are both still.
    double switchMarginMps = 0.05;
    // Flight starts when the vertical component of the root's measured specific force (a - g,
    // m/s^2) stays below this for flightFrames frames; it ends when a foot reaches the floor.
    double freeFallMps2 = 3.0;
    int flightFrames = 2;
    // The take-off velocity: the root's velocity from the contacts, complemented by the pelvis
    // accelerometer with this time constant (s). At the end of a push-off the feet leave the
    // floor gradually and the contacts no longer see the root's speed; the accelerometer does.
    double takeoffTimeConstantS = 0.3;
    // In flight the whole body's centre of mass flies the parabola, and the root moves about it
    // as the body's shape changes (a hop's root swings forward and back while the centre of mass
    // hardly moves). Its horizontal velocity at take-off: the centre of mass' mean over this
    // last stretch of the stance before it (s). In a push-off the floor pushes mostly upwards,
    // so the horizontal velocity changes little over it, and a mean over frames does not take
    // one frame's finite difference of a fast-changing shape.
    double takeoffWindowS = 0.1;
    // Sitting: with both thighs at least this far from the vertical (deg), the seat (a point on
    // the pelvis below the middle of the hip joints, near the ischial tuberosities; pelvis
    // frame) can carry the body. Standing, walking and running keep a thigh within 30 deg of
    // the vertical; sitting on a stool or a chair takes both past 45.
    double seatedThighDeg = 45;
    Vec3d seatBelowHipsM = Vec3d(0, -0.08, -0.04);
    // ... and with the centre of mass further across than this (m, half a foot's width) from
    // the support of the foot points near the floor: off its feet, the body is on the seat.
    double offFeetM = 0.05;
    // ... for this long (s): a sitting is a state, not the instant of a landing or a push-off
    // (the centre of mass passes behind the feet for a frame or two there).
    double seatedForS = 0.1;
    // Kneeling: each knee is a contact point too (shank frame, from the knee joint: the front of
    // the knee below the kneecap, where a kneeling body rests on the floor). A knee qualifies
    // within heightM of the lowest point of the feet and knees while every foot point is more
    // than heightM above that: the feet carry the body whenever they can (on one knee, the
    // front foot flat on the floor does). Standing, walking or squatting, the knees are far
    // above the feet.
    Vec3d kneeFrontM = Vec3d(0, -0.04, 0.05);
    // What the pelvis accelerometer allows the contacts: the root's velocity from the held
    // point may differ from the one the accelerometer predicts (the previous frame's plus the
    // measured acceleration) by this much in one frame (m/s); beyond it the rest of the step is
    // taken as the held point slipping and left out. A leg whose orientation jumps (a clipped
    // gyroscope, a capture that flips a leg about its long axis) or a hand-over between the
    // feet in a push-off moves the root by centimetres in a frame that no force moved the body
    // by. Above the frames' spread where nothing slips (the 99th percentile of walking,
    // turning and sitting at 30-100 poses a second): docs/skeleton.md, "Slips the pelvis did
    // not feel". While the pelvis reads free fall (below freeFallMps2) the bound is zero: the
    // feet carry nothing then, whatever still touches the floor.
    double contactStepMps = 0.3;
    // A held foot sliding late: its dead reckoning measures a slip for FootInertialOptions::
    // maxSpanS after a still instant; beyond it, while it is still known (maxKnownSpanS), the
    // held point follows it too when the foot clearly slides (faster than swingMps across),
    // along the floor (its vertical velocity within slideVerticalMps of zero: a foot on the
    // floor does not move up or down, so a dead reckoning that says so has gone wrong) and the
    // body moves slower across than slideBodyMps (a turn or a shuffle on the spot: no stride's
    // impacts in the integration). A foot turned on the floor in a pivot slides at about
    // 1 m/s (docs/skeleton.md, "A foot sliding in a turn").
    double slideVerticalMps = 0.3;
    double slideBodyMps = 0.5;
    double gravityMps2 = 9.81;
};

enum class ContactPhase : std::uint8_t { LeftStance, RightStance, Flight, Seated };

// The feet's contact points in one frame: heel, ball, toe tip of each foot, world, with their
// velocities.
struct FootState {
    std::array<Vec3d, 6> pointM{};  // left heel, ball, toe; right heel, ball, toe
    std::array<Vec3d, 6> velocityMps{};
};

// Where the whole body's centre of mass is relative to the root, in the pose's world frame (the
// segments' mass fractions and centres of mass; Dimensions).
Vec3d centreOfMassOffsetM(const Dimensions& d, const Pose& pose);

// The feet's own sensors by dead reckoning (fusion/body/foot_inertial.h), left then right: where
// each sits on its hindfoot (segment frame) and, when known (integrated from a still instant not
// long ago: FootInertial::known), its velocity and rate in the skeleton world frame; valid when
// recent enough to measure a slip by (FootInertial::valid).
struct FootSensorMotion {
    std::array<bool, 2> valid{};
    std::array<bool, 2> known{};
    std::array<bool, 2> still{};
    std::array<Vec3d, 2> velocityMps{Vec3d::Zero(), Vec3d::Zero()};
    std::array<Vec3d, 2> rateRadS{Vec3d::Zero(), Vec3d::Zero()};
    std::array<Vec3d, 2> onFootM{Vec3d::Zero(), Vec3d::Zero()};
};

class RootTracker {
public:
    explicit RootTracker(const ContactOptions& options = {}) : options_(options) {}

    // Places the root so that the lowest foot point stands on the floor (y = 0) with the root
    // horizontally at horizontalM (x, z); pose needs positions from FK with any root.
    void reset(const Dimensions& d, Pose& pose, double rootXM = 0, double rootZM = 0);

    // One frame: pose has orientations and positions from FK with its root at the origin
    // (relative positions); feet velocities relative to the root (root velocity excluded).
    // Moves the pose's positions to the new root. rootSpecificForceMps2: the pelvis
    // accelerometer's reading (specific force, a - g) in the skeleton world frame, when known:
    // it tells a flight phase (free fall: about zero) and the velocity at take-off.
    // footSensors, when given: the anchored point moves with its foot's measured slip while that
    // foot is valid and not still (a foot rolling off the floor in a push-off slips forward a
    // little; the contacts alone take it for still).
    void update(const Dimensions& d, Pose& pose, const FootState& relativeFeet, double dtS,
                const std::optional<Vec3d>& rootSpecificForceMps2 = std::nullopt,
                const FootSensorMotion* footSensors = nullptr);

    const Vec3d& rootM() const { return root_; }
    const Vec3d& rootVelocityMps() const { return velocity_; }
    ContactPhase phase() const { return phase_; }
    // 0-5 as in FootState, 6 the seat, 7 and 8 the left and right knee, -1 in flight.
    int contactPoint() const { return point_; }
    int stanceChanges() const { return stanceChanges_; }

private:
    Vec3d takeoffHorizontalComVelocity() const;
    // One frame on the ground: the point that carries the body (a foot point or the seat) chosen
    // and held; where the root goes. comOffset and comRate: the centre of mass from the root and
    // its velocity about it; seat and seatVelocity: the seat point relative to the root.
    Vec3d stanceStep(const Pose& pose, const FootState& feet, double minY,
                     const FootSensorMotion* footSensors, double dtS, const Vec3d& comOffset,
                     const Vec3d& comRate, const Vec3d& seat, const Vec3d& seatVelocity,
                     const std::array<Vec3d, 2>& knees);
    // A sitting posture with the body off its feet and knees, in which the seat may carry it
    // (ContactOptions::seatedThighDeg, offFeetM): the feet's and knees' points relative to the
    // root, minY the lowest of them, com the centre of mass from the root and its velocity
    // about the root.
    bool seated(const Pose& pose, const std::array<Vec3d, 8>& points, double minY, const Vec3d& com,
                const Vec3d& comVelocityAboutRoot) const;
    // Foot f, held, slides beyond its dead reckoning's slip span (ContactOptions::
    // slideVerticalMps, slideBodyMps).
    bool slidingLate(const FootSensorMotion& footSensors, std::size_t f) const;
    // The feet's sensors this frame (ContactOptions::swingMps, plantedMps): each foot's level as
    // it comes to rest, and whether the other foot is planted now; footMinY: each foot's lowest
    // point relative to the root, soleY: the lower of its heel and ball. True when a foot was
    // planted in this frame.
    bool updatePlantedFoot(const FootSensorMotion& footSensors,
                           const std::array<double, 2>& footMinY,
                           const std::array<double, 2>& soleY);
    // The level a point taking over the body at heightM stands on: resting, its foot at rest
    // there; landing, its foot's sensor says it is not swinging.
    double supportLevel(double heightM, bool resting, bool landing);

    ContactOptions options_;
    Vec3d root_ = Vec3d::Zero();
    Vec3d velocity_ = Vec3d::Zero();
    // The centre of mass: at the take-off (when the free fall began), its velocity then, and
    // where it is in flight and how fast it rises.
    Vec3d takeoffCom_ = Vec3d::Zero();
    Vec3d takeoffComVelocity_ = Vec3d::Zero();
    Vec3d com_ = Vec3d::Zero();
    double comVerticalVelocity_ = 0;
    Vec3d comOffset_ = Vec3d::Zero();      // the latest frame's centre of mass from the root
    Vec3d comOffsetRate_ = Vec3d::Zero();  // and how fast it moved in that frame
    // The feet's sensors relative to the root at the latest frame, when the feet were given.
    std::array<Vec3d, 2> footSensorRelM_{Vec3d::Zero(), Vec3d::Zero()};
    bool footSensorsKnown_ = false;
    // The seat and the knees relative to the root at the latest frame: their velocities.
    Vec3d seatRelM_ = Vec3d::Zero();
    std::array<Vec3d, 2> kneeRelM_{Vec3d::Zero(), Vec3d::Zero()};
    double offFeetS_ = 0;  // how long the body has been off its feet in a sitting posture
    // The centre of mass at the end of the latest frames in stance (world) and their durations,
    // a ring (the newest at comHistoryHead_): the take-off's horizontal velocity.
    struct ComSample {
        Vec3d positionM = Vec3d::Zero();
        double dtS = 0;
    };
    static constexpr std::size_t kComHistory = 32;
    std::array<ComSample, kComHistory> comHistory_{};
    std::size_t comHistoryHead_ = 0;
    std::size_t comHistoryCount_ = 0;
    double freeFallS_ = 0;                  // since then
    Vec3d fusedVelocity_ = Vec3d::Zero();   // contacts and pelvis accelerometer, for take-off
    Vec3d smoothVelocity_ = Vec3d::Zero();  // low-passed root velocity, for the predictions
    Vec3d anchor_ = Vec3d::Zero();          // world position of the contact point
    int point_ = -1;
    ContactPhase phase_ = ContactPhase::LeftStance;
    // The heights the feet have stood on (the floor, at 0, first); the anchor's height is one of
    // them while a foot carries the body.
    static constexpr std::size_t kLevels = 16;
    std::array<double, kLevels> levels_{};
    std::size_t levelCount_ = 1;
    double takeoffLevelM_ = 0;
    std::array<double, 2> stillForS_{};  // how long each foot's sensor has been still
    int plantedFoot_ = -1;               // a foot planted on another level, by the feet's sensors
    std::array<bool, 2> footSlow_{};     // each foot's sensor slower than plantedMps
    // Each foot's level when it came to rest (while it stays slow).
    std::array<std::optional<double>, 2> landedLevelM_{};
    int freeFallCount_ = 0;
    int stanceChanges_ = 0;
    bool started_ = false;
};

// Foot contact points (heel, ball, toe of each foot) of a pose, world, and their velocities
// from the feet's Jacobians and the joint rates (root velocity excluded).
void footState(const Dimensions& d, const Pose& pose, const JointRates& rates, FootState& out);
// The same from Jacobians already made for any point of each hindfoot (the foot is rigid: the
// velocity of point p is v + w x (p - point)), so that the solver builds each chain only once.
void footState(const Dimensions& d, const Pose& pose, const ChainJacobian& left,
               const ChainJacobian& right, const JointRates& rates, FootState& out);

}  // namespace caphub::body
