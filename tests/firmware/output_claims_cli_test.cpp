// Faults found by trying evaluate, sim, calibrate, run, selftest and fusion replay as an
// attacker would: an output that named an input replaced it, an output into a FIFO hung, one into
// a missing folder failed only after the work, and numbers the commands took silently (a
// duration of 1e-10 s ran until Ctrl-C, a speed of 1e300 spun, 1e-9 Hz ran at the full rate).
#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include "tests/firmware/cli_run.h"

namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

using caphub::testing::caphub;
using caphub::testing::CliRun;
using caphub::testing::shell;

const std::string& dir() {
    static const std::string d =
        caphub::testing::freshFolder(::testing::TempDir(), "caphub_output_claims_");
    return d;
}

std::string path(const std::string& name) {
    return dir() + "/" + name;
}

std::string readAll(const std::string& file) {
    std::ifstream in(file, std::ios::binary);
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
}

// A copy of a short clip of the tree's, so that a regression overwrites nothing of the tree's.
const std::string& clip() {
    static const std::string p = [] {
        const std::string f = path("clip.bvh");
        fs::copy_file(CAPHUB_TEST_DATA_DIR "/bvh/cmu_16_36_run_daz.bvh", f,
                      fs::copy_options::overwrite_existing);
        return f;
    }();
    return p;
}

std::string fifo(const std::string& name) {
    const std::string p = path(name);
    fs::remove(p);
    EXPECT_EQ(::mkfifo(p.c_str(), 0644), 0);
    return p;
}

bool isFifo(const std::string& p) {
    struct stat st {};
    return ::lstat(p.c_str(), &st) == 0 && S_ISFIFO(st.st_mode);
}

// The command under a timeout: a regression that hangs fails the test instead of the suite.
CliRun bounded(const std::string& args) {
    return shell("timeout -k 3 60 " + std::string(CAPHUB_BINARY) + " " + args);
}

TEST(EvaluateOutput, TheJsonIsNeverAnInputAndIsCheckedBeforeTheRun) {
    const std::string before = readAll(clip());
    const CliRun self = bounded("evaluate --bvh " + clip() + " --json " + clip());
    EXPECT_EQ(self.exitCode, 2) << self.output;
    EXPECT_THAT(self.output, HasSubstr("which the command also reads or writes"));
    EXPECT_EQ(readAll(clip()), before);
    // Refused before the clip is played: no table was printed.
    const CliRun missing =
        bounded("evaluate --bvh " + clip() + " --json " + path("no-folder/scores.json"));
    EXPECT_EQ(missing.exitCode, 2) << missing.output;
    EXPECT_THAT(missing.output, HasSubstr("the folder '" + path("no-folder") + "' does not exist"));
    EXPECT_THAT(missing.output, ::testing::Not(HasSubstr("deg")));
    const std::string pipe = fifo("scores.fifo");
    const CliRun intoFifo = bounded("evaluate --bvh " + clip() + " --json " + pipe);
    EXPECT_EQ(intoFifo.exitCode, 2) << intoFifo.output;
    EXPECT_THAT(intoFifo.output, HasSubstr("is a FIFO"));
    EXPECT_TRUE(isFifo(pipe));
}

// Every clip is read before the first run: a clip whose skeleton is no body in metres (an
// OFFSET of 1e50 made every figure nan) is refused, named, before the good one's run.
TEST(EvaluateInputs, EveryClipIsReadBeforeTheFirstRun) {
    // The same clip with its abdomen 1e50 units above its hip.
    std::string text = readAll(clip());
    const std::string offset = "OFFSET 0 20.6881 -0.73152";
    ASSERT_NE(text.find(offset), std::string::npos);
    text.replace(text.find(offset), offset.size(), "OFFSET 0 1e50 0");
    const std::string giant = path("giant.bvh");
    std::ofstream(giant) << text;
    const CliRun r = bounded("evaluate --bvh " + clip() + " --bvh " + giant);
    EXPECT_EQ(r.exitCode, 2) << r.output;
    EXPECT_THAT(r.output, HasSubstr("'" + giant + "': line 6: joint 'abdomen': its OFFSET is"));
    EXPECT_THAT(r.output, ::testing::Not(HasSubstr("deg")));
    // A seed twice counted its run twice in every mean; one that is not a number ran as 0.
    const CliRun twice = bounded("evaluate --bvh " + clip() + " --seeds 1,2,1");
    EXPECT_EQ(twice.exitCode, 2) << twice.output;
    EXPECT_THAT(twice.output, HasSubstr("seed 1 is given twice"));
    const CliRun negative = bounded("evaluate --bvh " + clip() + " --seeds 1,-1");
    EXPECT_EQ(negative.exitCode, 2) << negative.output;
    EXPECT_THAT(negative.output, HasSubstr("Value '-1' is not a seed"));
}

