// Root translation from foot contacts: the stance foot is held where it touched the floor and
// the root follows it; with both feet off the floor (a jump) the root flies ballistically.
// Assumes a flat, level floor at the height the feet had at reset (docs/skeleton.md).
#pragma once

#include <array>
#include <optional>

#include "fusion/body/kinematics.h"

namespace caphub::body {

struct ContactOptions {
    // A foot can be in contact when its lowest point is within this of the lowest foot point
    // of the body (m) ...
    double heightM = 0.04;
    // ... and that point moves up or down slower than this relative to the stance foot (m/s;
    // velocities from the Jacobian and the joint rates).
    double speedMps = 0.8;
    // The stance passes to the other foot when it is in contact and the stance foot's lowest
    // point has risen this far above the other's (m): hysteresis against chatter.
    double switchMarginM = 0.01;
    // Flight starts when the root's measured specific force (|a - g|, m/s^2) stays below this
    // for flightFrames frames; it ends when a foot reaches the floor.
    double freeFallMps2 = 3.0;
    int flightFrames = 2;
    double gravityMps2 = 9.81;
};

enum class ContactPhase : std::uint8_t { LeftStance, RightStance, Flight };

// The feet's contact points in one frame: heel, ball, toe tip of each foot, world, with their
// velocities.
struct FootState {
    std::array<Vec3d, 6> pointM{};  // left heel, ball, toe; right heel, ball, toe
    std::array<Vec3d, 6> velocityMps{};
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
    // accelerometer's |a - g| when known (for flight detection).
    void update(const Dimensions& d, Pose& pose, const FootState& relativeFeet, double dtS,
                std::optional<double> rootSpecificForceMps2 = std::nullopt);

    const Vec3d& rootM() const { return root_; }
    const Vec3d& rootVelocityMps() const { return velocity_; }
    ContactPhase phase() const { return phase_; }
    int contactPoint() const { return point_; }  // 0-5 as in FootState, -1 in flight
    int stanceChanges() const { return stanceChanges_; }

private:
    ContactOptions options_;
    Vec3d root_ = Vec3d::Zero();
    Vec3d velocity_ = Vec3d::Zero();
    Vec3d takeoffVelocity_ = Vec3d::Zero();
    Vec3d anchor_ = Vec3d::Zero();  // world position of the contact point
    int point_ = -1;
    ContactPhase phase_ = ContactPhase::LeftStance;
    double floorYM = 0;
    int freeFallCount_ = 0;
    int stanceChanges_ = 0;
    bool started_ = false;
};

// Foot contact points (heel, ball, toe of each foot) of a pose, world, and their velocities
// from the feet's Jacobians and the joint rates (root velocity excluded).
void footState(const Dimensions& d, const Pose& pose, const JointRates& rates, FootState& out);

}  // namespace caphub::body
