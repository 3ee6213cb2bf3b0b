// The faults of issue 25 in export and file inputs, as a person meets them at a shell: what
// `export -o` may write over, directories given where a file is expected, status files that are
// not status documents, one exit-code rule for every command, and board files too large for a
// recording's metadata.
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <unistd.h>

#include "tests/firmware/cli_run.h"
#include "tests/firmware/export_fixture.h"

namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using ::testing::Not;

using caphub::testing::caphub;
using caphub::testing::CliRun;
using caphub::testing::shell;

const std::string& dir() {
    static const std::string d = [] {
        const std::string p =
            caphub::testing::freshFolder(::testing::TempDir(), "caphub_file_faults_");
        fs::create_directories(p + "/a-directory");
        return p;
    }();
    return d;
}

std::string path(const std::string& name) {
    return dir() + "/" + name;
}

const std::string& walk() {
    static const std::string p = [] {
        const std::string f = path("walk.cap");
        caphub::firmware::testing::writeWalkRecording(f);
        return f;
    }();
    return p;
}

std::string readAll(const std::string& file) {
    std::ifstream in(file, std::ios::binary);
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
}

std::string writeFile(const std::string& name, const std::string& text) {
    const std::string p = path(name);
    std::ofstream(p, std::ios::binary | std::ios::trunc) << text;
    return p;
}

bool isCharDevice(const std::string& p) {
    struct stat st {};
    return ::lstat(p.c_str(), &st) == 0 && S_ISCHR(st.st_mode);
}

bool isFifo(const std::string& p) {
    struct stat st {};
    return ::lstat(p.c_str(), &st) == 0 && S_ISFIFO(st.st_mode);
}

// ---- export -o: regular files only ----

// A device node: one of the test's own (the "full" device, made with mknod as root, as CI runs
// the tests), so that a regression replaces nothing of the machine's; without root, /dev/full,
// which a user cannot replace anyway. Run as root, /dev/full used to be replaced by a regular
// file holding the CSV.
std::string deviceNode() {
    const std::string node = path("full-device");
    if (::mknod(node.c_str(), S_IFCHR | 0666, makedev(1, 7)) == 0) {
        return node;
    }
    return "/dev/full";
}

TEST(ExportOutput, ADeviceIsRefusedAndLeftAsItWas) {
    const std::string device = deviceNode();
    ASSERT_TRUE(isCharDevice(device));
    const CliRun r = caphub("export " + walk() + " --format csv -o " + device);
    EXPECT_EQ(r.exitCode, 2) << r.output;
    EXPECT_THAT(r.output, HasSubstr("'" + device + "' is a device"));
    EXPECT_TRUE(isCharDevice(device));
    EXPECT_FALSE(fs::exists(device + ".part"));
}

TEST(ExportOutput, AFifoIsRefusedAndLeftAsItWas) {
    const std::string fifo = path("out.fifo");
    ASSERT_EQ(::mkfifo(fifo.c_str(), 0644), 0);
    const CliRun r = caphub("export " + walk() + " --format csv -o " + fifo);
    EXPECT_EQ(r.exitCode, 2) << r.output;
    EXPECT_THAT(r.output, HasSubstr("'" + fifo + "' is a FIFO"));
    EXPECT_TRUE(isFifo(fifo));
    EXPECT_FALSE(fs::exists(fifo + ".part"));
}

TEST(ExportOutput, ASymlinkIsWrittenThroughIntoTheRegularFileItNames) {
    const std::string target = writeFile("target.csv", "old contents\n");
    const std::string link = path("link.csv");
    fs::create_symlink(target, link);
    const CliRun r = caphub("export " + walk() + " --format csv -o " + link);
    EXPECT_EQ(r.exitCode, 0) << r.output;
    EXPECT_TRUE(fs::is_symlink(link));  // still the link, now naming the export
    EXPECT_EQ(fs::read_symlink(link), target);
    EXPECT_THAT(readAll(target), ::testing::StartsWith("t,pelvis_qw,"));
    EXPECT_FALSE(fs::exists(link + ".part"));
    EXPECT_FALSE(fs::exists(target + ".part"));
}

