// The scoring of solved poses against a truth: the 21 segments' joints and the paper's 17.
#include "fusion/body/pose_score.h"

#include <numbers>

#include <gtest/gtest.h>

namespace caphub::body {
namespace {

using S = Segment;

Quatd rotX(double deg) {
    return Quatd(Eigen::AngleAxisd(deg * std::numbers::pi / 180, Vec3d::UnitX()));
}

// A pose of the default subject from joint rotations, as a truth and as a solved pose.
Pose poseFrom(const std::array<Quatd, kSegmentCount>& local) {
    board::SubjectConfig subject;
    subject.heightM = 1.75;
    Pose p;
    p.qLocal = local;
    worldFromLocal(p);
    forwardKinematics(*dimensionsFromSubject(subject), Vec3d(0, 0.93, 0), p);
    return p;
}

BodyTruth truthOf(const Pose& p) {
    BodyTruth t;
    t.qWorldSegment = p.qWorld;
    t.positionM = p.positionM;
    return t;
}

std::array<Quatd, kSegmentCount> reference() {
    std::array<Quatd, kSegmentCount> q;
    q.fill(Quatd::Identity());
    return q;
}

TEST(PoseScore, NoFrameIsNoScoreNotAPerfectOne) {
    const PoseScorer empty;
    EXPECT_FALSE(empty.score().has_value());
    PoseScorer one;
    auto solvedLocal = reference();
    solvedLocal[idx(S::LForearm)] = rotX(10);
    one.add(poseFrom(solvedLocal), truthOf(poseFrom(reference())));
    ASSERT_TRUE(one.score());
    EXPECT_EQ(one.score()->frames, 1);
}

TEST(PoseScore, TheLumbarJointScoresTheWholeRotationNotItsSplit) {
    // The truth bends l5 13 deg forward and t12 16 deg back; the solver splits the same
    // -3 deg evenly. The two spine rows of the 21 are off by about 14.5 deg, the paper's
    // lumbar joint (pelvis -> t12) is exact.
    auto trueLocal = reference();
    trueLocal[idx(S::L5)] = rotX(13);
    trueLocal[idx(S::T12)] = rotX(-16);
    auto solvedLocal = reference();
    solvedLocal[idx(S::L5)] = rotX(-1.5);
    solvedLocal[idx(S::T12)] = rotX(-1.5);
    PoseScorer scorer;
    scorer.add(poseFrom(solvedLocal), truthOf(poseFrom(trueLocal)));
    ASSERT_TRUE(scorer.score());
    const PoseScore s = *scorer.score();

    EXPECT_NEAR(s.angleDeg[idx(S::L5)], 14.5, 1e-6);
    EXPECT_NEAR(s.angleDeg[idx(S::T12)], 14.5, 1e-6);
    for (std::size_t j = 0; j < independentJoints().size(); ++j) {
        EXPECT_NEAR(s.independentAngleDeg[j], 0, 1e-6) << independentJoints()[j].name;
    }
    EXPECT_NEAR(s.independentMeanAngleDeg, 0, 1e-6);
    EXPECT_NEAR(s.meanAngleDeg, 29.0 / kSegmentCount, 1e-6);
    // The spine's shape still moves everything above l5: positions are not forgiven.
    EXPECT_GT(s.positionM[idx(S::T12)], 0.01);
    EXPECT_GT(s.independentMeanPositionM, 0.005);
}

TEST(PoseScore, AnElbowErrorCountsOnceInEachTable) {
    auto trueLocal = reference();
    trueLocal[idx(S::LForearm)] = rotX(40);
    auto solvedLocal = trueLocal;
    solvedLocal[idx(S::LForearm)] = rotX(34);
    PoseScorer scorer;
    scorer.add(poseFrom(solvedLocal), truthOf(poseFrom(trueLocal)));
    ASSERT_TRUE(scorer.score());
    const PoseScore s = *scorer.score();
    EXPECT_NEAR(s.meanAngleDeg, 6.0 / kSegmentCount, 1e-6);
    EXPECT_NEAR(s.independentMeanAngleDeg, 6.0 / kIndependentJointCount, 1e-6);
    EXPECT_NEAR(s.independentPositionM[0], 0, 1e-12);  // the root
}

TEST(PoseScore, ASparseSuitIsScoredOverTheSegmentsItMeasures) {
    // The truth bends the left knee 30 deg and the left elbow 40 deg; the solver gets the elbow
    // 4 deg off and holds the leg straight, as a 10-sensor upper body does. Over the measured
    // segments only, the knee (held, not measured) does not count; every row is still there.
    auto trueLocal = reference();
    trueLocal[idx(S::LCalf)] = rotX(30);
    trueLocal[idx(S::LForearm)] = rotX(40);
    auto solvedLocal = trueLocal;
    solvedLocal[idx(S::LCalf)] = Quatd::Identity();
    solvedLocal[idx(S::LForearm)] = rotX(36);
    std::uint32_t upper = kAllSegments;
    for (S seg : {S::LThigh, S::LCalf, S::LHindfoot, S::LMiddistal, S::RThigh, S::RCalf,
                  S::RHindfoot, S::RMiddistal}) {
        upper &= ~(std::uint32_t{1} << idx(seg));
    }
    PoseScorer sparse;
    sparse.setMeasured(upper);
    PoseScorer all;
    sparse.add(poseFrom(solvedLocal), truthOf(poseFrom(trueLocal)));
    all.add(poseFrom(solvedLocal), truthOf(poseFrom(trueLocal)));
    const PoseScore s = *sparse.score();
    const PoseScore a = *all.score();

    EXPECT_EQ(s.measuredJoints, 13);
    EXPECT_NEAR(s.meanAngleDeg, 4.0 / 13, 1e-6);
    EXPECT_NEAR(a.meanAngleDeg, 34.0 / kSegmentCount, 1e-6);
    EXPECT_NEAR(s.angleDeg[idx(S::LCalf)], 30, 1e-6);  // reported, not averaged
    // The paper's 17: the hips, knees and ankles (6) are out, 11 are left.
    EXPECT_EQ(s.measuredIndependentJoints, 11);
    EXPECT_NEAR(s.independentMeanAngleDeg, 4.0 / 11, 1e-6);
    EXPECT_FALSE(rootTranslationMeasured(s.measured));
    EXPECT_TRUE(rootTranslationMeasured(a.measured));
    const std::string table = formatScoreTable(s);
    EXPECT_NE(table.find("| l_knee (not measured) | l_calf |"), std::string::npos) << table;
    EXPECT_NE(table.find("| **mean** of the 13 measured |"), std::string::npos) << table;
    EXPECT_NE(table.find("root translation: not measured"), std::string::npos) << table;
    EXPECT_EQ(formatScoreTable(a).find("not measured"), std::string::npos);
}

TEST(PoseScore, AClipWithNoToesStillGivesTheSubjectAFootToRollOn) {
    // A rig whose foot ends at the ankle (the Daz release of the CMU clips maps no toes: their
    // segment sits on the ankle) measures no foot. The contact points are the default subject's
    // foot scaled with the measured leg: a heel behind the ankle and a ball and toe ahead of it,
    // all below it, not three copies of the ankle (the root tracker could not roll the foot
    // then: the run clip's root fell 43 % of its path short).
    board::SubjectConfig tall;
    tall.heightM = 1.75 * 1.2;  // the measured subject: a fifth taller than the default one
    const Dimensions model = *dimensionsFromSubject(board::SubjectConfig{});
    Pose p;
    p.qLocal = reference();
    worldFromLocal(p);
    forwardKinematics(*dimensionsFromSubject(tall), Vec3d(0, 1.1, 0), p);
    BodyTruth t = truthOf(p);
    t.positionM[idx(S::LMiddistal)] = t.positionM[idx(S::LHindfoot)];
    t.positionM[idx(S::RMiddistal)] = t.positionM[idx(S::RHindfoot)];
    const Dimensions d = measuredDimensions({t});
    for (int foot = 0; foot < 2; ++foot) {
        const auto& fp = foot == 0 ? d.leftFootPointM : d.rightFootPointM;
        const auto& mp = foot == 0 ? model.leftFootPointM : model.rightFootPointM;
        const auto toes = static_cast<std::size_t>(idx(foot == 0 ? S::LMiddistal : S::RMiddistal));
        EXPECT_LT(fp[0].z(), -0.02) << foot;  // heel behind the ankle
        EXPECT_GT(fp[1].z(), 0.08) << foot;   // ball ahead
        EXPECT_GT(fp[2].z(), fp[1].z() + 0.02) << foot;
        for (std::size_t i = 0; i < fp.size(); ++i) {
            EXPECT_LT(fp[i].y(), -0.03) << foot << " " << i;  // the sole below the ankle
            EXPECT_TRUE(fp[i].isApprox(1.2 * mp[i], 1e-9)) << foot << " " << i;
        }
        EXPECT_TRUE(d.offsetM[toes].isApprox(1.2 * model.offsetM[toes], 1e-9)) << foot;
    }
    // A clip with toes keeps its own: the ball where the toes are.
    const Dimensions withToes = measuredDimensions({truthOf(p)});
    EXPECT_TRUE(withToes.leftFootPointM[1].isApprox(
        withToes.offsetM[static_cast<std::size_t>(idx(S::LMiddistal))], 1e-9));
}

}  // namespace
}  // namespace caphub::body
