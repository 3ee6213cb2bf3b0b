// caphub reprocess: a recording made by `caphub run` on the virtual suit goes through fusion and
// body again into a new recording that `caphub info` and `caphub export` read; the output is the
// same byte for byte from the same input; the body calibration chosen after the fact changes
// the poses; bad options and inputs are refused with exit code 2 and a message.
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include "firmware/recording/reader.h"
#include "firmware/recording/writer.h"
#include "tests/firmware/cli_run.h"
#include "tests/firmware/sim_speed.h"

namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

using caphub::testing::caphub;
using caphub::testing::CliRun;
using caphub::testing::speedOption;

std::string temp(const std::string& name) {
    const std::string d = ::testing::TempDir() + "caphub_reprocess_" + std::to_string(getpid());
    fs::create_directories(d);
    return d + "/" + name;
}

std::string readAll(const std::string& p) {
    std::ifstream in(p, std::ios::binary);
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
}

struct Contents {
    std::uint64_t samples = 0;
    std::uint64_t orientations = 0;
    std::vector<Eigen::Quaternionf> poseJoints;  // every pose's joints, in order
    std::vector<Eigen::Vector3f> roots;
    std::uint64_t calibrated = 0;
    std::uint64_t poses = 0;
    std::string metadata;
};

Contents contentsOf(const std::string& path) {
    using namespace caphub::firmware;
    Contents c;
    auto reader = RecordingReader::open(path);
    EXPECT_TRUE(reader.ok()) << path;
    if (!reader) {
        return c;
    }
    c.metadata = (*reader)->metadata();
    RecordView v;
    std::vector<Eigen::Quaternionf> joints;
    while ((*reader)->next(v) == 1) {
        switch (v.type) {
            case cap::RecordType::RawSample:
                ++c.samples;
                break;
            case cap::RecordType::Orientation:
                ++c.orientations;
                break;
            case cap::RecordType::Pose: {
                Eigen::Vector3f root;
                EXPECT_TRUE(decodePose(v, root, joints));
                c.poseJoints.insert(c.poseJoints.end(), joints.begin(), joints.end());
                c.roots.push_back(root);
                ++c.poses;
                break;
            }
            case cap::RecordType::Event: {
                cap::EventKind k{};
                int sensor = 0;
                int error = 0;
                std::string text;
                EXPECT_TRUE(decodeEvent(v, k, sensor, error, text));
                c.calibrated += k == cap::EventKind::Calibrated ? 1 : 0;
                break;
            }
            default:
                break;
        }
    }
    return c;
}

// One recording of the virtual suit (T-pose lead-in, then its walk), made once for the suite.
// Each test checks that it was made: a fatal failure in SetUpTestSuite itself would only mark the
// tests skipped, and a broken recording must fail them.
class Reprocess : public ::testing::Test {
protected:
    static void SetUpTestSuite() {
        source_ = temp("source.cap");
        fs::remove(source_);
        sourceRun_ = caphub("run --board sim-suit --duration 7 " + speedOption(4) +
                            " --calibrate tpose "
                            "--no-preview --no-stream --record " +
                            source_);
    }
    void SetUp() override { ASSERT_EQ(sourceRun_.exitCode, 0) << sourceRun_.output; }
    static std::string source_;
    static CliRun sourceRun_;
};
std::string Reprocess::source_;
CliRun Reprocess::sourceRun_;

TEST_F(Reprocess, ARecordingOfTheVirtualSuitReprocessesAndInfoAndExportReadTheResult) {
    const std::string out = temp("out.cap");
    fs::remove(out);
    const CliRun r = caphub("reprocess " + source_ + " -o " + out);
    ASSERT_EQ(r.exitCode, 0) << r.output;
    EXPECT_THAT(r.output, HasSubstr("body calibration: the recording's: T-pose held from 2.500 s"));
    EXPECT_FALSE(fs::exists(out + ".part"));
    const Contents in = contentsOf(source_);
    const Contents got = contentsOf(out);
    EXPECT_EQ(got.samples, in.samples);       // every raw sample carried over
    EXPECT_EQ(got.orientations, in.samples);  // one orientation per sample, computed anew
    EXPECT_EQ(got.calibrated, 1u);            // the T-pose calibration redone
    EXPECT_NEAR(static_cast<double>(got.poses), static_cast<double>(in.poses), 2.0);
    EXPECT_THAT(got.metadata, HasSubstr("[reprocess]"));
    // The same stages on the same samples: the poses are those of the capture (the capture
    // orders the buses' samples as they were read, which the file keeps).
    ASSERT_EQ(got.poseJoints.size(), in.poseJoints.size());
    double worst = 0;
    for (std::size_t i = 0; i < got.poseJoints.size(); ++i) {
        worst = std::max(worst,
                         static_cast<double>(got.poseJoints[i].angularDistance(in.poseJoints[i])));
    }
    EXPECT_LT(worst, 1e-3);

    const CliRun info = caphub("info " + out);
    EXPECT_EQ(info.exitCode, 0) << info.output;
    const std::string csv = temp("out.csv");
    const CliRun ex = caphub("export " + out + " --format csv -o " + csv);
    EXPECT_EQ(ex.exitCode, 0) << ex.output;
    EXPECT_GT(fs::file_size(csv), 1000u);
}