TEST(ExportOutput, ASymlinkToADeviceOrToNothingIsRefused) {
    const std::string device = deviceNode();
    const std::string toDevice = path("to-device.csv");
    fs::create_symlink(device, toDevice);
    const CliRun toIt = caphub("export " + walk() + " --format csv -o " + toDevice);
    EXPECT_EQ(toIt.exitCode, 2) << toIt.output;
    EXPECT_THAT(toIt.output, HasSubstr("'" + device + "' is a device"));
    EXPECT_TRUE(fs::is_symlink(toDevice));
    EXPECT_TRUE(isCharDevice(device));

    const std::string dangling = path("dangling.csv");
    fs::create_symlink(path("nowhere/x.csv"), dangling);
    const CliRun none = caphub("export " + walk() + " --format csv -o " + dangling);
    EXPECT_EQ(none.exitCode, 2) << none.output;
    EXPECT_THAT(none.output, HasSubstr("names '" + path("nowhere/x.csv") + "'"));
    EXPECT_TRUE(fs::is_symlink(dangling));
}

// It used to read "rename to 'outdir': Success": the error code was overwritten before the
// message was built.
TEST(ExportOutput, ADirectoryIsSaidToBeOne) {
    const CliRun r = caphub("export " + walk() + " --format bvh -o " + path("a-directory"));
    EXPECT_EQ(r.exitCode, 2) << r.output;
    EXPECT_THAT(r.output, HasSubstr("'" + path("a-directory") + "' is a directory"));
    EXPECT_THAT(r.output, Not(HasSubstr("Success")));
    EXPECT_TRUE(fs::is_directory(path("a-directory")));
    EXPECT_FALSE(fs::exists(path("a-directory.part")));
}

TEST(ExportOutput, ARegularFileIsReplaced) {
    const std::string out = writeFile("replace.csv", "old contents\n");
    const CliRun r = caphub("export " + walk() + " --format csv -o " + out);
    EXPECT_EQ(r.exitCode, 0) << r.output;
    EXPECT_THAT(readAll(out), ::testing::StartsWith("t,pelvis_qw,"));
}

// A write that fails half-way (a file size limit stands in for a full disk) is a failure of the
// work, exit 1, and the file that was there is left as it was.
TEST(ExportOutput, AFailedWriteIsARuntimeErrorThatLeavesTheOldFile) {
    const std::string out = writeFile("full.csv", "old contents\n");
    const CliRun r = shell("trap '' XFSZ; ulimit -f 16; exec " + std::string(CAPHUB_BINARY) +
                           " export " + walk() + " --format csv -o " + out);
    EXPECT_EQ(r.exitCode, 1) << r.output;
    EXPECT_THAT(r.output, HasSubstr("File too large"));
    EXPECT_EQ(readAll(out), "old contents\n");
    EXPECT_FALSE(fs::exists(out + ".part"));
}

// ---- directories where a file is expected ----

TEST(FileInputs, ADirectoryGivenForAFileIsSaidToBeOne) {
    const std::string d = path("a-directory");
    const std::string expected = "'" + d + "' is a directory";
    const std::vector<std::string> commands = {
        "boards validate " + d,
        "info " + d,
        "export " + d + " --format csv -o " + path("x.csv"),
        "export " + walk() + " --format csv --names " + d + " -o " + path("x.csv"),
        "replay " + d + " --preview png:" + path("frames"),
        "status --file " + d,
        "run --board " + d + " --duration 1 --no-record --no-preview",
        "run --board sim-upper10 --map " + d + " --duration 1 --no-record --no-preview",
        "run --board sim-upper10 --bvh " + d + " --duration 1 --no-record --no-preview",
        "run --board sim-upper10 --calibration " + d + " --duration 1 --no-record --no-preview",
        "run --board sim-upper10 --mag-state " + d + " --duration 1 --no-record --no-preview",
        "sim --board sim-upper10 --all --bvh " + d + " --out " + path("sim-out"),
        "sim --board sim-upper10 --all --map " + d + " --out " + path("sim-out"),
        "fusion replay --in " + d,
        "evaluate --board sim-upper10 --bvh " + d,
        "selftest --board " + d,
        "calibrate gyro --board sim-upper10 --file " + d,
    };
    for (const auto& c : commands) {
        const CliRun r = caphub(c);
        EXPECT_EQ(r.exitCode, 2) << "caphub " << c << "\n" << r.output;
        EXPECT_THAT(r.output, HasSubstr(expected)) << "caphub " << c;
    }
}

