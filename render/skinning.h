// Per-frame skinning of a Skin by the skeleton's pose: rigid groups with one transform, deformable
// groups by linear blending (paper eqs. 14-16) or dual quaternions, chosen per group.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "hal/core/error.h"
#include "hal/core/quaternion.h"
#include "render/skin.h"

namespace caphub::render {

// One skinned vertex as the renderer uploads it: position and normal, each padded to 4 floats
// (w = 1 and 0) so that a vertex is two aligned 16-byte vectors.
struct alignas(32) SkinnedVertex {
    float position[4];
    float normal[4];
};

// Segment transforms for one frame: the rotation of each segment (segment -> world) and where
// the pelvis origin is. Segment origins follow by forward kinematics over the skin's own joint
// origins, so the mesh keeps its proportions whatever the skeleton's (docs/render.md).
struct SkinPose {
    std::array<Quatd, kSegmentCount> qWorld;
    Vec3d pelvisM = Vec3d::Zero();
    SkinPose() { qWorld.fill(Quatd::Identity()); }
};

class Skinner {
public:
    explicit Skinner(const Skin& skin);

    // Changes how a group is skinned. Rigid is refused for a group whose vertices are not all
    // weighted fully to one segment.
    Result<void> setGroupMethod(int group, GroupMethod method);
    GroupMethod groupMethod(int group) const {
        return groups_[static_cast<std::size_t>(group)].method;
    }
    // Every rigid group skinned by linear blending instead (their weights are 1 on one segment,
    // so the result is the same): to measure what rigid groups save.
    void setRigidGroupsBlended(bool blended);

    // Computes the 21 segment transforms (matrices and dual quaternions) for a pose.
    void setPose(const SkinPose& pose);
    // Skins every vertex of the current pose into output().
    void skin();

    std::span<const SkinnedVertex> output() const { return out_; }
    std::size_t vertexCount() const { return out_.size(); }
    // World origin of each segment in the current pose (the skin's joints).
    const std::array<Vec3d, kSegmentCount>& jointPositionsM() const { return jointPositionsM_; }

    // Per segment: a 3x4 affine matrix as four columns of 4 floats (the fourth is the
    // translation), and a unit dual quaternion (real x y z w, dual x y z w).
    struct alignas(32) Matrix {
        float c[16];
    };
    struct alignas(32) DualQuat {
        float q[8];
    };

private:
    struct Group {
        GroupMethod method;
        bool rigidCapable;
        int segment;
        std::uint32_t first, count;
    };
    struct alignas(32) BindVertex {
        float position[4];
        float normal[4];
    };
    std::vector<BindVertex> bind_;
    std::vector<std::array<std::uint8_t, 4>> joints_;
    std::vector<std::array<float, 4>> weights_;
    std::vector<Group> groups_;
    std::vector<SkinnedVertex> out_;
    std::array<Vec3d, kSegmentCount> originsM_;
    std::array<Vec3d, kSegmentCount> jointPositionsM_;
    std::array<Matrix, kSegmentCount> matrices_;
    std::array<DualQuat, kSegmentCount> dualQuats_;
    bool rigidBlended_ = false;
};

}  // namespace caphub::render
