// caphub export run as a person would: the summary line, the exit codes, the messages for a
// recording without poses, a damaged recording and bad options, and progress on a terminal.
#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

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
    EXPECT_EQ(r.exitCode, 1);
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
    bytes[bytes.size() - 100 * 376 + 50] ^= 0x20;  // inside pose record 200 (of 300)
    std::ofstream(rec, std::ios::binary | std::ios::trunc) << bytes;
    const CliRun r = caphub("export " + rec + " --format csv -o " + temp("damaged.csv"));
    EXPECT_EQ(r.exitCode, 0) << r.output;
    EXPECT_THAT(r.output, HasSubstr("skipped 376 bytes in 1 damaged range(s)"));
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