TEST(SimOutput, AStreamIsNeverAnInputNorWrittenIntoAFifo) {
    const std::string before = readAll(clip());
    const CliRun self = bounded("sim --sensor pelvis --bvh " + clip() + " -o " + clip());
    EXPECT_EQ(self.exitCode, 2) << self.output;
    EXPECT_THAT(self.output, HasSubstr("which the command also reads or writes"));
    EXPECT_EQ(readAll(clip()), before);
    const std::string pipe = fifo("pelvis.fifo");
    const CliRun intoFifo = bounded("sim --sensor pelvis --bvh " + clip() + " -o " + pipe);
    EXPECT_EQ(intoFifo.exitCode, 2) << intoFifo.output;
    EXPECT_TRUE(isFifo(pipe));
    // In --all's folder a FIFO with a stream's name stops the command before the simulation,
    // with nothing written.
    fs::create_directories(path("all"));
    const std::string skeleton = fifo("all/skeleton.csv.gz");
    const CliRun all = bounded("sim --all --bvh " + clip() + " -o " + path("all"));
    EXPECT_EQ(all.exitCode, 2) << all.output;
    EXPECT_THAT(all.output, HasSubstr("skeleton.csv.gz' is a FIFO"));
    EXPECT_FALSE(fs::exists(path("all/pelvis.csv.gz")));
    EXPECT_TRUE(isFifo(skeleton));
    // And a stream that can be written is, whole, with no part left beside it.
    const CliRun ok = bounded("sim --sensor pelvis --bvh " + clip() + " -o " + path("p.csv.gz"));
    ASSERT_EQ(ok.exitCode, 0) << ok.output;
    EXPECT_GT(fs::file_size(path("p.csv.gz")), 1000u);
    EXPECT_FALSE(fs::exists(path("p.csv.gz.part")));
}

// A clip of a single frame of motion gave a capture of no duration, which runs until stopped:
// sim never ended.
TEST(SimInputs, AClipOfOneFrameIsRefusedInsteadOfSimulatedForEver) {
    // The Daz clip's map starts its motion at frame 6: seven frames leave one of motion.
    const std::string text = readAll(clip());
    const std::size_t frames = text.find("Frames:");
    const std::size_t frameTime = text.find("Frame Time:");
    ASSERT_NE(frames, std::string::npos);
    std::size_t end = text.find('\n', frameTime);
    for (int row = 0; row < 7; ++row) {
        end = text.find('\n', end + 1);
    }
    const std::string one = path("one-frame.bvh");
    std::ofstream(one) << text.substr(0, frames) << "Frames: 7\n"
                       << text.substr(frameTime, end + 1 - frameTime);
    const CliRun r = bounded("sim --sensor pelvis --bvh " + one + " -o " + path("one.csv.gz"));
    EXPECT_EQ(r.exitCode, 2) << r.output;
    EXPECT_THAT(r.output, HasSubstr("its motion is a single frame (frame 6 of the file)"));
}

TEST(CalibrateOutput, TheFileIsCheckedBeforeTheSensorsAreMoved) {
    const std::string pipe = fifo("cal.fifo");
    const CliRun intoFifo = bounded("calibrate gyro --file " + pipe);
    EXPECT_EQ(intoFifo.exitCode, 2) << intoFifo.output;
    EXPECT_THAT(intoFifo.output, HasSubstr("is a FIFO"));
    EXPECT_THAT(intoFifo.output, ::testing::Not(HasSubstr("scripted")));
    const CliRun missing = bounded("calibrate gyro --file " + path("no-folder/cal.toml"));
    EXPECT_EQ(missing.exitCode, 2) << missing.output;
    EXPECT_THAT(missing.output, HasSubstr("does not exist"));
    const CliRun ok = bounded("calibrate gyro --file " + path("cal.toml"));
    ASSERT_EQ(ok.exitCode, 0) << ok.output;
    EXPECT_THAT(readAll(path("cal.toml")), HasSubstr("gyro_bias_rad_s"));
    EXPECT_FALSE(fs::exists(path("cal.toml.part")));
}

