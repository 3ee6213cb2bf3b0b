// The T-pose lead-in: the subject stands in the T-pose, then moves into the clip without a jump
// in pose, rate or acceleration, with rates that are the derivatives of the pose.
#include "board/sim/lead_in.h"

#include <filesystem>
#include <memory>

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
