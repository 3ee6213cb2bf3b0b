// The relative heading of two sensors on either side of a joint, from the joint's acceleration.
// Two segments joined at a point move that point together: each sensor's specific force carried
// to the joint centre (f + w' x r + w x (w x r), r from the sensor to the centre) is one vector,
// the joint's, seen through two orientations. Taken into the earth frame through the sensors'
// filters, the two agree in their vertical parts (the inclinations are the accelerometers') and
// their horizontal parts are turned against each other by the difference of the two headings'
// errors - whatever the magnetometer does, so that a heading that is the gyroscope's alone (no
// magnetometer calibration yet) can be set against its neighbour's while the body moves. The
// angle that turns the parent side's horizontal acceleration onto the child side's is averaged
// as the sums of their cross and dot products (each pair weighted by the product of their
// sizes), with a memory so that it follows the gyroscope's drift. Still, the joint's
// acceleration is gravity alone and tells nothing: the answer waits for the body to move (walking
// gives 1-4 m/s^2 at the hips, knees and elbows). docs/body-calibration.md, "Headings from the
// joints".
#pragma once

#include <array>
#include <optional>

#include "fusion/body/kinematics.h"

namespace caphub::body {

struct JointHeadingOptions {
    // Each side's joint acceleration low-passed with this time constant (s) before the two are
    // compared: the samples of two sensors on two buses are a few ms apart, and the
    // differentiated gyroscope is noisy.
    double filterTauS = 0.03;
    // The sums' memory (s): long against a stride, short against the gyroscope's drift.
    double memoryS = 20.0;
    // An answer needs this much horizontal acceleration ((m/s^2)^2 s, the sum of the products of
    // the two sides' sizes over time: a walk's elbow gives 2-3 a second, its knee tens), ...
    double minEnergy = 1.5;
    // ... turned by one angle: the resultant length of the products (1 when every pair gave the
    // same angle).
    double minConsistency = 0.9;
    // A pair whose vertical parts, or whose horizontal sizes, differ by more than this (m/s^2)
    // is not one acceleration seen twice (the model's limits: a joint that is no point, skin
    // sliding, a clip's artefact) and is left out.
    double maxMismatchMps2 = 1.5;
    // A pair with a side beyond this horizontal acceleration (m/s^2) is left out too: an impact
    // (a heel strike's spike, where a millisecond's misalignment or the skin's give decides the
    // direction) or a clip's artefact, not a body's motion.
    double maxAccelerationMps2 = 30.0;
    // The two sides' latest accelerations are compared only when their samples are this close (s).
    double maxSkewS = 0.012;
};

class JointHeading {
public:
    explicit JointHeading(const JointHeadingOptions& options = {}) : options_(options) {}

    enum Side { Parent = 0, Child = 1 };
    // One side's joint acceleration (earth frame, ENU, m/s^2) at tS (s). A child sample is paired
    // with the parent side's latest.
    void add(Side side, double tS, const Vec3d& accEnuMps2);
    // The angle (rad, about up) that turns the parent side's horizontal joint acceleration onto
    // the child's: the child's heading error less the parent's. None before enough motion, or
    // while the pairs disagree.
    std::optional<double> angleRad() const;
    // A side's orientations were turned by angleRad about up from now on: what is held of it
    // (its filtered acceleration, the sums) turns with it.
    void turn(Side side, double angleRad);
    void reset();

    double energy() const { return energy_; }
    // Pairs taken and left out (maxMismatchMps2) so far.
    long pairs() const { return pairs_; }
    long mismatched() const { return mismatched_; }
    double consistency() const;

private:
    JointHeadingOptions options_;
    struct Filtered {
        Vec3d acc = Vec3d::Zero();
        double tS = 0;
        Vec3d previousAcc =
            Vec3d::Zero();  // the one before (interpolated to the other side's time)
        double previousS = 0;
        bool valid = false;
        bool hasPrevious = false;
        // The filtered acceleration at tS: between (or on from) the two latest.
        Vec3d at(double tS) const;
    };
    std::array<Filtered, 2> sides_;
    double sumCross_ = 0;  // sum of w (p x c)_z: sin of the angle times the sizes
    double sumDot_ = 0;    // sum of w (p . c)
    double energy_ = 0;    // sum of w |p| |c|
    double lastPairS_ = 0;
    bool paired_ = false;
    long pairs_ = 0;
    long mismatched_ = 0;
};

}  // namespace caphub::body
