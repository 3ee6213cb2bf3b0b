// caphub export as a library: the frames it reads from a recording (window, rate, damage) and
// the four formats it writes, each read back by an independent reader (the project's BVH reader,
// tinygltf, plain text parsing) and compared with the poses the recording holds.
#include "firmware/export/export.h"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <optional>
#include <random>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <tiny_gltf.h>
#include <unistd.h>

#include "board/loader.h"
#include "board/sim/bvh.h"
#include "firmware/export/euler.h"
#include "firmware/export/joint_names.h"
#include "firmware/recording/reader.h"
#include "firmware/recording/writer.h"
#include "fusion/body/body_calibration.h"
#include "fusion/body/skeleton.h"
#include "render/skin.h"
#include "tests/firmware/export_fixture.h"

namespace caphub::firmware::exporter {
namespace {

using ::testing::HasSubstr;
using testing::RecordedPose;
using testing::WalkRecordingOptions;
using testing::writeWalkRecording;

constexpr double kDeg = 180.0 / std::numbers::pi;

std::string temp(const std::string& name) {
    // ctest runs each test in its own process, in parallel: each process has its own files.
    return ::testing::TempDir() + "caphub_export_" + std::to_string(getpid()) + "_" + name;
}

std::string readText(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
}

std::vector<std::string> lines(const std::string& text) {
    std::vector<std::string> out;
    std::istringstream in(text);
    for (std::string l; std::getline(in, l);) {
        out.push_back(l);
    }
    return out;
}

std::vector<std::string> split(const std::string& s, char sep) {
    std::vector<std::string> out;
    std::string cell;
    std::istringstream in(s);
    while (std::getline(in, cell, sep)) {
        out.push_back(cell);
    }
    if (!s.empty() && s.back() == sep) {
        out.emplace_back();  // getline does not give the empty last cell
    }
    return out;
}

// The walk recording most tests export: 3 s of poses at 100 Hz, written once.
const std::vector<RecordedPose>& walk() {
    static const std::vector<RecordedPose> poses = writeWalkRecording(temp("walk.cap"));
    return poses;
}
const std::string& walkPath() {
    (void)walk();
    static const std::string path = temp("walk.cap");
    return path;
}

TrackOptions window(std::optional<double> fromS, std::optional<double> toS,
                    std::optional<double> rateHz) {
    TrackOptions o;
    o.fromS = fromS;
    o.toS = toS;
    o.rateHz = rateHz;
    return o;
}

ExportOptions as(Format f, double unitsPerM = 1) {
    ExportOptions o;
    o.format = f;
    o.unitsPerM = unitsPerM;
    return o;
}

WalkRecordingOptions walkOptions(double seconds, double heightM, bool withPoses) {
    WalkRecordingOptions o;
    o.seconds = seconds;
    o.heightM = heightM;
    o.withPoses = withPoses;
    return o;
}

ExportSummary exportOk(const std::string& rec, const std::string& out, const ExportOptions& o) {
    auto s = exportRecording(rec, out, o);
    EXPECT_TRUE(s.ok()) << (s.ok() ? "" : s.error().message);
    return s.ok() ? *s : ExportSummary{};
}

Quatd toD(const Eigen::Quaternionf& q) {
    return q.cast<double>().normalized();
}

// ---------------------------------------------------------------------------------------------
// Euler angles.

TEST(ExportEuler, ZxyAnglesRecomposeToTheRotation) {
    std::mt19937 rng(7);
    std::normal_distribution<double> n;
    for (int i = 0; i < 1000; ++i) {
        const Quatd q = Quatd(n(rng), n(rng), n(rng), n(rng)).normalized();
        const EulerZxyDeg e = eulerZxyDeg(q);
        Quatd back;
        ASSERT_TRUE(fromEulerIntrinsic("ZXY", Vec3d(e.z, e.x, e.y) / kDeg, back));
        // Double-precision trigonometry on a well-conditioned rotation: 1e-9 deg is a million
        // times below what the BVH text keeps (6 decimals).
        EXPECT_LT(angleBetween(q, back) * kDeg, 1e-9) << i;
        EXPECT_LE(std::abs(e.x), 90.0);
    }
}

TEST(ExportEuler, GimbalLockGivesAnEquivalentRotation) {
    for (double xDeg : {90.0, -90.0, 89.99999999, -89.9999999}) {
        for (double zDeg : {0.0, 30.0, -120.0}) {
            for (double yDeg : {0.0, 45.0, 170.0}) {
                Quatd q;
                ASSERT_TRUE(fromEulerIntrinsic("ZXY", Vec3d(zDeg, xDeg, yDeg) / kDeg, q));
                const EulerZxyDeg e = eulerZxyDeg(q);
                ASSERT_TRUE(std::isfinite(e.z) && std::isfinite(e.x) && std::isfinite(e.y));
                Quatd back;
                ASSERT_TRUE(fromEulerIntrinsic("ZXY", Vec3d(e.z, e.x, e.y) / kDeg, back));
                // At the lock only z +- y is defined; the representation error is bounded by
                // 2 cos(x) rad (euler.cpp), below 1e-4 deg here: 100 times under 0.01 deg.
                EXPECT_LT(angleBetween(q, back) * kDeg, 1e-4) << xDeg << " " << zDeg << " " << yDeg;
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// BVH.

TEST(ExportBvh, RoundTripThroughTheBvhReaderMatchesTheRecordingWithinAHundredthOfADegree) {
    const std::string out = temp("walk.bvh");
    const ExportSummary s = exportOk(walkPath(), out, {});
    auto clip = board::sim::loadBvh(out);
    ASSERT_TRUE(clip.ok()) << clip.error().message;
    ASSERT_EQ(clip->frameCount, static_cast<int>(walk().size()));
    EXPECT_EQ(s.frames, walk().size());
    const auto& names = body::joints();
    double worstDeg = 0;
    double worstRootM = 0;
    for (int f = 0; f < clip->frameCount; ++f) {
        const RecordedPose& p = walk()[static_cast<std::size_t>(f)];
        for (int seg = 0; seg < body::kSegmentCount; ++seg) {
            const int j = clip->findJoint(names[static_cast<std::size_t>(seg)].name);
            ASSERT_GE(j, 0);
            Vec3d t;
            Quatd q;
            clip->localPose(j, clip->frame(f), t, q);
            worstDeg = std::max(
                worstDeg, angleBetween(q, toD(p.qLocal[static_cast<std::size_t>(seg)])) * kDeg);
            if (seg == 0) {
                worstRootM = std::max(worstRootM, (t - p.rootM.cast<double>()).norm());
            }
        }
    }
    // The brief's bound. The text keeps 6 decimals of a degree; what is left is float input.
    EXPECT_LT(worstDeg, 0.01);
    // 6 decimals of a metre: 0.5 um per axis, plus float rounding of the recording.
    EXPECT_LT(worstRootM, 2e-6);
    std::cout << "BVH round trip: worst joint error " << worstDeg << " deg, root " << worstRootM
              << " m over " << clip->frameCount << " frames\n";
}

TEST(ExportBvh, HierarchyHasUniqueNamesBracesOnTheirOwnLinesAndZxyChannels) {
    const std::string out = temp("layout.bvh");
    exportOk(walkPath(), out, {});
    const auto text = lines(readText(out));
    std::set<std::string> jointNames;
    int endSites = 0;
    int rootChannels = 0;
    int jointChannels = 0;
    for (const auto& l : text) {
        if (l == "MOTION") {
            break;
        }
        const std::string t = l.substr(l.find_first_not_of('\t'));
        if (t.find('{') != std::string::npos || t.find('}') != std::string::npos) {
            EXPECT_TRUE(t == "{" || t == "}") << "brace not on its own line: " << l;
        }
        if (t.rfind("ROOT ", 0) == 0 || t.rfind("JOINT ", 0) == 0) {
            EXPECT_TRUE(jointNames.insert(t.substr(t.find(' ') + 1)).second) << t;
        }
        endSites += t == "End Site";
        rootChannels +=
            t == "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation";
        jointChannels += t == "CHANNELS 3 Zrotation Xrotation Yrotation";
    }
    EXPECT_EQ(jointNames.size(), 21u);
    EXPECT_EQ(endSites, 5);  // head, both hands, both toes
    EXPECT_EQ(rootChannels, 1);
    EXPECT_EQ(jointChannels, 20);
    EXPECT_THAT(readText(out), HasSubstr("Frame Time: 0.010000000\n"));
}

TEST(ExportBvh, OffsetsAreTheSubjectsDimensionsInTheChosenUnit) {
    const std::string rec = temp("short.cap");
    const auto poses = writeWalkRecording(rec, walkOptions(0.5, 1.6, true));
    board::SubjectConfig subject;
    subject.heightM = 1.6;
    const body::Dimensions d = *body::dimensionsFromSubject(subject);
    for (double unit : {1.0, 100.0}) {
        ExportOptions o;
        o.unitsPerM = unit;
        const std::string out = temp("units.bvh");
        exportOk(rec, out, o);
        auto clip = board::sim::loadBvh(out);
        ASSERT_TRUE(clip.ok()) << clip.error().message;
        const int knee = clip->findJoint("l_knee");
        ASSERT_GE(knee, 0);
        const Vec3d want = d.offsetM[static_cast<std::size_t>(body::idx(board::Segment::LCalf))];
        // 6 decimals in the file.
        EXPECT_LT((clip->joints[static_cast<std::size_t>(knee)].offset - want * unit).norm(), 1e-6)
            << unit;
        // The root's position channels are in the unit too.
        Vec3d t;
        Quatd q;
        clip->localPose(0, clip->frame(0), t, q);
        EXPECT_LT((t - poses[0].rootM.cast<double>() * unit).norm(), 2e-6 * unit) << unit;
    }
}

TEST(ExportBvh, ReferenceFrameOptionPrependsTheTPose) {
    ExportOptions o;
    o.referenceFrame = true;
    const std::string out = temp("ref.bvh");
    const ExportSummary s = exportOk(walkPath(), out, o);
    auto clip = board::sim::loadBvh(out);
    ASSERT_TRUE(clip.ok()) << clip.error().message;
    EXPECT_EQ(clip->frameCount, static_cast<int>(walk().size()) + 1);
    EXPECT_EQ(s.frames, walk().size() + 1);
    for (int j = 0; j < static_cast<int>(clip->joints.size()); ++j) {
        Vec3d t;
        Quatd q;
        clip->localPose(j, clip->frame(0), t, q);
        EXPECT_EQ(angleBetween(q, Quatd::Identity()), 0.0) << clip->joints[j].name;
    }
    // Frame 1 is the recording's first pose.
    Vec3d t;
    Quatd q;
    clip->localPose(clip->findJoint("l_hip"), clip->frame(1), t, q);
    EXPECT_LT(angleBetween(q, toD(walk()[0].qLocal[13])) * kDeg, 0.01);
}

TEST(ExportBvh, FrameTimeKeepsNineDecimalsForNonIntegerRates) {
    ExportOptions o;
    o.track.rateHz = 29.97;
    const std::string out = temp("ntsc.bvh");
    exportOk(walkPath(), out, o);
    EXPECT_THAT(readText(out), HasSubstr("Frame Time: 0.033366700\n"));
}

TEST(ExportBvh, CmuAndUnityNameSetsNameTheJoints) {
    for (const char* set : {"cmu", "unity"}) {
        ExportOptions o;
        o.names = set;
        const std::string out = temp(std::string(set) + ".bvh");
        exportOk(walkPath(), out, o);
        auto clip = board::sim::loadBvh(out);
        ASSERT_TRUE(clip.ok());
        EXPECT_EQ(clip->joints[0].name, "Hips");
        EXPECT_GE(clip->findJoint("LeftFoot"), 0) << set;
        EXPECT_GE(clip->findJoint(std::string(set) == "cmu" ? "LeftForeArm" : "LeftLowerArm"), 0)
            << set;
        EXPECT_GE(clip->findJoint(std::string(set) == "cmu" ? "RightToeBase" : "RightToes"), 0)
            << set;
    }
}

// ---------------------------------------------------------------------------------------------
// Joint name files.

TEST(ExportNames, MapFileRenamesListedSegmentsAndKeepsTheOthers) {
    auto n = parseJointNames("pelvis = \"root\"\nl_hand = \"LeftPaw\"\n", "names.toml");
    ASSERT_TRUE(n.ok()) << n.error().message;
    EXPECT_EQ(n->joint[0], "root");
    EXPECT_EQ(n->segment[8], "LeftPaw");
    EXPECT_EQ(n->joint[1], "vl5");
    EXPECT_EQ(n->segment[1], "l5");
}

TEST(ExportNames, MapFileErrorsNameTheFileAndLine) {
    auto unknown = parseJointNames("pelvis = \"Hips\"\nelbow = \"x\"\n", "names.toml");
    ASSERT_FALSE(unknown.ok());
    EXPECT_THAT(unknown.error().message, HasSubstr("names.toml:2:"));
    EXPECT_THAT(unknown.error().message, HasSubstr("'elbow' is not a segment"));

    auto notString = parseJointNames("\n\npelvis = 3\n", "names.toml");
    ASSERT_FALSE(notString.ok());
    EXPECT_THAT(notString.error().message, HasSubstr("names.toml:3: pelvis: expected a quoted"));

    auto spaced = parseJointNames("skull = \"my head\"\n", "names.toml");
    ASSERT_FALSE(spaced.ok());
    EXPECT_THAT(spaced.error().message, HasSubstr("names.toml:1:"));

    auto twice = parseJointNames("l_hand = \"Hand\"\nr_hand = \"Hand\"\n", "names.toml");
    ASSERT_FALSE(twice.ok());
    EXPECT_THAT(twice.error().message, HasSubstr("names.toml:2:"));
    EXPECT_THAT(twice.error().message, HasSubstr("expected unique names"));

    auto broken = parseJointNames("pelvis = \"Hips\nx", "names.toml");
    ASSERT_FALSE(broken.ok());
    EXPECT_THAT(broken.error().message, HasSubstr("names.toml:1:"));
}

TEST(ExportNames, MissingMapFileIsAnError) {
    auto n = jointNamesFor(temp("no-such-names.toml"));
    ASSERT_FALSE(n.ok());
    EXPECT_THAT(n.error().message,
                HasSubstr("expected hanim, cmu, unity, opensim or a readable map file"));
}

// ---------------------------------------------------------------------------------------------
// Frames: rate, window, damage.

TEST(ExportFrames, DefaultRateIsTheRecordingsPoseRate) {
    auto reader = RecordingReader::open(walkPath());
    ASSERT_TRUE(reader.ok());
    auto track = readPoseTrack(**reader, {});
    ASSERT_TRUE(track.ok()) << track.error().message;
    EXPECT_NEAR(track->rateHz, 100.0, 1e-9);  // 10 ms intervals, exact in integer ns
    EXPECT_EQ(track->frames.size(), walk().size());
    EXPECT_EQ(track->subjectSource, "subject of board 'sim-suit' (1.75 m)");
}

TEST(ExportFrames, DownsamplingKeepsEveryOtherRecordedPose) {
    auto reader = RecordingReader::open(walkPath());
    ASSERT_TRUE(reader.ok());
    auto track = readPoseTrack(**reader, window({}, {}, 50));
    ASSERT_TRUE(track.ok()) << track.error().message;
    ASSERT_EQ(track->frames.size(), walk().size() / 2);  // 0, 0.02, ... 2.98 s
    for (std::size_t f = 0; f < track->frames.size(); ++f) {
        const RecordedPose& p = walk()[2 * f];
        EXPECT_NEAR(track->frames[f].tS, 0.02 * static_cast<double>(f), 1e-9);
        for (std::size_t s = 0; s < 21; ++s) {
            // Falls exactly on a recorded pose: only the float -> double conversion remains.
            EXPECT_LT(angleBetween(track->frames[f].qLocal[s], toD(p.qLocal[s])), 1e-9);
        }
    }
}

TEST(ExportFrames, UpsamplingSlerpsBetweenRecordedPoses) {
    auto reader = RecordingReader::open(walkPath());
    ASSERT_TRUE(reader.ok());
    auto track = readPoseTrack(**reader, window({}, {}, 300));
    ASSERT_TRUE(track.ok()) << track.error().message;
    EXPECT_EQ(track->frames.size(), 3 * (walk().size() - 1) + 1);  // up to the last pose, 2.99 s
    for (std::size_t f = 0; f + 3 < track->frames.size(); f += 3) {
        const RecordedPose& a = walk()[f / 3];
        const RecordedPose& b = walk()[f / 3 + 1];
        for (std::size_t k = 1; k < 3; ++k) {
            const double alpha = static_cast<double>(k) / 3.0;
            const PoseFrame& got = track->frames[f + k];
            for (std::size_t s = 0; s < 21; ++s) {
                const Quatd want = toD(a.qLocal[s]).slerp(alpha, toD(b.qLocal[s]));
                // The grid time is rounded to whole ns: alpha is off by up to 0.5 ns / 10 ms,
                // far below 1e-6 rad for any joint speed under 2000 rad/s.
                EXPECT_LT(angleBetween(got.qLocal[s], want), 1e-6) << f + k << " " << s;
            }
            const Vec3d rootWant =
                a.rootM.cast<double>() + alpha * (b.rootM - a.rootM).cast<double>();
            EXPECT_LT((got.rootM - rootWant).norm(), 1e-9);
        }
    }
}

TEST(ExportFrames, FromAndToCutAWindowInSecondsFromTheFirstPose) {
    auto reader = RecordingReader::open(walkPath());
    ASSERT_TRUE(reader.ok());
    auto track = readPoseTrack(**reader, window(1.0, 2.0, {}));
    ASSERT_TRUE(track.ok()) << track.error().message;
    ASSERT_EQ(track->frames.size(), 101u);  // 1.00, 1.01, ..., 2.00 s
    EXPECT_NEAR(track->frames.front().tS, 1.0, 1e-9);
    EXPECT_NEAR(track->frames.back().tS, 2.0, 1e-9);
    EXPECT_LT(angleBetween(track->frames.front().qLocal[7], toD(walk()[100].qLocal[7])), 1e-9);
}

TEST(ExportFrames, BadWindowAndRateAreRefused) {
    for (const TrackOptions& o :
         {window(2.0, 1.0, {}), window(10.0, {}, {}), window({}, {}, 0.0), window({}, {}, -5.0),
          window({}, {}, std::nan("")), window(-1.0, {}, {})}) {
        auto reader = RecordingReader::open(walkPath());
        ASSERT_TRUE(reader.ok());
        auto track = readPoseTrack(**reader, o);
        ASSERT_FALSE(track.ok());
        EXPECT_EQ(track.error().code, EINVAL);
    }
}

TEST(ExportFrames, DamagedRecordExportsTheRestAndCountsWhatWasSkipped) {
    const std::string rec = temp("damaged.cap");
    const auto poses = writeWalkRecording(rec);
    std::string bytes = readText(rec);
    // Pose records are 20 + 16 + 16 * 21 + 4 (the not-measured mask) + 4 = 380 bytes after the
    // header: flip one byte in the payload of poses 50 and 51, and break the sync marker of pose
    // 200.
    constexpr std::size_t kRecord = 380;
    const std::size_t first = bytes.size() - poses.size() * kRecord;
    bytes[first + 50 * kRecord + 100] ^= 0x5a;
    bytes[first + 51 * kRecord + 30] ^= 0x01;
    bytes[first + 200 * kRecord] ^= 0x7f;
    std::ofstream(rec, std::ios::binary | std::ios::trunc) << bytes;

    auto s = exportRecording(rec, temp("damaged.csv"), as(Format::Csv));
    ASSERT_TRUE(s.ok()) << s.error().message;
    EXPECT_EQ(s->poseRecords, poses.size() - 3);
    EXPECT_EQ(s->damagedBytes, 3 * kRecord);
    EXPECT_GE(s->damageRanges, 2u);
    // The gaps are bridged: the export still covers the whole recording at its rate.
    EXPECT_EQ(s->frames, poses.size());
    EXPECT_EQ(lines(readText(temp("damaged.csv"))).size(), poses.size() + 1);
}

TEST(ExportFrames, RecordingWithoutPosesSaysTheBodyStageWasOff) {
    const std::string rec = temp("raw-only.cap");
    writeWalkRecording(rec, walkOptions(0.2, 1.75, false));
    auto s = exportRecording(rec, temp("raw-only.bvh"), {});
    ASSERT_FALSE(s.ok());
    EXPECT_THAT(s.error().message, HasSubstr("no pose records: was the body stage on?"));
    EXPECT_FALSE(std::filesystem::exists(temp("raw-only.bvh")));
    EXPECT_FALSE(std::filesystem::exists(temp("raw-only.bvh.part")));
}

TEST(ExportFrames, NotARecordingIsAnError) {
    const std::string path = temp("not-a-recording.cap");
    std::ofstream(path) << "HIERARCHY\n";
    auto s = exportRecording(path, temp("x.bvh"), {});
    ASSERT_FALSE(s.ok());
    EXPECT_THAT(s.error().message, HasSubstr(path));
}

TEST(ExportFrames, UnwritableOutputIsAnErrorNamingIt) {
    const std::string out = temp("no-such-dir/out.bvh");
    auto s = exportRecording(walkPath(), out, {});
    ASSERT_FALSE(s.ok());
    EXPECT_THAT(s.error().message, HasSubstr(out));
}

// ---------------------------------------------------------------------------------------------
// CSV and .sto.

TEST(ExportCsv, HeaderRowsAndPositionsInTheChosenUnit) {
    const std::string out = temp("walk.csv");
    exportOk(walkPath(), out, as(Format::Csv, 100));
    const auto rows = lines(readText(out));
    ASSERT_EQ(rows.size(), walk().size() + 1);
    const auto header = split(rows[0], ',');
    ASSERT_EQ(header.size(), 1u + 21 * 7 + 1);
    EXPECT_EQ(header[0], "t");
    EXPECT_EQ(header[1], "pelvis_qw");
    EXPECT_EQ(header[7], "pelvis_pz");
    EXPECT_EQ(header[1 + 20 * 7 + 6], "r_middistal_pz");
    EXPECT_EQ(header.back(), "not_measured");
    for (std::size_t f = 0; f < walk().size(); f += 37) {
        const auto cells = split(rows[f + 1], ',');
        ASSERT_EQ(cells.size(), header.size());
        EXPECT_NEAR(std::stod(cells[0]), 0.01 * static_cast<double>(f), 1e-6);
        // The pelvis origin is the root: cm, 6 decimals.
        for (int c = 0; c < 3; ++c) {
            EXPECT_NEAR(std::stod(cells[5 + static_cast<std::size_t>(c)]),
                        walk()[f].rootM[c] * 100.0, 1e-4);
        }
        // World orientations are the walk's own (7 decimals, float recording).
        for (std::size_t s = 0; s < 21; ++s) {
            const Quatd q(std::stod(cells[1 + s * 7]), std::stod(cells[2 + s * 7]),
                          std::stod(cells[3 + s * 7]), std::stod(cells[4 + s * 7]));
            EXPECT_LT(angleBetween(q.normalized(), walk()[f].qWorld[s]) * kDeg, 0.01)
                << f << " " << s;
        }
    }
}

ExportOptions stoOf(StoOrientations which, const std::string& names = "hanim") {
    ExportOptions o = as(Format::Sto);
    o.stoOrientations = which;
    o.names = names;
    return o;
}

TEST(ExportSto, OpenSenseHeaderImuColumnsAndWxyzCells) {
    const std::string out = temp("walk.sto");
    exportOk(walkPath(), out, stoOf(StoOrientations::Segments));
    const auto rows = lines(readText(out));
    ASSERT_EQ(rows.size(), 6 + walk().size());
    EXPECT_EQ(rows[0], "DataRate=100.000000");
    EXPECT_EQ(rows[1], "DataType=Quaternion");
    EXPECT_EQ(rows[2], "version=3");
    EXPECT_EQ(rows[3], "OpenSimVersion=4.1");
    EXPECT_EQ(rows[4], "endheader");
    const auto header = split(rows[5], '\t');
    ASSERT_EQ(header.size(), 22u);
    EXPECT_EQ(header[0], "time");
    EXPECT_EQ(header[1], "pelvis_imu");
    EXPECT_EQ(header[9], "l_hand_imu");
    const auto cells = split(rows[6 + 120], '\t');
    ASSERT_EQ(cells.size(), 22u);
    EXPECT_NEAR(std::stod(cells[0]), 1.2, 1e-9);
    for (std::size_t s = 0; s < 21; ++s) {
        const auto wxyz = split(cells[s + 1], ',');
        ASSERT_EQ(wxyz.size(), 4u);
        const Quatd q(std::stod(wxyz[0]), std::stod(wxyz[1]), std::stod(wxyz[2]),
                      std::stod(wxyz[3]));
        EXPECT_NEAR(q.norm(), 1.0, 1e-6);  // 7 decimals per component
        EXPECT_LT(angleBetween(q.normalized(), walk()[120].qWorld[s]) * kDeg, 0.01) << s;
    }
}

TEST(ExportSto, QuaternionColumnsDoNotFlipSign) {
    const std::string out = temp("flip.sto");
    exportOk(walkPath(), out, stoOf(StoOrientations::Segments));
    const auto rows = lines(readText(out));
    std::vector<Eigen::Vector4d> previous(21);
    for (std::size_t r = 6; r < rows.size(); ++r) {
        const auto cells = split(rows[r], '\t');
        for (std::size_t s = 0; s < 21; ++s) {
            const auto c = split(cells[s + 1], ',');
            const Eigen::Vector4d q(std::stod(c[0]), std::stod(c[1]), std::stod(c[2]),
                                    std::stod(c[3]));
            if (r > 6) {
                EXPECT_GT(q.dot(previous[s]), 0.0) << r << " " << s;
            }
            previous[s] = q;
        }
    }
}

// The sensors' orientations, the default: one column per sensor of the recording's board, in its
// order, each the segment's world orientation times the sensor's mounting (q_world_sensor =
// q_world_segment q_segment_sensor): without a body calibration in the file the board's nominal
// mountings.
TEST(ExportSto, SensorColumnsHoldEachSensorsOrientationThroughItsNominalMounting) {
    const board::LoadResult suit =
        board::loadBoardFile(std::filesystem::path(CAPHUB_SOURCE_DIR) / "board/sim-suit.toml");
    ASSERT_TRUE(suit.ok());
    const std::string out = temp("sensors.sto");
    exportOk(walkPath(), out, as(Format::Sto));  // sensors by default
    const auto rows = lines(readText(out));
    ASSERT_EQ(rows.size(), 6 + walk().size());
    const auto header = split(rows[5], '\t');
    ASSERT_EQ(header.size(), 1 + suit.board->sensors.size());
    for (std::size_t c = 0; c < suit.board->sensors.size(); ++c) {
        EXPECT_EQ(header[c + 1],
                  std::string(board::segmentName(suit.board->sensors[c].segment)) + "_imu");
    }
    // Not trivially the segments': the shipped suit's nominal mountings are not all identity.
    double largestMountingDeg = 0;
    for (std::size_t r : {0u, 150u, 299u}) {
        const auto cells = split(rows[6 + r], '\t');
        for (std::size_t c = 0; c < suit.board->sensors.size(); ++c) {
            const auto& sensor = suit.board->sensors[c];
            const auto wxyz = split(cells[c + 1], ',');
            ASSERT_EQ(wxyz.size(), 4u);
            const Quatd q = Quatd(std::stod(wxyz[0]), std::stod(wxyz[1]), std::stod(wxyz[2]),
                                  std::stod(wxyz[3]))
                                .normalized();
            const Quatd expected =
                walk()[r].qWorld[static_cast<std::size_t>(sensor.segment)] * sensor.mounting;
            // float poses in the file, 7 decimals per component: well within 0.01 deg.
            EXPECT_LT(angleBetween(q, expected) * kDeg, 0.01) << r << " " << sensor.name;
            largestMountingDeg = std::max(largestMountingDeg,
                                          angleBetween(sensor.mounting, Quatd::Identity()) * kDeg);
        }
    }
    EXPECT_GT(largestMountingDeg, 10.0);
}

// A body calibration recorded in the file gives the mountings from its time on (and before it,
// since the capture writes no pose before its first calibration).
TEST(ExportSto, SensorColumnsFollowTheRecordedBodyCalibration) {
    body::BodyCalibration cal;
    cal.method = body::CalibrationMethod::TPose;
    std::mt19937 rng(7);
    std::normal_distribution<double> n(0, 1);
    for (int s : {body::idx(body::Segment::Pelvis), body::idx(body::Segment::LCalf)}) {
        cal.mask |= body::SegmentMask{1} << s;
        cal.mounting[static_cast<std::size_t>(s)] =
            Quatd(n(rng), n(rng), n(rng), n(rng)).normalized();
    }
    WalkRecordingOptions o;
    o.bodyCalibrationText = body::toText(cal);
    o.calibrationAtS = 1.0;
    const std::string rec = temp("calibrated.cap");
    const auto poses = writeWalkRecording(rec, o);
    const std::string out = temp("calibrated.sto");
    exportOk(rec, out, as(Format::Sto));
    const board::LoadResult suit =
        board::loadBoardFile(std::filesystem::path(CAPHUB_SOURCE_DIR) / "board/sim-suit.toml");
    ASSERT_TRUE(suit.ok());
    const auto rows = lines(readText(out));
    const auto header = split(rows[5], '\t');
    const auto column = [&](const std::string& label) {
        return static_cast<std::size_t>(std::find(header.begin(), header.end(), label) -
                                        header.begin());
    };
    for (std::size_t r : {0u, 99u, 100u, 250u}) {
        const auto cells = split(rows[6 + r], '\t');
        for (auto [label, segment] : {std::pair{"pelvis_imu", body::Segment::Pelvis},
                                      std::pair{"l_calf_imu", body::Segment::LCalf},
                                      std::pair{"r_calf_imu", body::Segment::RCalf}}) {
            const auto c = column(label);
            ASSERT_LT(c, header.size()) << label;
            const auto wxyz = split(cells[c], ',');
            const Quatd q = Quatd(std::stod(wxyz[0]), std::stod(wxyz[1]), std::stod(wxyz[2]),
                                  std::stod(wxyz[3]))
                                .normalized();
            const auto i = static_cast<std::size_t>(body::idx(segment));
            Quatd mounting = cal.mounting[i];
            if (!body::has(cal.mask, body::idx(segment))) {
                for (const auto& sc : suit.board->sensors) {
                    if (sc.segment == segment) {
                        mounting = sc.mounting;  // not calibrated: the nominal one
                    }
                }
            }
            EXPECT_LT(angleBetween(q, poses[r].qWorld[i] * mounting) * kDeg, 0.01)
                << r << " " << label;
        }
    }
}

// --names opensim: the body names of OpenSim's full-body models, whose IMU placer finds a body
// by taking "_imu" off the column label; sensors on segments those models have no body for
// (the head, the clavicles) are left out.
TEST(ExportSto, OpenSimNamesGiveTheModelsBodies) {
    const std::string sensors = temp("opensim-sensors.sto");
    exportOk(walkPath(), sensors, stoOf(StoOrientations::Sensors, "opensim"));
    EXPECT_EQ(lines(readText(sensors))[5],
              "time\tpelvis_imu\ttorso_imu\thumerus_l_imu\tradius_l_imu\thand_l_imu\t"
              "humerus_r_imu\tradius_r_imu\thand_r_imu\tfemur_l_imu\ttibia_l_imu\tcalcn_l_imu\t"
              "femur_r_imu\ttibia_r_imu\tcalcn_r_imu");
    const std::string segments = temp("opensim-segments.sto");
    exportOk(walkPath(), segments, stoOf(StoOrientations::Segments, "opensim"));
    const auto rows = lines(readText(segments));
    EXPECT_EQ(rows[5],
              "time\tpelvis_imu\ttorso_imu\thumerus_l_imu\tradius_l_imu\thand_l_imu\t"
              "humerus_r_imu\tradius_r_imu\thand_r_imu\tfemur_l_imu\ttibia_l_imu\tcalcn_l_imu\t"
              "toes_l_imu\tfemur_r_imu\ttibia_r_imu\tcalcn_r_imu\ttoes_r_imu");
    // torso_imu is the t12 segment's orientation.
    const auto cells = split(rows[6 + 42], '\t');
    const auto wxyz = split(cells[2], ',');
    const Quatd q(std::stod(wxyz[0]), std::stod(wxyz[1]), std::stod(wxyz[2]), std::stod(wxyz[3]));
    EXPECT_LT(
        angleBetween(q.normalized(),
                     walk()[42].qWorld[static_cast<std::size_t>(body::idx(body::Segment::T12))]) *
            kDeg,
        0.01);
}

TEST(ExportSto, OpenSimNamesAreForStoOnlyAndSensorsNeedABoard) {
    ExportOptions bvh = as(Format::Bvh);
    bvh.names = "opensim";
    FailureKind kind = FailureKind::Work;
    auto r = exportRecording(walkPath(), temp("opensim.bvh"), bvh, {}, &kind);
    ASSERT_FALSE(r.ok());
    EXPECT_THAT(r.error().message, HasSubstr("for --format sto only"));
    EXPECT_EQ(kind, FailureKind::Input);

    // A recording without a board file: no sensors to name.
    const std::string rec = temp("boardless.cap");
    {
        auto writer = RecordingWriter::create(rec, "[recording]\nsoftware = \"test\"\n");
        ASSERT_TRUE(writer.ok());
        std::array<Eigen::Quaternionf, board::kSegmentCount> q;
        q.fill(Eigen::Quaternionf::Identity());
        for (int k = 0; k < 3; ++k) {
            ASSERT_EQ(
                (*writer)->writePose(timestampFromNs(k * 10'000'000), Eigen::Vector3f::Zero(), q),
                0);
        }
        ASSERT_EQ((*writer)->close(), 0);
    }
    kind = FailureKind::Work;
    r = exportRecording(rec, temp("boardless.sto"), as(Format::Sto), {}, &kind);
    ASSERT_FALSE(r.ok());
    EXPECT_THAT(r.error().message, HasSubstr("--orientations segments"));
    EXPECT_EQ(kind, FailureKind::Input);
    exportOk(rec, temp("boardless-segments.sto"), stoOf(StoOrientations::Segments));
}

// ---------------------------------------------------------------------------------------------
// Segments not measured (a sensor out): held in the file, and said.

// The walk with the left hand and forearm not measured from 1.0 to 1.5 s.
std::string heldWalkPath() {
    static const std::string path = [] {
        const std::string p = temp("held.cap");
        WalkRecordingOptions o;
        o.heldSegments = 1u << static_cast<int>(board::Segment::LHand) |
                         1u << static_cast<int>(board::Segment::LForearm);
        o.heldFromS = 1.0;
        o.heldToS = 1.5;
        (void)writeWalkRecording(p, o);
        return p;
    }();
    return path;
}

TEST(ExportNotMeasured, TheSummaryListsEachSegmentsSpan) {
    const ExportSummary s = exportOk(heldWalkPath(), temp("held.bvh"), {});
    ASSERT_EQ(s.notMeasured.size(), 2u);
    for (const auto& span : s.notMeasured) {
        EXPECT_TRUE(span.segment == board::Segment::LHand ||
                    span.segment == board::Segment::LForearm);
        EXPECT_NEAR(span.fromS, 1.0, 1e-9);
        EXPECT_NEAR(span.toS, 1.5, 1e-9);
    }
    EXPECT_TRUE(exportOk(walkPath(), temp("measured.bvh"), {}).notMeasured.empty());
}

TEST(ExportNotMeasured, CsvNamesTheHeldSegmentsInEachRow) {
    const std::string out = temp("held.csv");
    exportOk(heldWalkPath(), out, as(Format::Csv));
    const auto rows = lines(readText(out));
    ASSERT_EQ(rows.size(), 301u);
    int held = 0;
    for (std::size_t f = 1; f < rows.size(); ++f) {
        const auto cells = split(rows[f], ',');
        const double t = std::stod(cells[0]);
        ASSERT_EQ(cells.size(), 1u + 21 * 7 + 1);
        const std::string& last = cells.back();
        if (t >= 1.0 - 1e-9 && t <= 1.5 + 1e-9) {
            EXPECT_EQ(last, "l_forearm l_hand") << rows[f].substr(0, 12);
            ++held;
        } else {
            EXPECT_EQ(last, "") << rows[f].substr(0, 12);
        }
    }
    EXPECT_EQ(held, 51);
}

TEST(ExportNotMeasured, GlbListsTheHeldJointsInTheAnimationsExtras) {
    const std::string out = temp("held.glb");
    exportOk(heldWalkPath(), out, as(Format::Glb));
    tinygltf::TinyGLTF loader;
    tinygltf::Model model;
    std::string err;
    std::string warn;
    ASSERT_TRUE(loader.LoadBinaryFromFile(&model, &err, &warn, out)) << err;
    ASSERT_EQ(model.animations.size(), 1u);
    const tinygltf::Value& list = model.animations[0].extras.Get("caphub_not_measured");
    ASSERT_TRUE(list.IsArray());
    ASSERT_EQ(list.ArrayLen(), 2u);
    std::vector<std::string> joints;
    for (std::size_t i = 0; i < list.ArrayLen(); ++i) {
        joints.push_back(list.Get(static_cast<int>(i)).Get("joint").Get<std::string>());
        EXPECT_NEAR(list.Get(static_cast<int>(i)).Get("from_s").GetNumberAsDouble(), 1.0, 1e-9);
        EXPECT_NEAR(list.Get(static_cast<int>(i)).Get("to_s").GetNumberAsDouble(), 1.5, 1e-9);
    }
    EXPECT_THAT(joints, ::testing::UnorderedElementsAre("l_elbow", "l_radiocarpal"));
    // A recording with every segment measured has no such list.
    exportOk(walkPath(), temp("measured.glb"), as(Format::Glb));
    tinygltf::Model measured;
    ASSERT_TRUE(loader.LoadBinaryFromFile(&measured, &err, &warn, temp("measured.glb"))) << err;
    EXPECT_FALSE(measured.animations.at(0).extras.Has("caphub_not_measured"));
}

// ---------------------------------------------------------------------------------------------
// glb.

TEST(ExportGlb, LoadsWithTinygltfWithTheSkinTheJointsAndOneAnimation) {
    const std::string out = temp("walk.glb");
    exportOk(walkPath(), out, as(Format::Glb));
    tinygltf::TinyGLTF loader;
    tinygltf::Model model;
    std::string err;
    std::string warn;
    ASSERT_TRUE(loader.LoadBinaryFromFile(&model, &err, &warn, out)) << err;
    EXPECT_TRUE(err.empty()) << err;
    const auto skin = render::loadDefaultSkin();
    ASSERT_TRUE(skin.ok());
    ASSERT_EQ(model.nodes.size(), 22u);  // 21 joints and the mesh
    EXPECT_EQ(model.nodes[0].name, "humanoid_root");
    ASSERT_EQ(model.skins.size(), 1u);
    EXPECT_EQ(model.skins[0].joints.size(), 21u);
    EXPECT_EQ(model.accessors[static_cast<std::size_t>(model.skins[0].inverseBindMatrices)].count,
              21u);
    ASSERT_EQ(model.meshes.size(), 1u);
    const auto& prim = model.meshes[0].primitives.at(0);
    for (const char* a : {"POSITION", "NORMAL", "JOINTS_0", "WEIGHTS_0"}) {
        ASSERT_EQ(prim.attributes.count(a), 1u) << a;
        EXPECT_EQ(model.accessors[static_cast<std::size_t>(prim.attributes.at(a))].count,
                  skin->vertexCount())
            << a;
    }
    EXPECT_EQ(model.accessors[static_cast<std::size_t>(prim.indices)].count,
              skin->triangles.size() * 3);
    ASSERT_EQ(model.animations.size(), 1u);
    const auto& anim = model.animations[0];
    EXPECT_EQ(anim.channels.size(), 22u);  // 21 rotations and the root's translation
    for (const auto& s : anim.samplers) {
        EXPECT_EQ(s.interpolation, "LINEAR");
        EXPECT_EQ(model.accessors[static_cast<std::size_t>(s.input)].count, walk().size());
        EXPECT_EQ(model.accessors[static_cast<std::size_t>(s.output)].count, walk().size());
    }
    const auto& times = model.accessors[static_cast<std::size_t>(anim.samplers[0].input)];
    EXPECT_EQ(times.minValues.at(0), 0.0);
    EXPECT_NEAR(times.maxValues.at(0), 2.99, 1e-6);  // float seconds
}

TEST(ExportGlb, AnimationRotationsAreTheRecordedJointRotations) {
    const std::string out = temp("values.glb");
    exportOk(walkPath(), out, as(Format::Glb));
    tinygltf::TinyGLTF loader;
    tinygltf::Model model;
    std::string err;
    std::string warn;
    ASSERT_TRUE(loader.LoadBinaryFromFile(&model, &err, &warn, out)) << err;
    for (const auto& ch : model.animations[0].channels) {
        if (ch.target_path != "rotation") {
            continue;
        }
        const auto& acc = model.accessors[static_cast<std::size_t>(
            model.animations[0].samplers[static_cast<std::size_t>(ch.sampler)].output)];
        const auto& view = model.bufferViews[static_cast<std::size_t>(acc.bufferView)];
        const auto* data = reinterpret_cast<const float*>(model.buffers[0].data.data() +
                                                          view.byteOffset + acc.byteOffset);
        for (std::size_t f = 0; f < walk().size(); f += 50) {
            const float* v = data + 4 * f;
            const Quatd got(v[3], v[0], v[1], v[2]);  // glTF: x, y, z, w
            const auto& want = walk()[f].qLocal[static_cast<std::size_t>(ch.target_node)];
            // Float in, float out: a few ulps of a unit quaternion.
            EXPECT_LT(angleBetween(got, toD(want)) * kDeg, 1e-4) << ch.target_node << " " << f;
        }
    }
}

TEST(ExportGlb, CentimetresAreRefusedBecauseGltfIsInMetres) {
    auto s = exportRecording(walkPath(), temp("cm.glb"), as(Format::Glb, 100));
    ASSERT_FALSE(s.ok());
    EXPECT_THAT(s.error().message, HasSubstr("metres"));
}

}  // namespace
}  // namespace caphub::firmware::exporter
