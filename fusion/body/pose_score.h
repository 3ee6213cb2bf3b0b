// Scores solved poses against a ground truth of the same body: per joint the angle error of the
// joint rotation and the position error of the joint centre relative to the root, and the
// horizontal drift of the root over the distance walked. One scoring for every evaluation (ideal
// orientations in tests/body, the whole suit -> fusion -> body path in `caphub evaluate`).
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "fusion/body/body_calibration.h"
#include "fusion/body/kinematics.h"
#include "fusion/body/skeleton.h"

namespace caphub::body {

// The true state of the body at one instant, in the skeleton world frame (docs/frames.md):
// each segment's orientation (segment -> world) and origin (its proximal joint).
struct BodyTruth {
    std::array<Quatd, kSegmentCount> qWorldSegment;
    std::array<Vec3d, kSegmentCount> positionM;
    BodyTruth() {
        qWorldSegment.fill(Quatd::Identity());
        positionM.fill(Vec3d::Zero());
    }
};

// Bit i for segment i (as body::SegmentMask).
inline constexpr std::uint32_t kAllSegments = (std::uint32_t{1} << kSegmentCount) - 1;

struct PoseScore {
    int frames = 0;
    // The segments the suit measures (PoseSolver::coveredSegments): the means are over their
    // joints only, and the tables mark the rest "not measured". A joint of the paper's 17 counts
    // when both its segments are measured. The root's translation counts when both feet are.
    std::uint32_t measured = kAllSegments;
    // Per joint (segment index): mean angle error of the joint rotation (the pelvis: of its
    // world orientation), deg; mean position error of the joint centre relative to the root, m.
    std::array<double, kSegmentCount> angleDeg{};
    std::array<double, kSegmentCount> positionM{};
    double meanAngleDeg = 0;   // over the 21 joints (the measured ones)
    double meanPositionM = 0;  // over the 20 joints below the root (the measured ones)
    int measuredJoints = kSegmentCount;
    int measuredIndependentJoints = kIndependentJointCount;
    // The same for the paper's 17 independent joints (independentJoints(): the lumbar and
    // cervical joints as the whole pelvis -> t12 and t12 -> skull rotations, no toes).
    std::array<double, kIndependentJointCount> independentAngleDeg{};
    std::array<double, kIndependentJointCount> independentPositionM{};
    double independentMeanAngleDeg = 0;   // over the 17 (the measured ones)
    double independentMeanPositionM = 0;  // over the 16 below the root (the measured ones)
    double walkedM = 0;                   // horizontal path length of the true root
    // The true root's largest horizontal distance from where it was at the first frame: a clip
    // "in place" (a jump, a squat, hammering) stays within a few decimetres however long its
    // path of sway is.
    double excursionM = 0;
    double finalDriftM = 0;  // horizontal distance between solved and true root at the end
    double maxDriftM = 0;
    // The root's height against the truth's, the offset at the first frame removed (the floor
    // the solver assumes and the clip's floor need not be at one height): mean and largest
    // absolute error, m. Jumps and crouches show here.
    double meanHeightErrorM = 0;
    double maxHeightErrorM = 0;
    // Filled in by the caller (the solver's root tracker); -1: not known (a reprocessed take's,
    // scored from its records), and not printed.
    int stanceChanges = -1;
};

// Whether the paper's independent joint j rests on measured segments only.
bool independentJointMeasured(std::uint32_t measured, std::size_t j);

class PoseScorer {
public:
    // How the solved root is put on the true one. Absolute: as solved (the solver's root was
    // reset to the true root); AtFirstFrame: the horizontal offset at the first scored frame
    // is removed from every later one (the solver's root was reset anywhere, e.g. at a
    // calibration before the scored part).
    enum class RootOrigin : std::uint8_t { Absolute, AtFirstFrame };

    explicit PoseScorer(RootOrigin origin = RootOrigin::Absolute) : origin_(origin) {}

    // The segments the suit measures (default: all); see PoseScore::measured.
    void setMeasured(std::uint32_t segments) { sum_.measured = segments & kAllSegments; }

    void add(const Pose& solved, const BodyTruth& truth);
    // The means over the frames added so far; none before the first frame: a mean over nothing
    // is no score, and must not read as a perfect 0.
    std::optional<PoseScore> score() const;

private:
    RootOrigin origin_;
    PoseScore sum_;
    std::optional<Vec3d> lastTrueRootM_;
    Vec3d firstTrueRootM_ = Vec3d::Zero();
    Vec3d rootOffsetM_ = Vec3d::Zero();  // true minus solved, horizontal, at the first frame
    double heightOffsetM_ = 0;           // true minus solved root height at the first frame
};

// The subject's skeleton measured from true frames: each bone vector in its parent's frame,
// averaged over the frames (segments made of several mocap joints are not perfectly rigid), the
// foot contact points from the foot's bone (a clip with no toes: the default subject's foot,
// scaled with the measured leg); the rest (end sites, masses) from the default subject. frames
// must not be empty.
Dimensions measuredDimensions(const std::vector<BodyTruth>& frames);

// The per-joint tables (markdown; the 21 segments' joints, then the paper's 17) and the root's
// line.
std::string formatScoreTable(const PoseScore& s);

}  // namespace caphub::body
