// The T-pose lead-in: the subject stands in the T-pose, then moves into the clip without a jump
// in pose, rate or acceleration, with rates that are the derivatives of the pose.
#include "board/sim/lead_in.h"

#include <array>
#include <filesystem>
#include <memory>
#include <numbers>

#include <gtest/gtest.h>

#include "board/sim/bvh.h"
#include "board/sim/joint_map.h"

namespace caphub::board::sim {
namespace {

constexpr std::int64_t kMs = 1'000'000;

std::shared_ptr<const Motion> walk() {
    const auto clip = loadBvh(std::filesystem::path(CAPHUB_SOURCE_DIR) / "tests" / "data" / "bvh" /
                              "cmu_12_01_walk.bvh");
    return std::make_shared<const Motion>(*Motion::fromClip(*clip, *detectJointMap(*clip)));
}

SegmentState at(const SegmentTrajectory& m, Segment s, std::int64_t t) {
    SegmentState out;
    m.evaluate(s, t, out);
    return out;
}

TEST(LeadIn, StandsInTheTPoseThenJoinsTheClipWithoutAJump) {
    const auto clip = walk();
    const LeadInMotion m(clip, 2.0, 1.5);
    EXPECT_EQ(m.leadInNs(), 3'500 * kMs);
    for (Segment s : {Segment::Pelvis, Segment::LForearm, Segment::RCalf}) {
        const SegmentState still = at(m, s, 1'000 * kMs);
        EXPECT_TRUE(still.qWorldSegment.isApprox(Quatd::Identity())) << segmentName(s);
        EXPECT_EQ(still.omegaRadS.norm(), 0.0);
        EXPECT_EQ(still.velocityMps.norm(), 0.0);
        // Just before and at the clip's start: the same pose, rate and acceleration (within
        // what 1 ms of the clip's motion changes them).
        const SegmentState before = at(m, s, m.leadInNs() - kMs / 1000);
        const SegmentState after = at(*clip, s, 0);
        EXPECT_LT(before.qWorldSegment.angularDistance(after.qWorldSegment), 1e-3)
            << segmentName(s);
        EXPECT_LT((before.positionM - after.positionM).norm(), 1e-4) << segmentName(s);
        EXPECT_LT((before.omegaRadS - after.omegaRadS).norm(), 0.05) << segmentName(s);
        EXPECT_LT((before.velocityMps - after.velocityMps).norm(), 0.01) << segmentName(s);
    }
}

TEST(LeadIn, HoldsAGivenPoseWithTheBonesTurnedByIt) {
    // Arms down: the upper arms, forearms and hands turned a quarter turn about the forward
    // axis (+Z), as in an N-pose; everything else as in the T-pose.
    std::array<Quatd, kSegmentCount> pose;
    pose.fill(Quatd::Identity());
    const Quatd leftDown(Eigen::AngleAxisd(-std::numbers::pi / 2, Vec3d::UnitZ()));
    for (Segment s : {Segment::LUpperarm, Segment::LForearm, Segment::LHand}) {
        pose[static_cast<std::size_t>(s)] = leftDown;
    }
    const auto clip = walk();
    const LeadInMotion n(clip, 2.0, 1.5, pose);
    const LeadInMotion t(clip, 2.0, 1.5);
    const auto pos = [](const LeadInMotion& m, Segment s) {
        return at(m, s, kMs * 1000).positionM;
    };
    EXPECT_TRUE(at(n, Segment::LForearm, kMs * 1000).qWorldSegment.isApprox(leftDown));
    // The shoulder stays; the elbow, which is out to the side (+X) in the T-pose, hangs below
    // it by the same upper-arm length.
    EXPECT_LT((pos(n, Segment::LUpperarm) - pos(t, Segment::LUpperarm)).norm(), 1e-12);
    const Vec3d tBone = pos(t, Segment::LForearm) - pos(t, Segment::LUpperarm);
    const Vec3d nBone = pos(n, Segment::LForearm) - pos(n, Segment::LUpperarm);
    EXPECT_NEAR(nBone.norm(), tBone.norm(), 1e-12);
    EXPECT_LT((nBone - leftDown * tBone).norm(), 1e-12);
    EXPECT_LT(nBone.y(), -0.2);  // an upper arm is 0.25-0.35 m
    // The right arm and the legs do not move.
    EXPECT_LT((pos(n, Segment::RHand) - pos(t, Segment::RHand)).norm(), 1e-12);
    // And the blend still ends in the clip without a jump.
    const SegmentState before = at(n, Segment::LForearm, n.leadInNs() - kMs / 1000);
    const SegmentState after = at(*clip, Segment::LForearm, 0);
    EXPECT_LT(before.qWorldSegment.angularDistance(after.qWorldSegment), 1e-3);
}

TEST(LeadIn, BlendRatesAreTheDerivativesOfThePose) {
    const LeadInMotion m(walk(), 1.0, 1.5);
    for (Segment s : {Segment::Pelvis, Segment::LUpperarm, Segment::LHindfoot}) {
        for (std::int64_t t = 1'010 * kMs; t < 2'490 * kMs; t += 53 * kMs) {
            const SegmentState a = at(m, s, t - 500'000);
            const SegmentState b = at(m, s, t + 500'000);
            const SegmentState c = at(m, s, t);
            const Eigen::AngleAxisd d(a.qWorldSegment.conjugate() * b.qWorldSegment);
            // Central differences over 1 ms: errors of order 1e-6 of the rates at these speeds.
            EXPECT_LT((d.axis() * d.angle() / 1e-3 - c.omegaRadS).norm(), 1e-3) << t;
            EXPECT_LT(((b.positionM - a.positionM) / 1e-3 - c.velocityMps).norm(), 1e-4) << t;
            EXPECT_LT(((b.velocityMps - a.velocityMps) / 1e-3 - c.accelerationMps2).norm(), 1e-3)
                << t;
            EXPECT_LT(((b.omegaRadS - a.omegaRadS) / 1e-3 - c.alphaRadS2).norm(), 0.05) << t;
        }
    }
}

}  // namespace
}  // namespace caphub::board::sim