// ---- status --file ----

TEST(StatusFile, AFileThatIsNotAStatusDocumentIsRefused) {
    const std::string binary = writeFile("binary.json", std::string("\x89PNG\r\n\x1a\n\0\0", 10));
    const std::string text = writeFile("text.json", "hello, world\n");
    const std::string otherJson = writeFile("other.json", "{\"name\": \"not a status\"}\n");
    for (const auto& f : {binary, text, otherJson}) {
        const CliRun r = caphub("status --file " + f);
        EXPECT_EQ(r.exitCode, 2) << f << "\n" << r.output;
        EXPECT_THAT(r.output, HasSubstr("'" + f + "' is not a caphub status document")) << f;
        EXPECT_THAT(r.output, Not(HasSubstr("hello, world")));
        EXPECT_THAT(r.output, Not(HasSubstr("not a status\"")));
    }
}

// ---- one exit-code rule ----

// 2: what the command was given cannot be used (options, and every named file: missing, a
// directory or a device, malformed, or without what the command needs).
TEST(ExitCodes, EveryInputThatCannotBeUsedExitsTwo) {
    const std::string notRecording = writeFile("not-a-recording.cap", "this is not a recording");
    caphub::firmware::testing::WalkRecordingOptions o;
    o.seconds = 0.1;
    o.withPoses = false;
    const std::string noPoses = path("no-poses.cap");
    caphub::firmware::testing::writeWalkRecording(noPoses, o);
    const std::vector<std::string> commands = {
        "export " + walk() + " --format csv --names " + path("absent.toml") + " -o " +
            path("y.csv"),
        "export " + path("absent.cap") + " --format csv -o " + path("y.csv"),
        "export " + notRecording + " --format csv -o " + path("y.csv"),
        "export " + noPoses + " --format csv -o " + path("y.csv"),
        "export " + walk() + " --format csv -o " + path("no-such-folder/y.csv"),
        "info " + path("absent.cap"),
        "info " + notRecording,
        "info ''",  // an unset variable: not the build's information
        "export " + walk() + " --format csv -o ''",
        "reprocess " + walk() + " -o ''",
        "replay " + notRecording + " --preview png:" + path("frames"),
        "replay " + path("absent.cap") + " --preview png:" + path("frames"),
        "status --file " + path("absent.json"),
        "boards validate " + path("absent.toml"),
        "run --board sim-upper10 --map " + path("absent.toml") +
            " --duration 1 --no-record --no-preview",
        "run --board sim-upper10 --calibration " + path("absent.toml") +
            " --duration 1 --no-record --no-preview",
        "fusion replay --in " + path("absent.csv"),
        "evaluate --board sim-upper10 --bvh " + path("absent.bvh"),
    };
    for (const auto& c : commands) {
        const CliRun r = caphub(c);
        EXPECT_EQ(r.exitCode, 2) << "caphub " << c << "\n" << r.output;
    }
}

// `run --record missing/dir/take.cap` made the folders and recorded there: a mistyped folder
// was made, and the take looked for where it was meant to go. The folder must be there, as for
// every other command's output file.
TEST(FileInputs, ARecordingIntoAFolderThatIsNotThereIsRefused) {
    const std::string missing = path("no-such-folder");
    fs::remove_all(missing);
    const CliRun r = caphub("run --board sim-upper10 --record " + missing +
                            "/take.cap --duration 1 --no-preview");
    EXPECT_EQ(r.exitCode, 2) << r.output;
    EXPECT_NE(r.output.find("--record " + missing + "/take.cap: the folder '" + missing +
                            "' does not exist"),
              std::string::npos)
        << r.output;
    EXPECT_FALSE(fs::exists(missing));
    const std::string file = writeFile("a-file", "x");
    const CliRun f =
        caphub("run --board sim-upper10 --record " + file + "/take.cap --duration 1 --no-preview");
    EXPECT_EQ(f.exitCode, 2) << f.output;
    EXPECT_NE(f.output.find("Not a directory"), std::string::npos) << f.output;
}

