// caphub export run as a person would: the summary line, the exit codes, the messages for a
// recording without poses, a damaged recording and bad options, and progress on a terminal.
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include "board/sim/bvh.h"
#include "firmware/recording/reader.h"
#include "firmware/recording/writer.h"
#include "fusion/body/skeleton.h"
#include "hal/core/quaternion.h"
#include "tests/firmware/cli_run.h"
#include "tests/firmware/export_fixture.h"

namespace {

using ::testing::HasSubstr;
using ::testing::Not;

using caphub::testing::caphub;
using caphub::testing::CliRun;
using caphub::testing::shell;

std::string temp(const std::string& name) {
    // ctest runs each test in its own process, in parallel: each process has its own files.
    return ::testing::TempDir() + "caphub_export_cli_" + std::to_string(getpid()) + "_" + name;
}

const std::string& walk() {
    static const std::string path = [] {
        const std::string p = temp("walk.cap");
        caphub::firmware::testing::writeWalkRecording(p);
        return p;
    }();
    return path;
}

// The whole product path: `caphub run` captures the virtual suit (chip models, drivers, workers,
// filters, body solver) into a recording, `caphub export` writes BVH, the project's BVH reader
// reads it back, and every joint of every frame is the recording's pose within 0.01 deg.
TEST(ExportCli, ACaptureOfTheVirtualSuitRoundTripsThroughBvhWithinAHundredthOfADegree) {
    const std::string rec = temp("capture.cap");
    const CliRun run = caphub(
        "run --board sim-suit --duration 3 --pose-rate 50 "
        "--no-preview --record " +
        rec + " --status-file " + temp("status.json"));
    ASSERT_EQ(run.exitCode, 0) << run.output;
    ASSERT_THAT(run.output, HasSubstr("recording: " + rec));

    std::vector<std::vector<Eigen::Quaternionf>> poses;
    std::vector<Eigen::Vector3f> roots;
    {
        auto reader = caphub::firmware::RecordingReader::open(rec);
        ASSERT_TRUE(reader.ok()) << reader.error().message;
        caphub::firmware::RecordView v;
        while ((*reader)->next(v) == 1) {
            Eigen::Vector3f root;
            std::vector<Eigen::Quaternionf> joints;
            if (v.type == caphub::firmware::cap::RecordType::Pose &&
                caphub::firmware::decodePose(v, root, joints)) {
                poses.push_back(joints);
                roots.push_back(root);
            }
        }
        EXPECT_TRUE((*reader)->damage().empty());
    }
    ASSERT_GT(poses.size(), 100u);  // 3 s at 50 Hz, less the first sample's wait

    const std::string out = temp("capture.bvh");
    const CliRun ex = caphub("export " + rec + " --format bvh -o " + out);
    ASSERT_EQ(ex.exitCode, 0) << ex.output;
    auto clip = caphub::board::sim::loadBvh(out);
    ASSERT_TRUE(clip.ok()) << clip.error().message;
    // Poses are on a fixed grid of the pose rate, so the export at that rate has one frame each.
    ASSERT_EQ(clip->frameCount, static_cast<int>(poses.size()));
    const auto& names = caphub::body::joints();
    double worstDeg = 0;
    double worstRootM = 0;
    for (int f = 0; f < clip->frameCount; ++f) {
        for (int seg = 0; seg < caphub::body::kSegmentCount; ++seg) {
            const int j = clip->findJoint(names[static_cast<std::size_t>(seg)].name);
            ASSERT_GE(j, 0);
            caphub::Vec3d t;
            caphub::Quatd q;
            clip->localPose(j, clip->frame(f), t, q);
            const caphub::Quatd recorded =
                poses[static_cast<std::size_t>(f)][static_cast<std::size_t>(seg)].cast<double>();
            worstDeg =
                std::max(worstDeg, caphub::angleBetween(q, recorded.normalized()) * 180.0 / M_PI);
            if (seg == 0) {
                worstRootM = std::max(
                    worstRootM, (t - roots[static_cast<std::size_t>(f)].cast<double>()).norm());
            }
        }
    }
    EXPECT_LT(worstDeg, 0.01);  // the bound
    // 6 decimals of a metre in the text: 0.5 um per axis, plus float rounding of the recording.
    EXPECT_LT(worstRootM, 2e-6);
    std::cout << "capture -> BVH round trip: " << poses.size() << " poses, worst joint error "
              << worstDeg << " deg, root " << worstRootM << " m\n";
}

TEST(ExportCli, PrintsAOneLineSummaryWithFramesDurationAndSize) {
    const std::string out = temp("walk.bvh");
    const CliRun r = caphub("export " + walk() + " --format bvh -o " + out);
    EXPECT_EQ(r.exitCode, 0) << r.output;
    EXPECT_THAT(r.output, HasSubstr(out + ": 300 frames, 2.990 s at 100 Hz, "));
    EXPECT_THAT(r.output, HasSubstr("KiB (bvh)"));
    EXPECT_TRUE(std::filesystem::exists(out));
}

TEST(ExportCli, EveryFormatAndOptionIsAccepted) {
    for (const char* args :
         {"--format glb", "--format csv --units cm --rate 50", "--format sto --from 1 --to 2",
          "--format bvh --names cmu --reference-frame --rate 29.97"}) {
        const CliRun r = caphub("export " + walk() + " " + args + " -o " + temp("any.out"));
        EXPECT_EQ(r.exitCode, 0) << args << "\n" << r.output;
    }
    const CliRun r =
        caphub("export " + walk() + " --format sto --from 1 --to 2 -o " + temp("window.sto"));
    EXPECT_THAT(r.output, HasSubstr("101 frames, 1.000 s"));
}

TEST(ExportCli, RecordingWithoutPosesFailsWithTheReason) {
    const std::string rec = temp("raw.cap");
    caphub::firmware::testing::WalkRecordingOptions o;
    o.seconds = 0.1;
    o.withPoses = false;
    caphub::firmware::testing::writeWalkRecording(rec, o);
    const CliRun r = caphub("export " + rec + " --format bvh -o " + temp("raw.bvh"));
    EXPECT_EQ(r.exitCode, 2);  // the recording given has nothing to export
    EXPECT_THAT(r.output, HasSubstr("no pose records: was the body stage on?"));
}

TEST(ExportCli, DamagedRecordingExportsAndSaysHowMuchWasSkipped) {
    const std::string rec = temp("damaged.cap");
    const auto poses = caphub::firmware::testing::writeWalkRecording(rec);
    std::string bytes;
    {
        std::ifstream in(rec, std::ios::binary);
        std::stringstream s;
        s << in.rdbuf();
        bytes = s.str();
    }
    // A pose record of 21 joints: 20 + 16 + 21 x 16 + 4 (the not-measured mask) + 4 bytes.
    constexpr std::size_t kPoseRecord = 380;
    bytes[bytes.size() - 100 * kPoseRecord + 50] ^= 0x20;  // inside pose record 200 (of 300)
    std::ofstream(rec, std::ios::binary | std::ios::trunc) << bytes;
    const CliRun r = caphub("export " + rec + " --format csv -o " + temp("damaged.csv"));
    EXPECT_EQ(r.exitCode, 0) << r.output;
    EXPECT_THAT(r.output, HasSubstr("skipped 380 bytes in 1 damaged range(s)"));
    EXPECT_THAT(r.output, HasSubstr("299 good pose records"));
    EXPECT_THAT(r.output, HasSubstr("300 frames"));
}

TEST(ExportCli, BadOptionsAreUsageErrors) {
    const std::string out = temp("bad.out");
    EXPECT_EQ(caphub("export " + walk() + " --format fbx -o " + out).exitCode, 2);
    EXPECT_EQ(caphub("export " + walk() + " --format bvh -o " + out + " --units mm").exitCode, 2);
    EXPECT_EQ(caphub("export " + walk() + " --format bvh -o " + out + " --rate 0").exitCode, 2);
    const CliRun window = caphub("export " + walk() + " --format bvh -o " + out + " --from 9");
    EXPECT_EQ(window.exitCode, 2);
    EXPECT_THAT(window.output, HasSubstr("--from 9 s: the poses end at 2.990 s"));
    const CliRun glbCm = caphub("export " + walk() + " --format glb --units cm -o " + out);
    EXPECT_EQ(glbCm.exitCode, 2);
    const CliRun ref = caphub("export " + walk() + " --format csv --reference-frame -o " + out);
    EXPECT_EQ(ref.exitCode, 2);
    EXPECT_THAT(ref.output, HasSubstr("--reference-frame is for bvh only"));
}

TEST(ExportCli, NamesFileErrorsGiveFileAndLine) {
    const std::string names = temp("names.toml");
    std::ofstream(names) << "pelvis = \"Hips\"\nknee = \"Knee\"\n";
    const CliRun r =
        caphub("export " + walk() + " --format bvh --names " + names + " -o " + temp("n.bvh"));
    EXPECT_EQ(r.exitCode, 2);
    EXPECT_THAT(r.output, HasSubstr(names + ":2: 'knee' is not a segment"));
}

TEST(ExportCli, MissingRecordingIsAnError) {
    const CliRun r = caphub("export " + temp("none.cap") + " --format bvh -o " + temp("x.bvh"));
    EXPECT_NE(r.exitCode, 0);
    EXPECT_THAT(r.output, HasSubstr(temp("none.cap")));
}

TEST(ExportCli, ProgressIsShownOnATerminalOnly) {
    const std::string out = temp("progress.csv");
    const CliRun piped = caphub("export " + walk() + " --format csv -o " + out);
    EXPECT_THAT(piped.output, Not(HasSubstr("100%")));
    // script(1) gives the command a pseudo-terminal.
    if (shell("command -v script").exitCode != 0) {
        GTEST_FAIL() << "script(1) (util-linux) is needed to give caphub a terminal";
    }
    const CliRun tty = shell("script -qec '" + std::string(CAPHUB_BINARY) + " export " + walk() +
                             " --format csv -o " + out + "' /dev/null");
    EXPECT_EQ(tty.exitCode, 0) << tty.output;
    EXPECT_THAT(tty.output, HasSubstr("writing  100%"));
}

}  // namespace