TEST_F(Reprocess, TheSameInputGivesTheSameFileByteForByte) {
    for (const std::string opts : {"", " --smooth"}) {
        const std::string a = temp("a.cap");
        const std::string b = temp("b.cap");
        fs::remove(a);
        fs::remove(b);
        ASSERT_EQ(caphub("reprocess " + source_ + " -o " + a + opts).exitCode, 0);
        ASSERT_EQ(caphub("reprocess " + source_ + " -o " + b + opts).exitCode, 0);
        const std::string x = readAll(a);
        EXPECT_GT(x.size(), 10000u);
        EXPECT_TRUE(x == readAll(b)) << "options '" << opts << "'";
    }
}

TEST_F(Reprocess, ACalibrationChosenAtAnotherTimeChangesThePoses) {
    const std::string early = temp("early.cap");
    const std::string asRecorded = temp("as-recorded.cap");
    fs::remove(early);
    fs::remove(asRecorded);
    ASSERT_EQ(caphub("reprocess " + source_ + " -o " + asRecorded).exitCode, 0);
    // 0.2 s in: the filters have not settled yet, the mountings come out otherwise.
    const CliRun r =
        caphub("reprocess " + source_ + " -o " + early + " --calibrate tpose --at 0.2");
    ASSERT_EQ(r.exitCode, 0) << r.output;
    EXPECT_THAT(r.output, HasSubstr("T-pose held from 0.200 s"));
    const Contents a = contentsOf(asRecorded);
    const Contents b = contentsOf(early);
    EXPECT_EQ(b.calibrated, 1u);
    // Calibrated 2.3 s earlier: poses from then on.
    EXPECT_GT(b.poses, a.poses + 60);
    // The last poses (same grid times) differ.
    ASSERT_GT(a.poseJoints.size(), 170u);
    double differ = 0;
    for (std::size_t k = 1; k <= 170; ++k) {
        differ = std::max(differ,
                          static_cast<double>(a.poseJoints[a.poseJoints.size() - k].angularDistance(
                              b.poseJoints[b.poseJoints.size() - k])));
    }
    EXPECT_GT(differ, 0.005);  // rad

    const std::string none = temp("none.cap");
    fs::remove(none);
    ASSERT_EQ(caphub("reprocess " + source_ + " -o " + none + " --calibrate none").exitCode, 0);
    EXPECT_EQ(contentsOf(none).calibrated, 0u);
}

TEST_F(Reprocess, AnotherPoseRateGivesThatManyPoses) {
    const std::string out = temp("rate.cap");
    fs::remove(out);
    const std::string same = temp("rate60.cap");
    fs::remove(same);
    const CliRun r = caphub("reprocess " + source_ + " -o " + out + " --pose-rate 30");
    ASSERT_EQ(r.exitCode, 0) << r.output;
    // Against a reprocess at the recording's 60 Hz, not its live poses: how many of those the
    // live capture solved depends on the machine's load when the recording was made.
    const CliRun r60 = caphub("reprocess " + source_ + " -o " + same);
    ASSERT_EQ(r60.exitCode, 0) << r60.output;
    const Contents a = contentsOf(same);
    const Contents b = contentsOf(out);
    ASSERT_GT(a.poses, 60u);
    EXPECT_NEAR(static_cast<double>(b.poses), static_cast<double>(a.poses) / 2, 1.0);
}