TEST(NumberOptions, ValuesThatRoundToNothingOrOverflowAreRefused) {
    const struct {
        const char* args;
        const char* says;
    } cases[] = {
        // 1e-10 s rounded to 0 ns: "until Ctrl-C".
        {"run --board sim-upper10 -d 1e-10 --no-record --no-preview", "must be 0 or from 0.001"},
        {"serve --board sim-upper10 -d 1e-10", "must be 0 or from 0.001"},
        // 1e300 overflowed the simulated clock: the workers spun, no sample taken.
        {"run --board sim-upper10 -d 1 --speed 1e300 --no-record --no-preview",
         "not in range 0.001 to"},
        // Every sample is held until the fit.
        {"calibrate gyro -d 1e6", "must be 0 or from 1 to 600"},
        // Too short to judge a rate by: every sensor was blamed.
        {"selftest --seconds 0.001", "give at least 0.2 s"},
        // "-1" was read as 2^64 - 1 and '' as 0.
        {"run --board sim-upper10 -d 1 --seed -1 --no-record --no-preview", "is not a seed"},
        {"calibrate gyro --seed ''", "is not a seed"},
        {"run --board '' -d 1 --no-record --no-preview", "an empty path names no file"},
        // An empty path fell back to the default clip, map or calibration (none).
        {"sim --sensor pelvis --bvh ''", "--bvh: an empty path names no file"},
        {"run --board sim-upper10 -d 1 --no-record --calibration ''",
         "--calibration: an empty path names no file"},
        {"boards validate ''", "FILE: an empty path names no file"},
        // Refused in the words of an export's --rate.
        {"replay x.cap --fps 1e308 --preview png:x", "--fps: Value 1e308 not in range"},
    };
    for (const auto& c : cases) {
        const CliRun r = bounded(c.args);
        EXPECT_EQ(r.exitCode, 2) << c.args << "\n" << r.output;
        EXPECT_THAT(r.output, HasSubstr(c.says)) << c.args;
    }
    const std::string trial = path("trial.csv");
    std::ofstream(trial) << "t,gyr_x,gyr_y,gyr_z,acc_x,acc_y,acc_z,mag_x,mag_y,mag_z\n"
                            "0,0,0,0,0,0,9.81,0,20,-40\n0.01,0,0,0,0,0,9.81,0,20,-40\n"
                            "0.02,0,0,0,0,0,9.81,0,20,-40\n";
    // 1e-9 Hz overflowed the decimation and ran at the file's full rate.
    const CliRun slow = bounded("fusion replay --in " + trial + " --rate-hz 1e-9");
    EXPECT_EQ(slow.exitCode, 2) << slow.output;
    EXPECT_THAT(slow.output, HasSubstr("fewer than two of the file's 3 samples"));
    EXPECT_EQ(bounded("fusion replay --in " + trial + " --rate-hz 50").exitCode, 0);
}

