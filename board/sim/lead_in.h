// A reference pose before the clip: the subject stands in a calibration pose - the T-pose (every
// segment aligned with the world, facing +Z) or any other given as segment orientations, such
// as the N-pose - then moves smoothly into the clip's first pose and motion: what a person
// wearing a suit does when a capture starts with a calibration pose.
#pragma once

#include <array>
#include <memory>

#include "board/sim/motion.h"

namespace caphub::board::sim {

class LeadInMotion final : public SegmentTrajectory {
public:
    // Holds the T-pose for holdS, then blends over blendS into the clip; the clip's time 0 is
    // at holdS + blendS. The pose stands where the clip starts (the pelvis at its first
    // position), with the bone vectors of the clip's first pose.
    LeadInMotion(std::shared_ptr<const Motion> clip, double holdS, double blendS);
    // The same with the pose held given as each segment's orientation in the skeleton world.
    LeadInMotion(std::shared_ptr<const Motion> clip, double holdS, double blendS,
                 const std::array<Quatd, board::kSegmentCount>& pose);

    void evaluate(board::Segment s, std::int64_t tNs, SegmentState& out) const override;

    std::int64_t leadInNs() const { return holdNs_ + blendNs_; }
    std::int64_t durationNs() const { return leadInNs() + clip_->durationNs(); }
    const Motion& clip() const { return *clip_; }

private:
    // The blend at tNs into it, orientation and position only (rates by difference).
    void blendPose(board::Segment s, std::int64_t tNs, Quatd& q, Vec3d& p, Vec3d& v,
                   Vec3d& a) const;
    // The orientation at any instant, lead-in or clip.
    Quatd orientationAt(board::Segment s, std::int64_t tNs) const;

    std::shared_ptr<const Motion> clip_;
    std::int64_t holdNs_ = 0;
    std::int64_t blendNs_ = 0;
    std::array<Quatd, board::kSegmentCount> pose_{};          // the pose held
    std::array<Vec3d, board::kSegmentCount> poseM_{};         // each origin in it
    std::array<SegmentState, board::kSegmentCount> start_{};  // the clip at its time 0
};

}  // namespace caphub::board::sim
