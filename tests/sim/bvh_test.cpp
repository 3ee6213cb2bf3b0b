// The BVH reader: the whole grammar in any layout, both CMU clips, and a line-numbered error
// for every kind of malformed file.
#include "board/sim/bvh.h"

#include <cmath>
#include <filesystem>
#include <numbers>
#include <ostream>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace caphub::board::sim {
namespace {

using ::testing::ElementsAre;
using ::testing::HasSubstr;

const std::filesystem::path kData = std::filesystem::path(CAPHUB_TEST_DATA_DIR) / "bvh";
const std::filesystem::path kShared =
    std::filesystem::path(CAPHUB_SOURCE_DIR) / ".." / "shared" / "data" / "bvh";

constexpr double kRad = std::numbers::pi / 180.0;

BvhClip load(const std::string& name) {
    auto r = loadBvh(kData / name);
    EXPECT_TRUE(r.ok()) << r.error().message;
    return r.ok() ? std::move(r).value() : BvhClip{};
}

Quatd rot(const Vec3d& axis, double deg) {
    return Quatd(Eigen::AngleAxisd(deg * kRad, axis));
}

TEST(Bvh, ReadsJointsOffsetsChannelsAndEndSites) {
    const BvhClip c = load("minimal.bvh");
    ASSERT_EQ(c.joints.size(), 2u);
    EXPECT_EQ(c.joints[0].name, "Hips");
    EXPECT_EQ(c.joints[0].parent, -1);
    EXPECT_EQ(c.joints[0].line, 2);
    EXPECT_THAT(c.joints[0].channels,
                ElementsAre(BvhChannel::Xposition, BvhChannel::Yposition, BvhChannel::Zposition,
                            BvhChannel::Zrotation, BvhChannel::Xrotation, BvhChannel::Yrotation));
    EXPECT_FALSE(c.joints[0].endSite);
    EXPECT_EQ(c.joints[1].name, "Chest");
    EXPECT_EQ(c.joints[1].parent, 0);
    EXPECT_EQ(c.joints[1].offset, Vec3d(0, 10, 0));
    EXPECT_EQ(c.joints[1].firstChannel, 6);
    ASSERT_TRUE(c.joints[1].endSite);
    EXPECT_EQ(*c.joints[1].endSite, Vec3d(0, 5, 0));
}

TEST(Bvh, ReadsFramesAndFrameTime) {
    const BvhClip c = load("minimal.bvh");
    EXPECT_EQ(c.channelCount, 9);
    EXPECT_EQ(c.frameCount, 2);
    EXPECT_DOUBLE_EQ(c.frameTimeS, 0.1);
    EXPECT_THAT(c.frame(1), ElementsAre(4, 5, 6, 90, 0, 0, 0, 0, 0));
}

TEST(Bvh, AnyWhitespaceLayoutReadsTheSame) {
    const BvhClip a = load("minimal.bvh");
    const BvhClip b = load("layout_one_line.bvh");  // braces glued, one line, split numbers
    ASSERT_EQ(b.joints.size(), a.joints.size());
    for (std::size_t j = 0; j < a.joints.size(); ++j) {
        EXPECT_EQ(b.joints[j].name, a.joints[j].name);
        EXPECT_EQ(b.joints[j].offset, a.joints[j].offset);
        EXPECT_EQ(b.joints[j].channels, a.joints[j].channels);
    }
    EXPECT_EQ(b.frameTimeS, a.frameTimeS);
    EXPECT_EQ(b.values, a.values);
}

TEST(Bvh, ReadsCrlfLowercaseKeywordsNamesWithSpacesAndZeroChannels) {
    const BvhClip c = load("mixed_channels.bvh");
    ASSERT_EQ(c.joints.size(), 3u);
    EXPECT_EQ(c.joints[1].name, "Left Upper Arm");
    EXPECT_TRUE(c.joints[2].channels.empty());
    EXPECT_EQ(c.channelCount, 9);
    EXPECT_DOUBLE_EQ(c.frameTimeS, 0.008333);
    EXPECT_THAT(c.frame(0), ElementsAre(10, 20, 30, 5, 7, -15, 8, 25, 9));  // "+5" is 5
}

TEST(Bvh, RotationChannelsApplyInTheOrderListed) {
    const BvhClip c = load("minimal.bvh");
    Vec3d t;
    Quatd q;
    c.localPose(1, c.frame(0), t, q);  // Chest: Zrotation 10, Xrotation 20, Yrotation 30
    const Quatd expected =
        rot(Vec3d::UnitZ(), 10) * rot(Vec3d::UnitX(), 20) * rot(Vec3d::UnitY(), 30);
    // Exact up to rounding of three products of unit quaternions.
    EXPECT_LT(angleBetween(q, expected), 1e-12);
    EXPECT_GT(angleBetween(
                  q, rot(Vec3d::UnitX(), 20) * rot(Vec3d::UnitY(), 30) * rot(Vec3d::UnitZ(), 10)),
              1e-3);
    EXPECT_EQ(t, Vec3d(0, 10, 0));  // no position channels: the OFFSET
}

TEST(Bvh, RootWithRotationsOnlyKeepsItsOffset) {
    const BvhClip c = load("mixed_channels.bvh");
    Vec3d t;
    Quatd q;
    c.localPose(0, c.frame(0), t, q);
    EXPECT_EQ(t, Vec3d(0, 0, 0));
    EXPECT_LT(angleBetween(
                  q, rot(Vec3d::UnitX(), 10) * rot(Vec3d::UnitY(), 20) * rot(Vec3d::UnitZ(), 30)),
              1e-12);
}

TEST(Bvh, SixChannelsInAnyOrderOnANonRootJoint) {
    const BvhClip c = load("mixed_channels.bvh");
    Vec3d t;
    Quatd q;
    // Xrotation 5, Yposition 7, Zrotation -15, Xposition 8, Yrotation 25, Zposition 9.
    c.localPose(1, c.frame(0), t, q);
    EXPECT_EQ(t, Vec3d(8, 7, 9));  // position channels replace the OFFSET (1 0 0)
    EXPECT_LT(angleBetween(
                  q, rot(Vec3d::UnitX(), 5) * rot(Vec3d::UnitZ(), -15) * rot(Vec3d::UnitY(), 25)),
              1e-12);
}

TEST(Bvh, RootPositionChannelsGiveItsTranslation) {
    const BvhClip c = load("minimal.bvh");
    Vec3d t;
    Quatd q;
    c.localPose(0, c.frame(1), t, q);
    EXPECT_EQ(t, Vec3d(4, 5, 6));
    EXPECT_LT(angleBetween(q, rot(Vec3d::UnitZ(), 90)), 1e-12);
}

TEST(Bvh, ReadsSeveralRoots) {
    const auto r = parseBvh(
        "HIERARCHY ROOT A { OFFSET 0 0 0 CHANNELS 1 Yrotation }\n"
        "ROOT B { OFFSET 1 0 0 CHANNELS 1 Xposition }\n"
        "MOTION Frames: 1 Frame Time: 1\n5 6\n",
        "two_roots");
    ASSERT_TRUE(r.ok()) << r.error().message;
    ASSERT_EQ(r->joints.size(), 2u);
    EXPECT_EQ(r->joints[1].parent, -1);
    EXPECT_EQ(r->joints[1].firstChannel, 1);
}

TEST(Bvh, ReadsTheMotionBuilderStyleCmuClip) {
    const BvhClip c = load("cmu_12_01_walk.bvh");
    EXPECT_EQ(c.joints.size(), 31u);
    EXPECT_EQ(c.channelCount, 96);
    EXPECT_EQ(c.frameCount, 524);
    EXPECT_NEAR(c.frameTimeS, 1.0 / 120, 1e-6);  // the file says .0083333
    EXPECT_GE(c.findJoint("LeftUpLeg"), 0);
    EXPECT_EQ(c.values.size(), 524u * 96u);
}

TEST(Bvh, ReadsThe3dsMaxStyleCmuClip) {
    const auto path = kShared / "cmu_131_01_start_walk_stop.bvh";
    if (!std::filesystem::exists(path)) {
        GTEST_SKIP() << "shared data absent: " << path;
    }
    const auto r = loadBvh(path);
    ASSERT_TRUE(r.ok()) << r.error().message;
    EXPECT_EQ(r->joints.size(), 31u);
    EXPECT_EQ(r->frameCount, 994);
    EXPECT_GE(r->findJoint("LeftKnee"), 0);
    // Its arms use Z X Y, its trunk Z Y X: one order per joint.
    const auto& knee = r->joints[static_cast<std::size_t>(r->findJoint("LeftElbow"))];
    EXPECT_THAT(knee.channels,
                ElementsAre(BvhChannel::Zrotation, BvhChannel::Xrotation, BvhChannel::Yrotation));
}

struct Malformed {
    const char* file;
    int line;
    const char* expected;  // part of the message after "expected"
    const char* found;
};

// Names the case in test output (and in ctest's test names) by its file.
void PrintTo(const Malformed& m, std::ostream* os) {
    *os << m.file;
}

class BvhMalformed : public ::testing::TestWithParam<Malformed> {};

TEST_P(BvhMalformed, GivesTheLineAndWhatWasExpected) {
    const Malformed& m = GetParam();
    const auto path = kData / "malformed" / m.file;
    const auto r = loadBvh(path);
    ASSERT_FALSE(r.ok());
    const std::string& msg = r.error().message;
    EXPECT_THAT(msg, HasSubstr(path.string() + ": line " + std::to_string(m.line) + ": expected "));
    EXPECT_THAT(msg, HasSubstr(m.expected));
    EXPECT_THAT(msg, HasSubstr(std::string("found ") + m.found));
    EXPECT_EQ(r.error().code, EINVAL);
}

INSTANTIATE_TEST_SUITE_P(
    Files, BvhMalformed,
    ::testing::Values(
        Malformed{"empty.bvh", 1, "'HIERARCHY' at the start", "end of file"},
        Malformed{"not_bvh.bvh", 1, "'HIERARCHY' at the start", "'This'"},
        Malformed{"missing_brace.bvh", 3, "'{' after ROOT Hips", "'OFFSET'"},
        Malformed{"short_offset.bvh", 5, "three numbers after OFFSET", "'}'"},
        Malformed{"bad_channel.bvh", 5, "channel 2 of 3 of joint 'Hips'", "'Xrot'"},
        Malformed{"bad_channel_count.bvh", 5, "a channel count from 0 to 6", "'7'"},
        Malformed{"missing_offset.bvh", 5, "OFFSET in joint 'Hips' before its children", "'JOINT'"},
        Malformed{"unclosed.bvh", 6, "in joint 'Hips' (declared on line 2)", "'MOTION'"},
        Malformed{"no_frames_label.bvh", 17, "'Frames:' after MOTION", "'Frame:'"},
        Malformed{"bad_frame_time.bvh", 18, "a frame time in seconds (> 0)", "'0'"},
        Malformed{"bad_number.bvh", 19, "frame 0 of 2, channel Zposition of joint 'Hips'", "'x3'"},
        Malformed{"short_motion.bvh", 20, "frame 1 of 2, channel Yrotation of joint 'Chest'",
                  "end of file"},
        Malformed{"extra_values.bvh", 21, "the end of the file after 2 frames of 9 values", "'7'"},
        Malformed{"huge_frame_count.bvh", 17, "frames of 9 values", "'Frames: 2000000000'"}),
    [](const ::testing::TestParamInfo<Malformed>& param) {
        std::string n = param.param.file;
        n = n.substr(0, n.find('.'));
        return n;
    });

TEST(Bvh, BinaryGarbageIsQuotedReadably) {
    const std::string text = std::string("HIERARCHY\nROOT\x01\xff", 16);
    const auto r = parseBvh(text, "garbage");
    ASSERT_FALSE(r.ok());
    EXPECT_THAT(r.error().message, HasSubstr("found 'ROOT\\x01\\xff'"));
}

TEST(Bvh, DuplicateChannelIsAnError) {
    const auto r =
        parseBvh("HIERARCHY\nROOT A\n{\nOFFSET 0 0 0\nCHANNELS 2 Xrotation Xrotation\n}", "dup");
    ASSERT_FALSE(r.ok());
    EXPECT_THAT(r.error().message, HasSubstr("dup: line 5: expected each channel at most once"));
}

TEST(Bvh, MissingFileIsAnErrorNamingIt) {
    const auto r = loadBvh(kData / "no_such_file.bvh");
    ASSERT_FALSE(r.ok());
    EXPECT_THAT(r.error().message, HasSubstr("no_such_file.bvh"));
    EXPECT_EQ(r.error().code, ENOENT);
}

TEST(Bvh, DeepNestingDoesNotExhaustTheStack) {
    // 100,000 nested joints: a recursive parser would overflow its stack here.
    std::string text = "HIERARCHY\nROOT R {\nOFFSET 0 0 0\n";
    constexpr int kDepth = 100000;
    for (int i = 0; i < kDepth; ++i) {
        text += "JOINT j { OFFSET 0 1 0\n";
    }
    text += std::string(kDepth, '}') + "}\nMOTION\nFrames: 0\nFrame Time: 1\n";
    const auto r = parseBvh(text, "deep");
    ASSERT_TRUE(r.ok()) << r.error().message;
    EXPECT_EQ(r->joints.size(), static_cast<std::size_t>(kDepth) + 1);
}

// A clip at 120 frames/s whose Chest turns 2 deg a frame (240 deg/s, a body's pace), except where
// it flips by `flipDeg` about its long axis for three frames and back.
std::string flippingClip(double flipDeg) {
    std::string text =
        "HIERARCHY\nROOT Hips\n{\nOFFSET 0 0 0\nCHANNELS 6 Xposition Yposition Zposition "
        "Zrotation Xrotation Yrotation\nJOINT Chest\n{\nOFFSET 0 10 0\nCHANNELS 3 Zrotation "
        "Xrotation Yrotation\nEnd Site\n{\nOFFSET 0 5 0\n}\n}\n}\nMOTION\nFrames: 20\n"
        "Frame Time: 0.0083333\n";
    for (int f = 0; f < 20; ++f) {
        const double twist = (f >= 10 && f < 13) ? flipDeg : 0.0;
        text += "0 0 0 0 0 " + std::to_string(2.0 * f) + " 0 0 " + std::to_string(twist) + "\n";
    }
    return text;
}

TEST(Bvh, AJointFlippedFasterThanABodyCanTurnIsFound) {
    const auto flipped = parseBvh(flippingClip(170.0), "flip");
    ASSERT_TRUE(flipped.ok()) << flipped.error().message;
    const auto turns = implausibleTurns(*flipped);
    ASSERT_EQ(turns.size(), 1u);
    EXPECT_EQ(turns[0].joint, "Chest");
    EXPECT_EQ(turns[0].frames, 2);  // there and back
    EXPECT_NEAR(turns[0].maxTurnRad, 170.0 * kRad, 1e-6);
    // 60 deg in a frame is 7,200 deg/s: fast, but a body's (a pitcher's upper arm).
    const auto fast = parseBvh(flippingClip(60.0), "fast");
    ASSERT_TRUE(fast.ok()) << fast.error().message;
    EXPECT_TRUE(implausibleTurns(*fast).empty());
}

TEST(Bvh, TheShippedClipsTurnNoLimbFasterThanABody) {
    for (const char* name : {"cmu_12_01_walk.bvh", "cmu_16_36_run_daz.bvh"}) {
        const auto clip = loadBvh(kData / name);
        ASSERT_TRUE(clip.ok()) << clip.error().message;
        EXPECT_TRUE(implausibleTurns(*clip).empty()) << name;
    }
    // cmu_131_01's right thumb flips (a joint no sensor measures).
    const auto walkStop = loadBvh(kData / "cmu_131_01_start_walk_stop.bvh");
    ASSERT_TRUE(walkStop.ok()) << walkStop.error().message;
    const auto turns = implausibleTurns(*walkStop);
    ASSERT_EQ(turns.size(), 1u);
    EXPECT_EQ(turns[0].joint, "RThumb");
}

}  // namespace
}  // namespace caphub::board::sim