// 1: the work started and failed (covered with the output above and by the full-disk capture
// in cli_test.cpp); and status's answer when no hub has run where it looks by default.
TEST(ExitCodes, StatusWithNoHubAtTheDefaultPlaceExitsOne) {
    const CliRun r = shell("CAPHUB_STATUS=" + path("no-hub-here.json") + " " +
                           std::string(CAPHUB_BINARY) + " status");
    EXPECT_EQ(r.exitCode, 1) << r.output;
    EXPECT_THAT(r.output, HasSubstr("no hub has run here"));
}

// ---- board files a recording cannot hold ----

std::string shippedBoardText() {
    return readAll(std::string(CAPHUB_SOURCE_DIR) + "/board/sim-upper10.toml");
}

// Larger than any recording's metadata: refused before it is parsed, the limit and the reason
// said.
TEST(BoardSize, ABoardFileLargerThanARecordingCanHoldIsInvalid) {
    std::string text = shippedBoardText();
    text += "# " + std::string(2u << 20, 'x') + "\n";
    const std::string big = writeFile("big-board.toml", text);
    for (const std::string& c :
         {"boards validate " + big,
          "run --board " + big + " --duration 1 --no-preview --record " + path("big.cap")}) {
        const CliRun r = caphub(c);
        EXPECT_EQ(r.exitCode, 2) << c << "\n" << r.output;
        EXPECT_THAT(r.output, HasSubstr("1048576 bytes")) << c;
        EXPECT_THAT(r.output, HasSubstr("a recording embeds the board file")) << c;
    }
    EXPECT_FALSE(fs::exists(path("big.cap")));
}

// Under the size limit, but its escaped copy (a newline becomes "\n") does not fit in the
// metadata: said at validate and at run start, with the size it would take.
TEST(BoardSize, ABoardFileWhoseEmbeddedCopyDoesNotFitIsInvalid) {
    std::string text = shippedBoardText();
    for (int i = 0; i < 400'000; ++i) {
        text += "#\n";
    }
    ASSERT_LT(text.size(), 1u << 20);
    const std::string big = writeFile("escaped-board.toml", text);
    for (const std::string& c :
         {"boards validate " + big,
          "run --board " + big + " --duration 1 --no-preview --record " + path("escaped.cap")}) {
        const CliRun r = caphub(c);
        EXPECT_EQ(r.exitCode, 2) << c << "\n" << r.output;
        EXPECT_THAT(r.output, HasSubstr("1048576 bytes")) << c;
        EXPECT_THAT(r.output, HasSubstr("a recording embeds the board file")) << c;
        EXPECT_THAT(r.output, Not(HasSubstr("valid:"))) << c;
    }
    EXPECT_FALSE(fs::exists(path("escaped.cap")));
}

// ---- found by trying the program as an attacker would (2026-11-27) ----

// "nan" and "inf" pass CLI11's own number checks (every comparison with them is false): an
// import or a reprocess with --pose-rate nan looped for ever. Each is refused at once.
TEST(NumberOptions, NotAFiniteNumberIsRefusedInsteadOfLoopedOn) {
    const std::vector<std::string> commands = {
        "reprocess " + walk() + " --pose-rate nan -o " + path("nan.cap"),
        "export " + walk() + " --format csv --rate inf -o " + path("inf.csv"),
        "replay " + walk() + " --speed 0 --fps nan --preview png:" + path("frames-nan"),
        "replay " + walk() + " --speed nan --preview png:" + path("frames-nan"),
        "evaluate --board sim-upper10 --bvh " + path("absent.bvh") + " --pose-rate nan",
        "run --board sim-upper10 --duration nan --no-record --no-preview",
    };
    for (const auto& c : commands) {
        const CliRun r = shell("timeout 60 " + std::string(CAPHUB_BINARY) + " " + c);
        EXPECT_EQ(r.exitCode, 2) << "caphub " << c << "\n" << r.output;
        EXPECT_THAT(r.output, HasSubstr("is not a finite number")) << "caphub " << c;
    }
    EXPECT_FALSE(fs::exists(path("nan.cap")));
    EXPECT_FALSE(fs::exists(path("nan.cap.part")));
    // A pose rate whose period rounds to nothing spun the capture's pipeline thread, deaf to
    // Ctrl-C: run and serve take 1-1000 poses a second, as evaluate and reprocess do.
    const CliRun fast = shell("timeout -k 3 30 " + std::string(CAPHUB_BINARY) +
                              " run --board sim-upper10 --duration 0.5 --pose-rate 3e9 "
                              "--no-record --no-preview");
    EXPECT_EQ(fast.exitCode, 2) << fast.output;
    EXPECT_THAT(fast.output, HasSubstr("--pose-rate: Value 3e9 not in range 1 to 1000"));
}

