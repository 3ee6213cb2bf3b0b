// Joint maps: the CMU presets fit their clips, a user map file fits a rig with other names,
// several joints may make one segment, and every mistake in a map is reported.
#include "board/sim/joint_map.h"

#include <filesystem>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace caphub::board::sim {
namespace {

using board::Segment;
using ::testing::HasSubstr;

const std::filesystem::path kData = std::filesystem::path(CAPHUB_TEST_DATA_DIR) / "bvh";

BvhClip load(const std::filesystem::path& path) {
    auto r = loadBvh(path);
    EXPECT_TRUE(r.ok()) << r.error().message;
    return r.ok() ? std::move(r).value() : BvhClip{};
}

int joint(const BvhClip& c, const char* name) {
    return c.findJoint(name);
}

std::size_t at(Segment s) {
    return static_cast<std::size_t>(s);
}

TEST(JointMap, WalkClipGetsTheMotionBuilderPreset) {
    const BvhClip clip = load(kData / "cmu_12_01_walk.bvh");
    const JointMap* map = detectJointMap(clip);
    ASSERT_NE(map, nullptr);
    EXPECT_EQ(map->name, "cmu-motionbuilder");
    EXPECT_EQ(map->unitM, kCmuUnitM);
}

TEST(JointMap, MotionBuilderPresetMapsAll21Segments) {
    const BvhClip clip = load(kData / "cmu_12_01_walk.bvh");
    const auto b = bindJointMap(*findBuiltInJointMap("cmu-motionbuilder"), clip);
    ASSERT_TRUE(b.ok()) << b.error().message;
    for (const auto& s : board::kSegments) {
        EXPECT_TRUE(b->mapped(s.id)) << s.name;
        EXPECT_EQ(b->poseSource[at(s.id)], s.id);
    }
    EXPECT_EQ(b->orientationJoint[at(Segment::LThigh)], joint(clip, "LeftUpLeg"));
    EXPECT_EQ(b->orientationJoint[at(Segment::LCalf)], joint(clip, "LeftLeg"));
}

TEST(JointMap, StartWalkStopClipGetsThe3dsMaxPreset) {
    const auto path = kData / "cmu_131_01_start_walk_stop.bvh";
    const BvhClip clip = load(path);
    const JointMap* map = detectJointMap(clip);
    ASSERT_NE(map, nullptr);
    EXPECT_EQ(map->name, "cmu-3dsmax");
    const auto b = bindJointMap(*map, clip);
    ASSERT_TRUE(b.ok()) << b.error().message;
    for (const auto& s : board::kSegments) {
        EXPECT_TRUE(b->mapped(s.id)) << s.name;
    }
    // 3ds Max names: LeftShoulder is the upper arm, LeftCollar the clavicle.
    EXPECT_EQ(b->orientationJoint[at(Segment::LUpperarm)], joint(clip, "LeftShoulder"));
    EXPECT_EQ(b->orientationJoint[at(Segment::LClavicle)], joint(clip, "LeftCollar"));
}

TEST(JointMap, DazReleaseClipGetsTheDazPreset) {
    // The Daz-friendly release of the CMU clips: root "hip", lThigh, lShin, ...; centimetres;
    // frames 1-5 blend out of the rest pose, so the motion starts at frame 6; no toes.
    const auto path = kData / "cmu_16_36_run_daz.bvh";
    const BvhClip clip = load(path);
    const JointMap* map = detectJointMap(clip);
    ASSERT_NE(map, nullptr);
    EXPECT_EQ(map->name, "cmu-daz");
    EXPECT_EQ(map->unitM, 0.01);
    EXPECT_EQ(map->firstFrame, 6);
    const auto b = bindJointMap(*map, clip);
    ASSERT_TRUE(b.ok()) << b.error().message;
    for (const auto& s : board::kSegments) {
        const bool toes = s.id == Segment::LMiddistal || s.id == Segment::RMiddistal;
        EXPECT_EQ(b->mapped(s.id), !toes) << s.name;
    }
    EXPECT_EQ(b->orientationJoint[at(Segment::Pelvis)], joint(clip, "hip"));
    EXPECT_EQ(b->orientationJoint[at(Segment::LThigh)], joint(clip, "lThigh"));
    EXPECT_EQ(b->poseSource[at(Segment::LMiddistal)], Segment::LHindfoot);
}

TEST(JointMap, NoPresetForAnUnknownRig) {
    const BvhClip clip = load(kData / "unity_rig.bvh");
    EXPECT_EQ(detectJointMap(clip), nullptr);
}

TEST(JointMap, UserMapFileFitsARigWithOtherNames) {
    const auto map = loadJointMap(kData / "unity_rig.toml");
    ASSERT_TRUE(map.ok()) << map.error().message;
    EXPECT_EQ(map->name, "unity-style");
    EXPECT_EQ(map->unitM, 0.01);
    ASSERT_TRUE(map->reference);
    EXPECT_EQ(map->reference->kind, ReferencePose::Kind::Rest);
    const BvhClip clip = load(kData / "unity_rig.bvh");
    const auto b = bindJointMap(*map, clip);
    ASSERT_TRUE(b.ok()) << b.error().message;
    EXPECT_EQ(b->orientationJoint[at(Segment::LForearm)], joint(clip, "LowerArm_L"));
}

TEST(JointMap, SeveralJointsOnASegmentTakeOrientationFromTheMostDistal) {
    const auto map = loadJointMap(kData / "unity_rig.toml");
    ASSERT_TRUE(map.ok()) << map.error().message;
    const BvhClip clip = load(kData / "unity_rig.bvh");
    const auto b = bindJointMap(*map, clip);
    ASSERT_TRUE(b.ok()) << b.error().message;
    EXPECT_EQ(b->orientationJoint[at(Segment::LUpperarm)], joint(clip, "UpperArm_Twist_L"));
    EXPECT_EQ(b->positionJoint[at(Segment::LUpperarm)], joint(clip, "UpperArm_L"));
    EXPECT_EQ(b->orientationJoint[at(Segment::T12)], joint(clip, "UpperChest"));
    EXPECT_EQ(b->positionJoint[at(Segment::T12)], joint(clip, "Chest"));
}

TEST(JointMap, JointsOfASegmentMayBeListedInAnyOrder) {
    const BvhClip clip = load(kData / "unity_rig.bvh");
    auto map = loadJointMap(kData / "unity_rig.toml");
    ASSERT_TRUE(map.ok()) << map.error().message;
    map->joints[at(Segment::LUpperarm)] = {"UpperArm_Twist_L", "UpperArm_L"};
    const auto b = bindJointMap(*map, clip);
    ASSERT_TRUE(b.ok()) << b.error().message;
    EXPECT_EQ(b->orientationJoint[at(Segment::LUpperarm)], joint(clip, "UpperArm_Twist_L"));
}

TEST(JointMap, MissingSegmentTakesThePoseOfItsNearestMappedAncestor) {
    const auto map = loadJointMap(kData / "unity_rig.toml");  // no r_middistal
    ASSERT_TRUE(map.ok()) << map.error().message;
    const auto b = bindJointMap(*map, load(kData / "unity_rig.bvh"));
    ASSERT_TRUE(b.ok()) << b.error().message;
    EXPECT_FALSE(b->mapped(Segment::RMiddistal));
    EXPECT_EQ(b->poseSource[at(Segment::RMiddistal)], Segment::RHindfoot);
}

TEST(JointMap, JointsNotInTheClipAreAllReported) {
    JointMap map = *findBuiltInJointMap("cmu-motionbuilder");
    const auto b = bindJointMap(map, load(kData / "unity_rig.bvh"));
    ASSERT_FALSE(b.ok());
    EXPECT_THAT(b.error().message, HasSubstr("segment l5: joint 'LowerBack' is not in the clip"));
    EXPECT_THAT(b.error().message,
                HasSubstr("segment r_middistal: joint 'RightToeBase' is not in the clip"));
}

TEST(JointMap, JointsOfOneSegmentMustBeOnOneChain) {
    auto map = loadJointMap(kData / "unity_rig.toml");
    ASSERT_TRUE(map.ok());
    map->joints[at(Segment::LHand)] = {"Hand_L", "Hand_R"};
    map->joints[at(Segment::RHand)] = {};
    const auto b = bindJointMap(*map, load(kData / "unity_rig.bvh"));
    ASSERT_FALSE(b.ok());
    EXPECT_THAT(b.error().message, HasSubstr("segment l_hand: its joints are not on one chain"));
}

TEST(JointMap, AJointCannotServeTwoSegments) {
    auto map = loadJointMap(kData / "unity_rig.toml");
    ASSERT_TRUE(map.ok());
    map->joints[at(Segment::LForearm)] = {"Hand_L"};
    const auto b = bindJointMap(*map, load(kData / "unity_rig.bvh"));
    ASSERT_FALSE(b.ok());
    EXPECT_THAT(b.error().message,
                HasSubstr("joint 'Hand_L' is mapped to both l_forearm and l_hand"));
}

TEST(JointMap, ThePelvisMustBeMapped) {
    auto map = loadJointMap(kData / "unity_rig.toml");
    ASSERT_TRUE(map.ok());
    map->joints[at(Segment::Pelvis)] = {};
    const auto b = bindJointMap(*map, load(kData / "unity_rig.bvh"));
    ASSERT_FALSE(b.ok());
    EXPECT_THAT(b.error().message, HasSubstr("segment pelvis: no joint mapped"));
}

TEST(JointMapFile, UnknownSegmentNamesFileLineAndKey) {
    const auto r = parseJointMap(
        "unit_m = 0.01\n[segments]\npelvis = \"Hips\"\nl_shin = \"Knee\"\n", "rig.toml");
    ASSERT_FALSE(r.ok());
    EXPECT_THAT(r.error().message,
                HasSubstr("rig.toml:4:1: segments.l_shin: unknown segment (expected one of: "
                          "pelvis, l5,"));
}

TEST(JointMapFile, WrongValueTypeIsReportedAtTheValue) {
    const auto r = parseJointMap("[segments]\npelvis = 3\nl5 = [\"A\", 4]\n", "rig.toml");
    ASSERT_FALSE(r.ok());
    EXPECT_THAT(r.error().message,
                HasSubstr("rig.toml:2:10: segments.pelvis: expected a BVH joint name or an "
                          "array of them"));
    EXPECT_THAT(r.error().message,
                HasSubstr("rig.toml:3:12: segments.l5: expected BVH joint names"));
}

TEST(JointMapFile, BadUnitAndReferenceAreReported) {
    const auto r = parseJointMap(
        "unit_m = -1\nreference = \"sideways\"\n[segments]\npelvis = \"H\"\n", "rig.toml");
    ASSERT_FALSE(r.ok());
    EXPECT_THAT(r.error().message, HasSubstr("rig.toml:1:10: unit_m: expected a number of metres"));
    EXPECT_THAT(r.error().message,
                HasSubstr("rig.toml:2:13: reference: expected \"rest\", \"tpose\" or a frame"));
}

TEST(JointMapFile, UnknownKeyAndMissingSegmentsTable) {
    const auto r = parseJointMap("units = 1\n", "rig.toml");
    ASSERT_FALSE(r.ok());
    EXPECT_THAT(r.error().message, HasSubstr("rig.toml:1:1: units: unknown key"));
    EXPECT_THAT(r.error().message, HasSubstr("segments: missing required table [segments]"));
}

TEST(JointMapFile, SyntaxErrorHasItsLine) {
    const auto r = parseJointMap("[segments]\npelvis = \"Hips\n", "rig.toml");
    ASSERT_FALSE(r.ok());
    EXPECT_THAT(r.error().message, HasSubstr("rig.toml:2:"));
    EXPECT_THAT(r.error().message, HasSubstr("TOML syntax error"));
}

TEST(JointMapFile, FrameNumberReference) {
    const auto r = parseJointMap("reference = 12\n[segments]\npelvis = \"Hips\"\n", "rig.toml");
    ASSERT_TRUE(r.ok()) << r.error().message;
    ASSERT_TRUE(r->reference);
    EXPECT_EQ(r->reference->kind, ReferencePose::Kind::Frame);
    EXPECT_EQ(r->reference->frame, 12);
    EXPECT_EQ(r->name, "rig");  // the file's stem when the map has no name
    EXPECT_FALSE(r->unitM);
}

}  // namespace
}  // namespace caphub::board::sim