// The capture's own outputs: the status file replaced a FIFO, a device (/dev/null, as root)
// and the recording itself; --mag-state replaced a file that was never a state file; an empty
// --record wrote a recording into the current folder.
TEST(RunOutputs, NoOutputReplacesAnotherOrAFileThatIsNotItsOwn) {
    const std::string run = "run --board sim-upper10 -d 1 --no-preview --no-stream ";
    const std::string pipe = fifo("status.fifo");
    const CliRun intoFifo = bounded(run + "--no-record --status-file " + pipe);
    EXPECT_EQ(intoFifo.exitCode, 2) << intoFifo.output;
    EXPECT_THAT(intoFifo.output, HasSubstr("is a FIFO"));
    EXPECT_TRUE(isFifo(pipe));
    const std::string same = path("same.cap");
    const CliRun both = bounded(run + "--record " + same + " --status-file " + same);
    EXPECT_EQ(both.exitCode, 2) << both.output;
    EXPECT_THAT(both.output, HasSubstr("which the command also reads or writes"));
    EXPECT_FALSE(fs::exists(same));
    const std::string precious = path("precious.txt");
    std::ofstream(precious) << "precious\n";
    const CliRun stranger = bounded(run + "--no-record --mag-state " + precious);
    EXPECT_EQ(stranger.exitCode, 2) << stranger.output;
    EXPECT_THAT(stranger.output, HasSubstr("is not a magnetometer state file"));
    EXPECT_EQ(readAll(precious), "precious\n");
    fs::create_directories(path("a-folder"));
    const CliRun folder = bounded(run + "--record " + path("a-folder"));
    EXPECT_EQ(folder.exitCode, 2) << folder.output;
    EXPECT_THAT(folder.output, HasSubstr("is a directory"));  // was "File exists"
    const CliRun empty = bounded(run + "--record ''");
    EXPECT_EQ(empty.exitCode, 2) << empty.output;
    EXPECT_THAT(empty.output, HasSubstr("an empty path names no file"));
    // serve: a takes folder that is a file started, then failed every take.
    const CliRun takes = bounded("serve --board sim-upper10 -d 1 --no-preview --recordings " +
                                 precious + " --state-dir " + path("state"));
    EXPECT_EQ(takes.exitCode, 2) << takes.output;
    EXPECT_THAT(takes.output, HasSubstr("--recordings '" + precious + "' is not a folder"));
}

// A closed terminal (SIGHUP) killed the capture: no end event, samples lost, the status file
// left saying it ran. It now ends the capture as Ctrl-C does.
TEST(RunSignals, AHangUpEndsTheCaptureCleanly) {
    const std::string cap = path("hup.cap");
    const std::string status = path("hup.json");
    const CliRun r = shell("timeout -k 3 120 sh -c '" + std::string(CAPHUB_BINARY) +
                           " run --board sim-upper10 -d 60 --no-preview --no-stream --record " +
                           cap + " --status-file " + status +
                           " > /dev/null 2>&1 & p=$!; for i in $(seq 300); do [ -s " + status +
                           " ] && break; sleep 0.1; done; kill -HUP $p; wait $p; echo rc=$?'");
    EXPECT_THAT(r.output, HasSubstr("rc=0")) << r.output;
    const CliRun info = caphub("info " + cap);
    EXPECT_EQ(info.exitCode, 0) << info.output;
    EXPECT_THAT(info.output, HasSubstr("recording stopped"));
    EXPECT_THAT(readAll(status), HasSubstr("\"running\": false"));
}

// A web client that sends its request a byte at a time held serve for as long as it kept
// sending: SIGTERM took 38 s. The workers now get a grace period after the capture has stopped.
TEST(ServeSignals, ASlowClientDoesNotHoldTheStop) {
    const int port = 20000 + static_cast<int>(::getpid() % 20000);
    const std::string script =
        std::string(CAPHUB_BINARY) +
        " serve --board sim-upper10 --no-preview --listen 127.0.0.1:" + std::to_string(port) +
        " --state-dir " + path("slow-state") + " --recordings " + path("slow-takes") + " > " +
        path("slow.log") + " 2>&1 & p=$!; " +
        "for i in $(seq 300); do (exec 3<>/dev/tcp/127.0.0.1/" + std::to_string(port) +
        ") 2>/dev/null && break; sleep 0.1; done; " + "exec 3<>/dev/tcp/127.0.0.1/" +
        std::to_string(port) + "; (while printf G >&3; do sleep 0.5; done) 2>/dev/null & t=$!; " +
        "sleep 1; kill -TERM $p; s=$(date +%s%N); wait $p; rc=$?; e=$(date +%s%N); kill $t; " +
        "echo rc=$rc ms=$(( (e - s) / 1000000 ))";
    const CliRun r = shell("timeout -k 3 120 bash -c '" + script + "'");
    std::smatch m;
    ASSERT_TRUE(std::regex_search(r.output, m, std::regex("rc=([0-9]+) ms=([0-9]+)")))
        << r.output << readAll(path("slow.log"));
    EXPECT_EQ(m[1], "0") << readAll(path("slow.log"));
    EXPECT_LT(std::stoi(m[2]), 10000) << readAll(path("slow.log"));
}