TEST_F(Reprocess, TheSmoothedRecordingHasEveryRecordAndInfoReadsIt) {
    const std::string out = temp("smooth.cap");
    fs::remove(out);
    const CliRun r = caphub("reprocess " + source_ + " -o " + out + " --smooth");
    ASSERT_EQ(r.exitCode, 0) << r.output;
    EXPECT_THAT(r.output, HasSubstr("smoothed"));
    const Contents in = contentsOf(source_);
    const Contents got = contentsOf(out);
    EXPECT_EQ(got.samples, in.samples);
    EXPECT_EQ(got.orientations, in.samples);
    EXPECT_EQ(got.calibrated, 1u);
    EXPECT_EQ(caphub("info " + out).exitCode, 0);
    EXPECT_THAT(got.metadata, HasSubstr("smooth_heading = 'causal'"));
    // The heading of both runs: another estimate, and the header says which.
    const std::string both = temp("smooth-both.cap");
    fs::remove(both);
    const CliRun rb =
        caphub("reprocess " + source_ + " -o " + both + " --smooth --smooth-heading both");
    ASSERT_EQ(rb.exitCode, 0) << rb.output;
    const Contents gotBoth = contentsOf(both);
    EXPECT_THAT(gotBoth.metadata, HasSubstr("smooth_heading = 'both'"));
    ASSERT_EQ(gotBoth.poseJoints.size(), got.poseJoints.size());
    float apart = 0;
    for (std::size_t i = 0; i < got.poseJoints.size(); ++i) {
        apart = std::max(apart, gotBoth.poseJoints[i].angularDistance(got.poseJoints[i]));
    }
    EXPECT_GT(apart, 1e-4f);
}

// Two takes joined into one file: the second's samples go back in time. They were fed to the
// filters as if in order; now each sample not after its sensor's previous one is skipped and
// counted with the recording's damage.
TEST_F(Reprocess, RawSamplesGoingBackInTimeAreSkippedAndSaid) {
    using namespace caphub::firmware;
    const std::string joined = temp("joined.cap");
    fs::remove(joined);
    std::uint64_t written = 0;
    {
        auto reader = RecordingReader::open(source_);
        ASSERT_TRUE(reader.ok());
        auto writer = RecordingWriter::create(joined, (*reader)->metadata());
        ASSERT_TRUE(writer.ok()) << writer.error().message;
        for (int copy = 0; copy < 2; ++copy) {
            auto again = RecordingReader::open(source_);
            ASSERT_TRUE(again.ok());
            RecordView v;
            int n = 0;
            while ((*again)->next(v) == 1 && n < 2000) {
                int sensor = -1;
                caphub::hal::ImuSample s;
                if (v.type == cap::RecordType::RawSample && decodeRawSample(v, sensor, s)) {
                    ASSERT_EQ((*writer)->writeRawSample(sensor, s), 0);
                    ++n;
                    ++written;
                }
            }
        }
        ASSERT_EQ((*writer)->close(), 0);
    }
    const std::string out = temp("joined_re.cap");
    fs::remove(out);
    const CliRun r = caphub("reprocess " + joined + " -o " + out);
    EXPECT_EQ(r.exitCode, 0) << r.output;
    EXPECT_THAT(r.output, HasSubstr("2000 raw sample(s) not after their sensor's previous one"));
    EXPECT_EQ(contentsOf(out).samples, written - 2000);
}

TEST_F(Reprocess, BadOptionsAndInputsAreRefusedWithExitCode2) {
    const std::string out = temp("bad.cap");
    fs::remove(out);
    const auto refused = [&](const std::string& args, const std::string& message) {
        const CliRun r = caphub("reprocess " + args);
        EXPECT_EQ(r.exitCode, 2) << args << "\n" << r.output;
        EXPECT_THAT(r.output, HasSubstr(message)) << args;
        EXPECT_FALSE(fs::exists(out)) << args;
        EXPECT_FALSE(fs::exists(out + ".part")) << args;
    };
    refused(source_ + " -o " + out + " --at 3", "--at needs --calibrate");
    refused(source_ + " -o " + out + " --calibrate tpose", "needs one --at");
    refused(source_ + " -o " + out + " --calibrate tn --at 1", "needs two --at");
    refused(source_ + " -o " + out + " --calibrate tpose --at 100",
            "--at 100: the pose must be held from there for 1 s within the recording's");
    refused(source_ + " -o " + out + " --calibrate sitting --at 1", "--calibrate");
    refused(source_ + " -o " + out + " --pose-rate 0", "--pose-rate");
    refused(source_ + " -o " + out + " --smooth-heading both",
            "--smooth-heading requires --smooth");
    refused(source_ + " -o " + out + " --smooth --smooth-heading sideways", "--smooth-heading");
    refused(temp("") + " -o " + out, "is a directory");
    refused(temp("missing.cap") + " -o " + out, "No such file");
    refused(source_ + " -o /dev/null", "is a device");
    refused(source_ + " -o " + temp(""), "is a directory");
    refused(source_ + " -o " + source_, "is the recording being reprocessed");
    refused(source_ + " -o " + out + " --calibration " + temp("missing.toml"), "No such file");
    const std::string garbage = temp("garbage.cap");
    std::ofstream(garbage) << "not a recording at all\n";
    refused(garbage + " -o " + out, "not a caphub recording");
}

}  // namespace
