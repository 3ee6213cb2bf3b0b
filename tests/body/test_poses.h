// Synthetic poses and sensor frames for the body tests: random joint rotations through the
// skeleton's own FK, random mountings, and the sensor orientations they imply.
#pragma once

#include <random>

#include "fusion/body/body_calibration.h"
#include "fusion/body/kinematics.h"

namespace caphub::body::testing {

inline Quatd randomRotation(std::mt19937& rng, double maxAngleRad) {
    std::normal_distribution<double> n(0, 1);
    std::uniform_real_distribution<double> u(0, maxAngleRad);
    Vec3d axis(n(rng), n(rng), n(rng));
    return fromAxisAngle<double>(axis.normalized(), u(rng));
}

inline Pose randomPose(std::mt19937& rng, double maxJointRad) {
    Pose p;
    for (auto& q : p.qLocal) {
        q = randomRotation(rng, maxJointRad);
    }
    worldFromLocal(p);
    return p;
}

// q_ENU_sensor for every segment in mask, given the true pose and mountings.
inline SensorFrame sensorsFor(const Pose& pose, const std::array<Quatd, kSegmentCount>& mounting,
                              SegmentMask mask, double headingRad = 0) {
    BodyCalibration c;
    c.headingRad = headingRad;
    const Quatd qEnuWorld = c.qEnuWorld();
    SensorFrame f;
    f.mask = mask;
    for (int i = 0; i < kSegmentCount; ++i) {
        const auto u = static_cast<std::size_t>(i);
        f.qEnuSensor[u] = (qEnuWorld * pose.qWorld[u] * mounting[u]).normalized();
    }
    return f;
}

inline Pose referencePose(ReferencePoseKind kind) {
    Pose p;
    for (int i = 0; i < kSegmentCount; ++i) {
        p.qWorld[static_cast<std::size_t>(i)] = referenceOrientation(kind, static_cast<Segment>(i));
    }
    localFromWorld(p);
    return p;
}

inline constexpr SegmentMask kAll = (SegmentMask{1} << kSegmentCount) - 1;

// The 17 sensors of board/sim-suit.toml.
inline constexpr SegmentMask kFullSuit =
    kAll &
    ~(bit(Segment::L5) | bit(Segment::C7) | bit(Segment::LMiddistal) | bit(Segment::RMiddistal));

// The paper's 10 upper-body sensors (board/sim-upper10.toml).
inline constexpr SegmentMask kUpper10 =
    bit(Segment::Pelvis) | bit(Segment::L5) | bit(Segment::T12) | bit(Segment::Skull) |
    bit(Segment::LUpperarm) | bit(Segment::LForearm) | bit(Segment::LHand) |
    bit(Segment::RUpperarm) | bit(Segment::RForearm) | bit(Segment::RHand);

}  // namespace caphub::body::testing