namespace {

// `caphub info` lists the spans in which a segment's sensor was out (the poses' not-measured
// masks), per segment, in the recording's time.
TEST(InfoCli, ListsTheSpansInWhichASegmentWasNotMeasured) {
    const std::string rec = temp("gaps.cap");
    std::filesystem::remove(rec);
    {
        auto w = caphub::firmware::RecordingWriter::create(rec, "");
        ASSERT_TRUE(w.ok()) << w.error().message;
        const std::vector<Eigen::Quaternionf> joints(21, Eigen::Quaternionf::Identity());
        const std::uint32_t pelvis = 1u << 0;
        const std::uint32_t forearm = 1u << 12;
        for (int k = 0; k <= 300; ++k) {  // 5 s at 60 Hz
            std::uint32_t mask = 0;
            if (k >= 60 && k < 120) {
                mask |= forearm;  // 1.000 - 1.983 s
            }
            if (k >= 180 && k < 190) {
                mask |= forearm | pelvis;  // 3.000 - 3.150 s
            }
            ASSERT_EQ(
                (*w)->writePose(caphub::timestampFromNs(1'000'000'000LL + k * 1'000'000'000LL / 60),
                                {0, 1, 0}, joints, mask),
                0);
        }
        ASSERT_EQ((*w)->close(), 0);
    }
    const CliRun info = caphub("info " + rec);
    ASSERT_EQ(info.exitCode, 0) << info.output;
    const std::string forearmName(
        caphub::board::segmentName(static_cast<caphub::board::Segment>(12)));
    const std::string pelvisName(
        caphub::board::segmentName(static_cast<caphub::board::Segment>(0)));
    EXPECT_THAT(info.output, HasSubstr("segments not measured"));
    EXPECT_THAT(info.output, HasSubstr(forearmName));
    EXPECT_THAT(info.output, HasSubstr("1.000 - 1.983 s (60 poses)"));
    EXPECT_THAT(info.output, HasSubstr("3.000 - 3.150 s (10 poses)"));
    EXPECT_THAT(info.output, HasSubstr(pelvisName));

    // A recording without gaps says so.
    const CliRun walkInfo = caphub("info " + walk());
    EXPECT_THAT(walkInfo.output, HasSubstr("segments not measured (no sensor on them, or their "
                                           "sensor out; held in the "
                                           "poses): none"));
}

}  // namespace