// fusion replay --out: written as an export is. It aborted on a full disk (an exception from
// the formatting library), left a truncated file when interrupted, and wrote over its own --in.
TEST(FusionReplayOutput, NeverItsInputNorADeviceAndWrittenWhole) {
    const std::string in = writeFile(
        "trial.csv",
        "t,gyr_x,gyr_y,gyr_z,acc_x,acc_y,acc_z,mag_x,mag_y,mag_z\n"
        "0,0,0,0,0,0,9.81,0,20,-40\n0.01,0,0,0,0,0,9.81,0,20,-40\n0.02,0,0,0,0,0,9.81,0,20,-40\n");
    const std::string before = readAll(in);
    const CliRun self = caphub("fusion replay --in " + in + " --out " + in);
    EXPECT_EQ(self.exitCode, 2) << self.output;
    EXPECT_THAT(self.output, HasSubstr("which the command also reads or writes"));
    EXPECT_EQ(readAll(in), before);
    const std::string device = deviceNode();
    const CliRun full = caphub("fusion replay --in " + in + " --out " + device);
    EXPECT_EQ(full.exitCode, 2) << full.output;
    EXPECT_THAT(full.output, HasSubstr("is a device"));
    EXPECT_TRUE(isCharDevice(device));
    const std::string out = path("estimate.csv");
    const CliRun ok = caphub("fusion replay --in " + in + " --out " + out);
    EXPECT_EQ(ok.exitCode, 0) << ok.output;
    EXPECT_THAT(readAll(out), ::testing::StartsWith("t,qw,qx,qy,qz\n0.000000,"));
    EXPECT_FALSE(fs::exists(out + ".part"));
}

// A pose record dated days after the others (a damaged file's, its checksum intact): the export
// would have made millions of frames until memory ran out, or, with a time near the end of the
// clock, none, and replaced OUT with an empty file before crashing.
TEST(ExportOutput, APoseFarAfterTheOthersIsRefusedAndTheOldFileKept) {
    caphub::firmware::testing::WalkRecordingOptions o;
    o.seconds = 0.5;
    o.extraPoseAtS = 1e6;
    const std::string far = path("far-pose.cap");
    caphub::firmware::testing::writeWalkRecording(far, o);
    const std::string old = writeFile("kept.csv", "old contents\n");
    const CliRun r = caphub("export " + far + " --format csv -o " + old);
    EXPECT_EQ(r.exitCode, 2) << r.output;
    EXPECT_THAT(r.output, HasSubstr("frames (1000000.000 s at 100 Hz): more than the 4000000 one "
                                    "export holds"));
    EXPECT_EQ(readAll(old), "old contents\n");
    EXPECT_FALSE(fs::exists(old + ".part"));
    // Within the bound, a window of it exports.
    const CliRun part = caphub("export " + far + " --format csv --to 0.4 -o " + old);
    EXPECT_EQ(part.exitCode, 0) << part.output;
}

// A pose record whose joint rotations are all zero (its checksum intact) was exported as the
// identity and not counted; a NaN one was. Both are malformed, skipped and said.
TEST(ExportInputs, APoseOfZeroQuaternionsIsMalformed) {
    caphub::firmware::testing::WalkRecordingOptions o;
    o.seconds = 0.5;
    o.extraPoseAtS = 0.6;
    o.extraPoseZero = true;
    const std::string rec = path("zero-pose.cap");
    caphub::firmware::testing::writeWalkRecording(rec, o);
    const CliRun r = caphub("export " + rec + " --format csv -o " + path("zero-pose.csv"));
    EXPECT_EQ(r.exitCode, 0) << r.output;
    EXPECT_THAT(r.output, HasSubstr("1 malformed and 0 out-of-order pose record(s)"));
}