// serve said "no password (this machine only)" while an extra MJPEG preview on 0.0.0.0 showed
// the capture to the network.
TEST(ServePreview, AnMjpegPreviewStaysOnThisMachine) {
    const CliRun wide = bounded(
        "serve --board sim-upper10 -d 1 --listen 127.0.0.1:0 --preview http:0.0.0.0:0 "
        "--state-dir " +
        path("preview-state") + " --recordings " + path("preview-takes"));
    EXPECT_EQ(wide.exitCode, 2) << wide.output;
    EXPECT_THAT(wide.output, HasSubstr("an MJPEG preview has no password"));
}

// A POST with neither a length nor chunks waited 5 s for a body, then answered 400 with nothing
// said; it is answered at once with what is missing.
TEST(ServeRequests, APostWithoutALengthIsAnsweredAtOnce) {
    const int port = 20000 + static_cast<int>((::getpid() + 7) % 20000);
    const std::string p = std::to_string(port);
    const std::string script =
        std::string(CAPHUB_BINARY) +
        " serve --board sim-upper10 --no-preview --listen 127.0.0.1:" + p + " --state-dir " +
        path("post-state") + " --recordings " + path("post-takes") +
        " > /dev/null 2>&1 & s=$!; for i in $(seq 300); do (exec 3<>/dev/tcp/127.0.0.1/" + p +
        ") 2>/dev/null && break; sleep 0.1; done; exec 3<>/dev/tcp/127.0.0.1/" + p +
        "; printf \"POST /api/take/stop HTTP/1.1\\r\\nHost: 127.0.0.1\\r\\n\\r\\n\" >&3; " +
        "timeout 3 head -c 12 <&3; echo; kill -TERM $s; wait $s";
    const CliRun r = shell("timeout -k 3 120 bash -c '" + script + "'");
    EXPECT_THAT(r.output, HasSubstr("HTTP/1.1 411")) << r.output;
}

// A status file dated in the future (a clock set back, a file touched) read as a live hub's.
TEST(StatusInputs, AStatusDatedInTheFutureIsNotALiveHub) {
    const std::string status = path("future.json");
    const CliRun run = bounded(
        "run --board sim-upper10 -d 1 --no-record --no-preview "
        "--no-stream --status-file " +
        status);
    ASSERT_EQ(run.exitCode, 0) << run.output;
    std::string text = readAll(status);
    const std::string stopped = "\"running\": false";
    ASSERT_NE(text.find(stopped), std::string::npos) << text;
    text.replace(text.find(stopped), stopped.size(), "\"running\": true");
    std::ofstream(status, std::ios::trunc) << text;
    EXPECT_EQ(caphub("status --file " + status).exitCode, 0);  // written now: live
    ASSERT_EQ(shell("touch -d '+1 hour' " + status).exitCode, 0);
    const CliRun future = caphub("status --file " + status);
    EXPECT_EQ(future.exitCode, 1) << future.output;
    EXPECT_THAT(future.output, HasSubstr("in the future"));
}

// A trial whose rows are all at rest (or whose markers were never seen) scored 0.000 deg: a
// perfect filter, over no row at all.
TEST(FusionScores, ATrialWithNothingToScoreIsSaidNotScoredAsPerfect) {
    std::string text =
        "t,gyr_x,gyr_y,gyr_z,acc_x,acc_y,acc_z,mag_x,mag_y,mag_z,opt_w,opt_x,opt_y,opt_z,"
        "movement\n";
    for (int i = 0; i < 50; ++i) {
        text += std::to_string(i * 0.01) + ",0,0,0,0,0,9.81,0,20,-40,1,0,0,0,0\n";
    }
    const std::string still = path("still.csv");
    std::ofstream(still) << text;
    const CliRun replay = bounded("fusion replay --in " + still);
    EXPECT_EQ(replay.exitCode, 0) << replay.output;
    EXPECT_THAT(replay.output, HasSubstr("has no row in movement"));
    EXPECT_THAT(replay.output, ::testing::Not(HasSubstr("0.000")));
    const CliRun cv = bounded("fusion cv --in " + still + " --in " + still + " --in " + still);
    EXPECT_EQ(cv.exitCode, 2) << cv.output;
    EXPECT_THAT(cv.output, HasSubstr("nothing to score"));
}

}  // namespace
