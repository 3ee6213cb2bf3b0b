// The skeleton: the joint tree, the paper's joint count, proportions from height and from
// measured lengths, masses, and mirrored joint limits.
#include "fusion/body/skeleton.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace caphub::body {
namespace {

using ::testing::HasSubstr;
using S = Segment;

Dimensions dims(double heightM, std::optional<double> massKg = std::nullopt) {
    board::SubjectConfig s;
    s.heightM = heightM;
    s.massKg = massKg;
    auto d = dimensionsFromSubject(s);
    EXPECT_TRUE(d.ok()) << d.error().message;
    return d.ok() ? *d : Dimensions{};
}

TEST(Skeleton, EveryParentComesBeforeItsChildren) {
    for (int i = 1; i < kSegmentCount; ++i) {
        EXPECT_GE(parentOf(i), 0) << i;
        EXPECT_LT(parentOf(i), i) << i;
    }
    EXPECT_EQ(parentOf(0), -1);
}

TEST(Skeleton, SeventeenIndependentJointsOverTwentyOneSegments) {
    int independent = 0;
    int derived = 0;
    int fixed = 0;
    for (const auto& j : joints()) {
        independent += j.kind == JointKind::Root || j.kind == JointKind::Driven ? 1 : 0;
        derived += j.kind == JointKind::Derived ? 1 : 0;
        fixed += j.kind == JointKind::Fixed ? 1 : 0;
    }
    EXPECT_EQ(independent, 17);
    EXPECT_EQ(derived, 2);
    EXPECT_EQ(fixed, 2);
}

TEST(Skeleton, ThePapersJointsSpanTheSpineAndLeaveOutTheToes) {
    const auto& ij = independentJoints();
    int lumbar = 0;
    int cervical = 0;
    for (const IndependentJoint& j : ij) {
        EXPECT_NE(j.distal, idx(S::LMiddistal));
        EXPECT_NE(j.distal, idx(S::RMiddistal));
        EXPECT_NE(j.distal, idx(S::L5));
        EXPECT_NE(j.distal, idx(S::C7));
        if (j.proximal < 0) {
            EXPECT_EQ(j.distal, idx(S::Pelvis));
            continue;
        }
        if (j.distal == idx(S::T12)) {
            ++lumbar;
            EXPECT_EQ(j.proximal, idx(S::Pelvis));
            EXPECT_EQ(j.centre, idx(S::L5));
        } else if (j.distal == idx(S::Skull)) {
            ++cervical;
            EXPECT_EQ(j.proximal, idx(S::T12));
            EXPECT_EQ(j.centre, idx(S::C7));
        } else {
            EXPECT_EQ(j.proximal, parentOf(j.distal)) << j.name;
            EXPECT_EQ(j.centre, j.distal) << j.name;
        }
    }
    EXPECT_EQ(lumbar, 1);
    EXPECT_EQ(cervical, 1);
}

TEST(Skeleton, JointsCarryHAnimNames) {
    EXPECT_EQ(jointInfo(S::Pelvis).name, "humanoid_root");
    EXPECT_EQ(jointInfo(S::LForearm).name, "l_elbow");
    EXPECT_EQ(jointInfo(S::RHindfoot).name, "r_talocrural");
    EXPECT_EQ(jointInfo(S::LMiddistal).name, "l_metatarsophalangeal");
    EXPECT_EQ(jointInfo(S::Skull).name, "skullbase");
}

TEST(Skeleton, LengthsAreDrillisContiniFractionsOfHeight) {
    const Dimensions d = dims(1.80);
    // Exact fractions of the table; 1e-12 is rounding only.
    EXPECT_NEAR(segmentLengthM(d, S::LUpperarm), 0.186 * 1.80, 1e-12);
    EXPECT_NEAR(segmentLengthM(d, S::RForearm), 0.146 * 1.80, 1e-12);
    EXPECT_NEAR(segmentLengthM(d, S::LHand), 0.108 * 1.80, 1e-12);
    EXPECT_NEAR(segmentLengthM(d, S::RThigh), 0.245 * 1.80, 1e-12);
    EXPECT_NEAR(segmentLengthM(d, S::LCalf), 0.246 * 1.80, 1e-12);
    EXPECT_NEAR(d.offsetM[idx(S::Pelvis)].y(), 0.530 * 1.80, 1e-12);
}

TEST(Skeleton, ReferencePoseStandsTheSubjectsHeightTall) {
    const Dimensions d = dims(1.62);
    // Root height + spine + neck + head = vertex at H (the table's levels add up exactly).
    double top = 0;
    for (S s : {S::Pelvis, S::L5, S::T12, S::C7, S::Skull}) {
        top += d.offsetM[idx(s)].y();
    }
    top += d.endSiteM[static_cast<int>(EndEffector::Head)].y();
    EXPECT_NEAR(top, 1.62, 1e-12);
    // Hip height minus thigh and shank: the ankle at 0.039 H.
    const double ankle = d.offsetM[idx(S::Pelvis)].y() + d.offsetM[idx(S::LCalf)].y() +
                         d.offsetM[idx(S::LHindfoot)].y();
    EXPECT_NEAR(ankle, 0.039 * 1.62, 1e-12);
}

TEST(Skeleton, MeasuredLengthReplacesDerivedOne) {
    board::SubjectConfig s;
    s.heightM = 1.75;
    s.segmentLengthsM = {{S::LThigh, 0.47}};
    auto d = dimensionsFromSubject(s);
    ASSERT_TRUE(d.ok());
    EXPECT_NEAR(segmentLengthM(*d, S::LThigh), 0.47, 1e-12);
    EXPECT_NEAR(segmentLengthM(*d, S::RThigh), 0.245 * 1.75, 1e-12);  // the other stays
}

TEST(Skeleton, SegmentMassesAddUpToTheSubjectsMass) {
    const Dimensions d = dims(1.75, 72.0);
    double sum = 0;
    for (double m : d.massKg) {
        sum += m;
    }
    EXPECT_NEAR(sum, 72.0, 1e-9);  // Dempster's fractions sum to 1
    EXPECT_NEAR(d.massKg[idx(S::LThigh)], 7.2, 1e-12);
}

TEST(Skeleton, ImplausibleSubjectIsRejectedWithWhatWasExpected) {
    board::SubjectConfig s;
    s.heightM = 17.5;
    auto d = dimensionsFromSubject(s);
    ASSERT_FALSE(d.ok());
    EXPECT_THAT(d.error().message, HasSubstr("expected 0.5 to 2.5 m"));
    s.heightM = 1.75;
    s.segmentLengthsM = {{S::LForearm, -0.2}};
    d = dimensionsFromSubject(s);
    ASSERT_FALSE(d.ok());
    EXPECT_THAT(d.error().message, HasSubstr("l_forearm"));
}

TEST(Skeleton, RightLimitsMirrorLeftOnes) {
    const auto& l = jointInfo(S::LUpperarm).limits;
    const auto& r = jointInfo(S::RUpperarm).limits;
    EXPECT_EQ(r.minDeg.x(), l.minDeg.x());
    EXPECT_EQ(r.maxDeg.y(), -l.minDeg.y());
    EXPECT_EQ(r.minDeg.z(), -l.maxDeg.z());
}

TEST(Skeleton, BonesRecordTheTreeAndTheReferencePose) {
    const Skeleton sk(dims(1.75));
    const Bone& t12 = sk.bone(S::T12);
    EXPECT_EQ(t12.childCount, 3);  // c7 and both clavicles
    EXPECT_EQ(t12.jointName, "vt12");
    EXPECT_EQ(sk.bone(S::LHand).parent, idx(S::LForearm));
    EXPECT_EQ(sk.bone(S::LForearm).baseTranslationM, sk.dimensions().offsetM[idx(S::LForearm)]);
    std::array<int, 8> chain{};
    EXPECT_EQ(sk.chain(EndEffector::LHand, chain), 7);
    EXPECT_EQ(chain[0], idx(S::Pelvis));
    EXPECT_EQ(chain[6], idx(S::LHand));
}

}  // namespace
}  // namespace caphub::body
