// Segment trajectories of the virtual suit: each segment's world orientation and position as
// smooth functions of time (cumulative cubic B-splines, docs/virtual-suit.md), so that gyro and
// accelerometer signals sampled at any instant are physically plausible between mocap frames.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <vector>

#include "board/segment.h"
#include "board/sim/bvh.h"
#include "board/sim/joint_map.h"
#include "hal/core/error.h"
#include "hal/core/quaternion.h"

namespace caphub::board::sim {

// The true state of one segment at one instant, in the skeleton world frame (docs/frames.md).
struct SegmentState {
    Quatd qWorldSegment = Quatd::Identity();  // segment -> world
    Vec3d positionM = Vec3d::Zero();          // the segment's origin: its proximal joint
    Vec3d velocityMps = Vec3d::Zero();        // of the origin, world frame
    Vec3d accelerationMps2 = Vec3d::Zero();   // of the origin, world frame (gravity excluded)
    Vec3d omegaRadS = Vec3d::Zero();          // angular velocity, segment frame
    Vec3d alphaRadS2 = Vec3d::Zero();         // angular acceleration, segment frame
};

using SuitState = std::array<SegmentState, board::kSegmentCount>;

// Anything that can say where a segment is and how it moves: the BVH-driven Motion, or an
// analytic motion in tests. evaluate() must not allocate: it runs once per simulated sample.
class SegmentTrajectory {
public:
    virtual ~SegmentTrajectory() = default;
    virtual void evaluate(board::Segment s, std::int64_t tNs, SegmentState& out) const = 0;
};

struct MotionOptions {
    std::optional<double> unitM;             // overrides the map's unit (metres per BVH unit)
    std::optional<ReferencePose> reference;  // overrides the map's; default frame 0
    std::optional<int> firstFrame;           // overrides the map's; default 0
    // Zero-phase low-pass of the mocap frames before the spline is fitted (-3 dB frequency, Hz;
    // 0: off). Mocap jitter of a millimetre or a degree per frame would otherwise become tens
    // of m/s^2 and thousands of rad/s^2 on the simulated sensors (docs/virtual-suit.md).
    double smoothingHz = 10;
    // true: the spline passes through every (smoothed) frame, control points solved for;
    // false: the frames are the control points, which smooths a little more.
    bool interpolate = true;
};

// A clip turned into 21 smooth segment trajectories. Time 0 is the first frame of motion (the
// map's or the option's firstFrame); before it and after the last frame the pose is held and
// every rate is zero. Frame numbers below count from the first frame of motion, except the
// reference frame, which is a frame of the file.
class Motion final : public SegmentTrajectory {
public:
    static Result<Motion> fromClip(const BvhClip& clip, const JointMap& map,
                                   const MotionOptions& options = {});

    void evaluate(board::Segment s, std::int64_t tNs, SegmentState& out) const override;

    // The ground truth of the whole suit at one instant.
    void evaluateAll(std::int64_t tNs, SuitState& out) const;

    // The keyframe the spline was fitted to (reference, unit and smoothing applied).
    Quatd keyOrientation(board::Segment s, int frame) const;
    Vec3d keyPositionM(board::Segment s, int frame) const;

    bool mapped(board::Segment s) const;
    int frameCount() const { return frameCount_; }  // frames of motion
    int firstFrame() const { return firstFrame_; }  // in the file
    double frameTimeS() const { return frameTimeS_; }
    std::int64_t durationNs() const;
    double unitM() const { return unitM_; }
    ReferencePose reference() const { return reference_; }
    // The largest knot residual left by the interpolation solve (rad); 0 when not interpolating.
    double fitResidualRad() const { return fitResidualRad_; }

private:
    // Control points padded with one phantom at each end: ctrl[m] is c_{m-1}.
    struct Track {
        std::vector<Quatd> q;
        std::vector<Vec3d> logQ;  // logQ[m] = log(q[m-1]^-1 q[m]), body frame; logQ[0] unused
        std::vector<Vec3d> p;
        std::vector<Vec3d> dP;  // dP[m] = p[m] - p[m-1]
        std::vector<Quatd> keyQ;
        std::vector<Vec3d> keyP;
    };

    Motion() = default;
    const Track& track(board::Segment s) const;

    std::array<Track, board::kSegmentCount> tracks_;
    std::array<board::Segment, board::kSegmentCount> source_{};
    std::array<bool, board::kSegmentCount> mapped_{};
    int frameCount_ = 0;
    int firstFrame_ = 0;
    double frameTimeS_ = 0;
    double unitM_ = 1;
    ReferencePose reference_;
    double fitResidualRad_ = 0;
};

}  // namespace caphub::board::sim
