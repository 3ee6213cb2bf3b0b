// caphub's H-Anim skeleton: the joint tree over the 21 segments of board/segment.h, the paper's
// per-bone record (Segment_Joint), joint limits, and body proportions from the subject's height
// or measured lengths. The tree, the proportions and the limits are documented in docs/skeleton.md.
#pragma once

#include <array>
#include <cstdint>
#include <string_view>
#include <vector>

#include "board/segment.h"
#include "board/subject.h"
#include "hal/core/error.h"
#include "hal/core/quaternion.h"

namespace caphub::body {

using board::Segment;
inline constexpr int kSegmentCount = board::kSegmentCount;

constexpr int idx(Segment s) {
    return static_cast<int>(s);
}

// How a joint's rotation is obtained (docs/skeleton.md, "The 17 joints").
enum class JointKind : std::uint8_t {
    Root,     // humanoid_root: 6 DOF, the pelvis' world pose
    Driven,   // articulated; its child segment is sensor-driven on the full suit
    Derived,  // takes a share of a spine rotation (vl5, vc7)
    Fixed,    // follows its parent (the toes)
};

// Soft limits of a joint rotation, as the components of its rotation vector in the parent
// segment's frame (X left, Y up, Z forward in the reference pose), degrees.
struct JointLimits {
    Vec3d minDeg = Vec3d::Constant(-180);
    Vec3d maxDeg = Vec3d::Constant(180);
};

// The joint that joins segment s to its parent: one per segment (the pelvis' is the root).
struct JointInfo {
    Segment segment;
    std::string_view name;  // H-Anim joint name
    int parent;             // parent segment index; -1 for the pelvis
    JointKind kind;
    int dof;  // anatomical degrees of freedom (the solver keeps all 3 rotations)
    JointLimits limits;
};

// The joint table in tree order: every parent comes before its children.
const std::array<JointInfo, kSegmentCount>& joints();
const JointInfo& jointInfo(Segment s);
namespace detail {
// The table joints() returns (skeleton.cpp), read inline by parentOf on the per-frame chain walks.
extern const std::array<JointInfo, kSegmentCount> kJointTable;
}  // namespace detail
inline int parentOf(int segment) {
    return detail::kJointTable[static_cast<std::size_t>(segment)].parent;
}

// The paper's 17 independent joints (docs/skeleton.md, "The paper's 17 joints on 21 segments"):
// the rotation from the proximal segment's frame to the distal one's, centred at the origin of
// `centre`. The lumbar joint spans pelvis -> t12 (vl5 + vt12, centred at l5's origin) and the
// cervical one t12 -> skull (vc7 + skullbase, at c7's origin); the root's proximal is -1 (its
// rotation is the pelvis' world orientation). The toes' fixed joints are not among them.
struct IndependentJoint {
    std::string_view name;
    int proximal;
    int distal;
    int centre;
};
inline constexpr int kIndependentJointCount = 17;
const std::array<IndependentJoint, kIndependentJointCount>& independentJoints();

// Points that are not a segment's origin: the tips of the chains (the Jacobian's end
// effectors) and the foot points used for ground contact.
enum class EndEffector : int { Head, LHand, RHand, LFoot, RFoot };
inline constexpr int kEndEffectorCount = 5;
std::string_view endEffectorName(EndEffector e);
Segment endEffectorSegment(EndEffector e);

// Where the foot touches the ground: heel, ball (the toe joint) and toe tip.
inline constexpr int kFootPointCount = 3;

// Animation playback state of a bone, for replays (the paper's last three fields).
struct Playback {
    std::int64_t currentFrame = 0;
    double speed = 1.0;        // playback rate, 1 = real time
    double blendWeight = 1.0;  // weight of this clip when blending with another
};

// The paper's Segment_Joint record (docs/skeleton.md). Static description plus current state.
struct Bone {
    int id = 0;                     // = segment index
    std::string_view name;          // H-Anim segment name
    std::string_view jointName;     // H-Anim name of the joint at its proximal end
    double lengthM = 0;             // proximal joint to the distal joint or end site
    double massKg = 0;              // 0 when the subject's mass is unknown
    Vec3d centreOfMassM;            // in the segment frame, from its origin
    int dof = 0;                    // anatomical DOF of its joint
    JointLimits limits;             // of its joint
    std::vector<int> meshElements;  // skin polygons attached to it (filled by render)
    int parent = -1;
    std::array<int, 3> children{-1, -1, -1};
    int childCount = 0;
    // Reference (T-pose) transform relative to the parent segment frame.
    Vec3d baseScale = Vec3d::Ones();
    Quatd baseRotation = Quatd::Identity();
    Vec3d baseTranslationM = Vec3d::Zero();
    // After the last solve, relative to the parent segment frame.
    Vec3d currentScale = Vec3d::Ones();
    Quatd currentRotation = Quatd::Identity();
    Vec3d currentTranslationM = Vec3d::Zero();
    Quatd animationQuaternion = Quatd::Identity();  // the driving quaternion (world)
    int channel = -1;                               // input channel (sensor index), -1: none
    Playback playback;
};

// Segment dimensions: the vector from each segment's parent origin to its own origin in the
// reference pose (world frame = segment frames), and the end sites.
struct Dimensions {
    std::array<Vec3d, kSegmentCount> offsetM{};            // offsetM[pelvis] is the root's height
    std::array<Vec3d, kEndEffectorCount> endSiteM{};       // from the end segment's origin
    std::array<Vec3d, kFootPointCount> leftFootPointM{};   // heel, ball, toe tip: from l_hindfoot
    std::array<Vec3d, kFootPointCount> rightFootPointM{};  // from r_hindfoot
    std::array<double, kSegmentCount> massKg{};
    // Each segment's share of the body's mass (sums to 1), known without the subject's mass:
    // where the whole body's centre of mass is (a jump's flight).
    std::array<double, kSegmentCount> massFraction{};
    std::array<Vec3d, kSegmentCount> centreOfMassM{};  // segment frame
};

// Proportions from the subject's height (Drillis & Contini 1966 length fractions, Dempster
// via Winter mass fractions and centres of mass; docs/skeleton.md), with any measured segment
// lengths from the suit file replacing the derived ones. Errors for a height outside
// 0.5-2.5 m, a mass outside 10-400 kg, or a measured length outside 0.01-1.5 m.
Result<Dimensions> dimensionsFromSubject(const board::SubjectConfig& subject);

// Each segment's centre of mass (Dempster via Winter: along the bone from its proximal joint)
// from the dimensions' bones: again after the bones change (a skeleton measured from a clip).
void setCentresOfMass(Dimensions& d);

// The segment length a set of dimensions implies (the distance to the distal joint or end
// site along the chain's main child).
double segmentLengthM(const Dimensions& d, Segment s);

class Skeleton {
public:
    explicit Skeleton(const Dimensions& d);

    const Dimensions& dimensions() const { return dims_; }
    const Bone& bone(Segment s) const { return bones_[static_cast<std::size_t>(idx(s))]; }
    Bone& bone(Segment s) { return bones_[static_cast<std::size_t>(idx(s))]; }
    const std::array<Bone, kSegmentCount>& bones() const { return bones_; }

    // Tip of chain e in the segment frame of its end segment.
    const Vec3d& endSiteM(EndEffector e) const {
        return dims_.endSiteM[static_cast<std::size_t>(e)];
    }
    // The chain from the pelvis to e's segment, root first; returns its length.
    int chain(EndEffector e, std::array<int, 8>& out) const;

private:
    Dimensions dims_;
    std::array<Bone, kSegmentCount> bones_;
};

}  // namespace caphub::body