// Records written twice or out of order (their checksums intact): export and reprocess skip and
// count them, and info said "damage: none".
TEST(InfoInputs, RecordsOutOfTimeOrderAreDamage) {
    caphub::firmware::testing::WalkRecordingOptions o;
    o.seconds = 0.5;
    const std::string good = path("in-order.cap");
    caphub::firmware::testing::writeWalkRecording(good, o);
    EXPECT_THAT(caphub("info " + good).output, HasSubstr("damage: none"));
    o.extraPoseAtS = 0.1;  // after the last pose in the file, dated before it
    const std::string rec = path("out-of-order.cap");
    caphub::firmware::testing::writeWalkRecording(rec, o);
    const CliRun r = caphub("info " + rec);
    EXPECT_EQ(r.exitCode, 0) << r.output;
    EXPECT_THAT(r.output, Not(HasSubstr("damage: none")));
    EXPECT_THAT(r.output, HasSubstr("0 raw sample(s) and 1 pose(s) not after the one before them"));
}

// A FIFO that nobody writes to, given as a recording or a stream: it used to hang every command
// in its open; it now reads as empty.
TEST(FileInputs, AFifoWithoutAWriterIsNotWaitedOn) {
    const std::string fifo = path("in.fifo");
    fs::remove(fifo);
    ASSERT_EQ(::mkfifo(fifo.c_str(), 0644), 0);
    const std::vector<std::string> commands = {
        "info " + fifo,
        "export " + fifo + " --format csv -o " + path("from-fifo.csv"),
        "reprocess " + fifo + " -o " + path("from-fifo.cap"),
        "replay " + fifo + " --speed 0 --preview png:" + path("frames-fifo"),
        "fusion replay --in " + fifo,
    };
    for (const auto& c : commands) {
        const CliRun r = shell("timeout 20 " + std::string(CAPHUB_BINARY) + " " + c);
        EXPECT_EQ(r.exitCode, 2) << "caphub " << c << "\n" << r.output;
    }
    // A text input read whole says it was a FIFO nobody wrote into (a status file was "not
    // JSON: unexpected end of input").
    const CliRun status =
        shell("timeout 20 " + std::string(CAPHUB_BINARY) + " status --file " + fifo);
    EXPECT_EQ(status.exitCode, 2) << status.output;
    EXPECT_THAT(status.output, HasSubstr("is a FIFO (named pipe) with nothing written into it"));
}

// replay --preview png:DIR wrote each frame through a symbolic link of that name (wherever it
// pointed) and hung on a FIFO of that name. Neither is written now.
TEST(ReplayOutput, AFrameNamedByASymlinkOrAFifoIsNotWritten) {
    const std::string frames = path("frames-links");
    fs::create_directories(frames);
    const std::string victim = writeFile("victim.txt", "keep me\n");
    fs::remove(frames + "/frame_000002.png");
    fs::create_symlink(victim, frames + "/frame_000002.png");
    const CliRun viaLink = shell("timeout 60 " + std::string(CAPHUB_BINARY) + " replay " + walk() +
                                 " --speed 0 --preview png:" + frames);
    EXPECT_THAT(viaLink.output, HasSubstr("a symbolic link: not followed")) << viaLink.output;
    EXPECT_EQ(readAll(victim), "keep me\n");

    const std::string withFifo = path("frames-fifo-inside");
    fs::create_directories(withFifo);
    fs::remove(withFifo + "/frame_000000.png");
    ASSERT_EQ(::mkfifo((withFifo + "/frame_000000.png").c_str(), 0644), 0);
    const CliRun viaFifo = shell("timeout 60 " + std::string(CAPHUB_BINARY) + " replay " + walk() +
                                 " --speed 0 --preview png:" + withFifo);
    EXPECT_NE(viaFifo.exitCode, 124) << "timed out: " << viaFifo.output;
    EXPECT_THAT(viaFifo.output, HasSubstr("a FIFO: not written")) << viaFifo.output;
    EXPECT_TRUE(isFifo(withFifo + "/frame_000000.png"));
}

}  // namespace
