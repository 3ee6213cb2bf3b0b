// The Hub on the virtual suit, driven as the control plane will drive it: takes started and
// stopped while the capture runs, each its own file holding only its own span, markers and
// commands recorded as events, the state queried, and commands refused when they cannot apply.
#include "firmware/runtime/hub.h"

#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

#include <gtest/gtest.h>

#include "board/loader.h"
#include "board/sim/virtual_suit.h"
#include "firmware/recording/reader.h"
#include "tests/firmware/sim_speed.h"

namespace caphub::firmware {
namespace {

namespace fs = std::filesystem;
using std::chrono::milliseconds;
using std::chrono::seconds;

struct TakeContents {
    std::uint64_t samples = 0;
    std::uint64_t orientations = 0;
    Timestamp firstSample = Timestamp::max();
    Timestamp lastSample = Timestamp::min();
    std::vector<std::pair<cap::EventKind, std::string>> events;
    std::vector<std::string> markers;
    std::uint64_t records = 0;
    std::size_t damage = 0;
    cap::RecordType lastType = cap::RecordType::Metadata;
};

TakeContents readTake(const fs::path& path) {
    TakeContents c;
    auto reader = RecordingReader::open(path.string());
    EXPECT_TRUE(reader.ok()) << path;
    if (!reader) {
        return c;
    }
    RecordView r;
    while ((*reader)->next(r) == 1) {
        c.lastType = r.type;
        ++c.records;
        switch (r.type) {
            case cap::RecordType::RawSample:
                ++c.samples;
                c.firstSample = std::min(c.firstSample, r.t);
                c.lastSample = std::max(c.lastSample, r.t);
                break;
            case cap::RecordType::Orientation:
                ++c.orientations;
                break;
            case cap::RecordType::Event: {
                cap::EventKind kind{};
                int sensor = 0;
                int error = 0;
                std::string text;
                EXPECT_TRUE(decodeEvent(r, kind, sensor, error, text));
                c.events.emplace_back(kind, text);
                break;
            }
            case cap::RecordType::Marker:
                c.markers.emplace_back(r.payload.begin(), r.payload.end());
                break;
            default:
                break;
        }
    }
    c.damage = (*reader)->damage().size();
    return c;
}

bool hasEvent(const TakeContents& c, cap::EventKind kind, const std::string& text) {
    for (const auto& [k, t] : c.events) {
        if (k == kind && t == text) {
            return true;
        }
    }
    return false;
}

// The hub's state once `done` holds of it, looked at every `every` at most 400 times (the last
// state looked at when it never held): the tests do not depend on how fast a loaded machine
// runs the capture.
template <typename Done>
HubState waitForState(Hub& hub, Done done, milliseconds every = milliseconds(25)) {
    HubState s = hub.state();
    for (int i = 1; i < 400 && !done(s); ++i) {
        std::this_thread::sleep_for(every);
        s = hub.state();
    }
    return s;
}

// Waits (at most 20 s of real time) until the running take holds `n` records.
bool waitForRecords(Hub& hub, std::uint64_t n) {
    const auto holds = [n](const HubState& s) { return s.take && s.take->records >= n; };
    return holds(waitForState(hub, holds, milliseconds(50)));
}

struct HubRig {
    board::Board board;
    SimulatedClock clock;
    board::SuitHardware suit;
    fs::path dir;
    std::unique_ptr<Hub> hub;

    explicit HubRig(const std::string& name)
        : clock(timestampFromNs(1'000'000'000), caphub::testing::simSpeed(4.0)),
          dir(fs::path(::testing::TempDir()) / ("caphub-hub-" + name)) {
        fs::remove_all(dir);
        auto loaded = board::loadBoardFile(CAPHUB_SOURCE_DIR "/board/sim-upper10.toml");
        EXPECT_TRUE(loaded.ok());
        board = *loaded.board;
        auto built = board::sim::buildVirtualSuit(board, clock, nullptr);
        EXPECT_TRUE(built.ok()) << built.error().message;
        suit = std::move(*built);
        HubOptions o;
        o.recordings = dir;
        o.softwareVersion = "hub-test";
        o.statusPath = dir / "status.json";
        hub = std::make_unique<Hub>(board, clock, suit, std::move(o));
    }

    // Lets the capture run for `d` of its clock (paced at 4x, or at real time on a slow build).
    void runFor(Duration d) {
        const Timestamp until = clock.now() + d;
        while (clock.now() < until) {
            std::this_thread::sleep_for(milliseconds(5));
        }
    }
};

TEST(Hub, TakesStartAndStopWhileTheCaptureRunsEachInItsOwnFile) {
    HubRig rig("takes");
    // Before the capture runs, commands are refused with a reason.
    auto early = rig.hub->startTake("early");
    ASSERT_FALSE(early.ok());
    EXPECT_NE(early.error().message.find("not running"), std::string::npos);

    const Timestamp captureStart = rig.clock.now();
    rig.hub->start();
    rig.runFor(milliseconds(1200));                         // the sensors come online
    EXPECT_FALSE(rig.hub->marker("nothing to mark").ok());  // no take yet
    EXPECT_FALSE(rig.hub->stopTake().ok());

    auto first = rig.hub->startTake("walk-1");
    ASSERT_TRUE(first.ok()) << first.error().message;
    EXPECT_EQ(first->path.parent_path(), rig.dir);
    EXPECT_TRUE(first->path.filename().string().ends_with("-walk-1.cap")) << first->path;
    ASSERT_TRUE(waitForRecords(*rig.hub, 600));
    ASSERT_TRUE(rig.hub->marker("left heel strike").ok());
    const HubState during = rig.hub->state();
    ASSERT_TRUE(during.take.has_value());
    EXPECT_EQ(during.take->path, first->path);
    EXPECT_GE(during.take->records, 600u);
    ASSERT_TRUE(waitForRecords(*rig.hub, 1200));
    auto stopped = rig.hub->stopTake();
    ASSERT_TRUE(stopped.ok()) << stopped.error().message;
    const Timestamp afterFirst = rig.clock.now();
    EXPECT_EQ(stopped->path, first->path);
    EXPECT_EQ(stopped->error, 0);

    rig.runFor(milliseconds(1600));  // between takes: nothing is written
    auto second = rig.hub->startTake("");
    ASSERT_TRUE(second.ok()) << second.error().message;
    EXPECT_NE(second->path, first->path);
    EXPECT_FALSE(rig.hub->startTake("bad/name").ok());  // refused; the take goes on
    EXPECT_FALSE(rig.hub->startTake("../up").ok());
    // The take being recorded is never deleted (the web page asked its own record of the take,
    // which a start still being carried out had not reached).
    auto busy = rig.hub->deleteTakeFile(second->path);
    ASSERT_FALSE(busy.ok());
    EXPECT_EQ(busy.error().code, EBUSY);
    EXPECT_TRUE(fs::exists(second->path));
    ASSERT_TRUE(waitForRecords(*rig.hub, 800));
    rig.hub->requestStop();
    (void)rig.hub->wait();  // ends the second take with the capture
    EXPECT_FALSE(rig.hub->marker("too late").ok());

    const TakeContents a = readTake(first->path);
    EXPECT_EQ(a.damage, 0u);
    // Samples and their orientations, about half the records each.
    EXPECT_GT(a.samples, 400u);
    EXPECT_GT(a.orientations, 400u);
    // Nothing from before the take (the capture ran 1.2 s of simulated time before it; a loaded
    // machine may deliver a few samples read just before the command after it).
    EXPECT_GT(a.firstSample, captureStart + milliseconds(800));
    EXPECT_LE(a.lastSample, afterFirst);
    ASSERT_FALSE(a.events.empty());
    EXPECT_EQ(a.events.front().first, cap::EventKind::TakeStarted);
    EXPECT_EQ(a.events.front().second, "walk-1");
    EXPECT_TRUE(hasEvent(a, cap::EventKind::Command, "stop take"));
    // The take's last records: "take stopped", then "recording stopped" (every file ends so).
    ASSERT_GE(a.events.size(), 2u);
    EXPECT_EQ(a.events[a.events.size() - 2].first, cap::EventKind::TakeStopped);
    EXPECT_EQ(a.events.back().first, cap::EventKind::RecordingStopped);
    EXPECT_EQ(a.lastType, cap::RecordType::Event);
    ASSERT_EQ(a.markers.size(), 1u);
    EXPECT_EQ(a.markers[0], "left heel strike");
    EXPECT_EQ(stopped->records, a.records);

    const TakeContents b = readTake(second->path);
    EXPECT_EQ(b.damage, 0u);
    EXPECT_GT(b.samples, 300u);  // of at least 800 records
    // Nothing from the gap between the takes (1.6 s of the clock).
    EXPECT_GT(b.firstSample, afterFirst + milliseconds(800));
    EXPECT_EQ(b.events.front().first, cap::EventKind::TakeStarted);
    ASSERT_GE(b.events.size(), 2u);
    EXPECT_EQ(b.events[b.events.size() - 2].first, cap::EventKind::TakeStopped);
    EXPECT_EQ(b.events.back().first, cap::EventKind::RecordingStopped);
    // Only the two takes were written (and the status).
    std::size_t caps = 0;
    for (const auto& e : fs::directory_iterator(rig.dir)) {
        caps += e.path().extension() == ".cap";
    }
    EXPECT_EQ(caps, 2u);
}

// Body calibration and heading reset asked of a running capture: the calibration averages from
// its countdown and completes (state, event and metadata in the take), a T+N calibration from two
// moments is refused with its reason when the arms did not move, and the heading reset is
// recorded; a negative countdown is refused.
TEST(Hub, CalibratesTheBodyAndResetsTheHeadingWhileTheCaptureRuns) {
    HubRig rig("calibrate");
    rig.hub->start();
    rig.runFor(milliseconds(1200));
    auto take = rig.hub->startTake("calibration");
    ASSERT_TRUE(take.ok()) << take.error().message;
    EXPECT_FALSE(rig.hub->calibrateBody(body::ReferencePoseKind::T, -seconds(1)).ok());
    ASSERT_TRUE(rig.hub->calibrateBody(body::ReferencePoseKind::T, milliseconds(500)).ok());
    const auto waitFor = [&](body::CalibrationStatus::State want) {
        return waitForState(
            *rig.hub, [want](const HubState& s) { return s.calibrationStatus.state == want; });
    };
    const HubState done = waitFor(body::CalibrationStatus::State::Done);
    ASSERT_EQ(done.calibrationStatus.state, body::CalibrationStatus::State::Done)
        << done.calibrationStatus.message;
    EXPECT_EQ(done.calibrationStatus.method, body::CalibrationMethod::TPose);
    EXPECT_TRUE(done.bodyCalibrated);

    // T+N needs the arms to go from horizontal to hanging between the two moments: the subject
    // of this suit stands still, so it fails, says why, and the T-pose calibration stays.
    ASSERT_TRUE(rig.hub->calibrateBodyTPlusN(milliseconds(100), milliseconds(1500)).ok());
    const HubState failed = waitFor(body::CalibrationStatus::State::Failed);
    ASSERT_EQ(failed.calibrationStatus.state, body::CalibrationStatus::State::Failed);
    EXPECT_EQ(failed.calibrationStatus.method, body::CalibrationMethod::TPlusN);
    EXPECT_NE(failed.calibrationStatus.message.find("between the poses"), std::string::npos)
        << failed.calibrationStatus.message;
    EXPECT_TRUE(failed.bodyCalibrated);

    ASSERT_TRUE(rig.hub->headingReset().ok());
    // Done once the capture reaches the moment it was asked at (later on a loaded machine).
    const HubState reset = waitForState(*rig.hub, [](const HubState& s) {
        return s.headingReset.state != body::HeadingResetStatus::State::Pending;
    });
    ASSERT_EQ(reset.headingReset.state, body::HeadingResetStatus::State::Done)
        << reset.headingReset.message;
    ASSERT_TRUE(waitForRecords(*rig.hub, rig.hub->state().take->records + 100));
    ASSERT_TRUE(rig.hub->stopTake().ok());
    rig.hub->requestStop();
    (void)rig.hub->wait();

    const TakeContents c = readTake(take->path);
    EXPECT_TRUE(hasEvent(c, cap::EventKind::Command, "calibrate tpose in 0.5 s"));
    EXPECT_TRUE(hasEvent(c, cap::EventKind::Command, "heading reset"));
    int calibrated = 0;
    int headingResets = 0;
    for (const auto& [kind, text] : c.events) {
        calibrated += kind == cap::EventKind::Calibrated;
        headingResets += kind == cap::EventKind::HeadingReset;
    }
    EXPECT_EQ(calibrated, 1);  // the T-pose; the T+N failed
    EXPECT_EQ(headingResets, 1);
}

// The stepped mode drives the same pipeline (recorder, fusion, body) on one thread: twice from
// the same start it records the same records, bit for bit.
TEST(Hub, SteppedRunsRecordTheSameRecordsEveryTime) {
    const auto recordOnce = [](const std::string& name) {
        auto loaded = board::loadBoardFile(CAPHUB_SOURCE_DIR "/board/sim-upper10.toml");
        EXPECT_TRUE(loaded.ok());
        const board::Board board = *loaded.board;
        SimulatedClock clock(timestampFromNs(1'000'000'000));
        auto suit = board::sim::buildVirtualSuit(board, clock, nullptr);
        EXPECT_TRUE(suit.ok());
        const fs::path path = fs::path(::testing::TempDir()) / ("caphub-hub-stepped-" + name);
        fs::remove(path);
        HubOptions o;
        o.mode = Capture::Mode::Stepped;
        auto writer = RecordingWriter::create(path.string(), "");
        EXPECT_TRUE(writer.ok());
        o.recordFromStart = std::move(*writer);
        Hub hub(board, clock, *suit, std::move(o));
        const CaptureStats stats = hub.runStepped(seconds(2));
        EXPECT_GT(stats.samples, 800u);  // 10 sensors at 50 Hz, after their start-up
        EXPECT_GT(hub.body().poses(), 50u);
        std::vector<std::uint8_t> bytes;
        auto reader = RecordingReader::open(path.string());
        EXPECT_TRUE(reader.ok());
        RecordView v;
        while ((*reader)->next(v) == 1) {
            bytes.push_back(static_cast<std::uint8_t>(v.type));
            bytes.insert(bytes.end(), v.payload.begin(), v.payload.end());
        }
        return bytes;
    };
    const auto a = recordOnce("a");
    const auto b = recordOnce("b");
    EXPECT_GT(a.size(), 10000u);
    EXPECT_EQ(a, b);
}

// The pose feed hands the consumers off the pipeline thread (streams, the control plane) every
// pose the body solves, the same as recorded, in order; the latest-value slot holds the last.
TEST(Hub, PublishesEveryRecordedPoseToTheFeed) {
    auto loaded = board::loadBoardFile(CAPHUB_SOURCE_DIR "/board/sim-upper10.toml");
    ASSERT_TRUE(loaded.ok());
    const board::Board board = *loaded.board;
    SimulatedClock clock(timestampFromNs(1'000'000'000));
    auto suit = board::sim::buildVirtualSuit(board, clock, nullptr);
    ASSERT_TRUE(suit.ok());
    const fs::path path = fs::path(::testing::TempDir()) / "caphub-hub-feed.cap";
    fs::remove(path);
    HubOptions o;
    o.mode = Capture::Mode::Stepped;
    auto writer = RecordingWriter::create(path.string(), "");
    ASSERT_TRUE(writer.ok());
    o.recordFromStart = std::move(*writer);
    Hub hub(board, clock, *suit, std::move(o));
    PoseFrame none;
    EXPECT_EQ(hub.poses().latest(none), 0u);
    const std::shared_ptr<PoseQueue> queue = hub.poses().subscribe();
    const std::shared_ptr<PoseQueue> dropped = hub.poses().subscribe();
    hub.poses().unsubscribe(dropped);
    hub.runStepped(seconds(2));

    std::vector<PoseFrame> fed;
    PoseFrame f;
    while (queue->pop(f)) {
        fed.push_back(f);
    }
    EXPECT_EQ(queue->dropped(), 0u);
    PoseFrame g;
    EXPECT_FALSE(dropped->pop(g));
    ASSERT_GT(fed.size(), 50u);
    EXPECT_EQ(fed.size(), hub.body().poses());
    PoseFrame latest;
    EXPECT_EQ(hub.poses().latest(latest), fed.back().serial);
    EXPECT_EQ(latest.t, fed.back().t);

    auto reader = RecordingReader::open(path.string());
    ASSERT_TRUE(reader.ok());
    RecordView v;
    std::size_t i = 0;
    while ((*reader)->next(v) == 1) {
        if (v.type != cap::RecordType::Pose) {
            continue;
        }
        Eigen::Vector3f root;
        std::vector<Eigen::Quaternionf> joints;
        std::uint32_t notMeasured = 0;
        ASSERT_TRUE(decodePose(v, root, joints, &notMeasured));
        ASSERT_EQ(joints.size(), static_cast<std::size_t>(body::kSegmentCount));
        ASSERT_LT(i, fed.size());
        const PoseFrame& p = fed[i];
        EXPECT_EQ(p.serial, i + 1);
        EXPECT_EQ(p.t, v.t);
        EXPECT_EQ(p.notMeasured, notMeasured);
        EXPECT_LT((p.rootM - root).norm(), 1e-6f);
        for (std::size_t j = 0; j < joints.size(); ++j) {
            EXPECT_NEAR(std::abs(p.local[j].dot(joints[j])), 1.0f, 1e-6f) << "pose " << i;
        }
        // The world orientations compose the joints down the tree.
        EXPECT_NEAR(std::abs(p.world[0].dot(p.local[0])), 1.0f, 1e-6f);
        for (int j = 1; j < body::kSegmentCount; ++j) {
            const auto u = static_cast<std::size_t>(j);
            const Eigen::Quaternionf composed =
                p.world[static_cast<std::size_t>(body::parentOf(j))] * p.local[u];
            EXPECT_NEAR(std::abs(composed.dot(p.world[u])), 1.0f, 1e-5f) << "segment " << j;
        }
        EXPECT_LE(p.newestSampleT, p.publishedT);
        ++i;
    }
    EXPECT_EQ(i, fed.size());
}

TEST(Hub, TakeNamesAreCheckedAndDated) {
    const std::time_t when = 1'700'000'000;
    auto plain = takeFileName("", when);
    ASSERT_TRUE(plain.ok());
    EXPECT_EQ(plain->size(), std::string("20231114-221320.cap").size());
    auto named = takeFileName("jump_2.b", when);
    ASSERT_TRUE(named.ok());
    EXPECT_TRUE(named->ends_with("-jump_2.b.cap"));
    for (const char* bad : {"a/b", "..", ".hidden", "a b", "x\n", "tab\t"}) {
        EXPECT_FALSE(takeFileName(bad, when).ok()) << bad;
    }
    EXPECT_FALSE(takeFileName(std::string(65, 'a'), when).ok());
    EXPECT_TRUE(takeFileName(std::string(64, 'a'), when).ok());
}

// What the magnetometers that no calibration corrects learn of their hard and soft iron is kept
// between runs (docs/fusion.md, "Persistence"): saved every magStateEvery of the capture's clock
// and at its end, loaded at the next start, so that it goes on learning from there.
TEST(Hub, KeepsTheMagnetometerEstimatesBetweenRuns) {
    auto loaded = board::loadBoardFile(CAPHUB_SOURCE_DIR "/board/sim-upper10.toml");
    ASSERT_TRUE(loaded.ok());
    const board::Board board = *loaded.board;
    const fs::path dir = fs::path(::testing::TempDir()) / "caphub-hub-magstate";
    fs::remove_all(dir);
    fs::create_directories(dir);
    const fs::path path = dir / "mag-estimates.txt";
    struct Run {
        std::vector<std::uint64_t> samplesAtStart;
        std::vector<std::uint64_t> samplesAtEnd;
        std::uint64_t saves = 0;
        std::uint64_t written = 0;
        std::string loadError;
        std::string saveError;
    };
    const auto runOnce = [&](const fs::path& statePath, Duration d) {
        SimulatedClock clock(timestampFromNs(1'000'000'000));
        auto suit = board::sim::buildVirtualSuit(board, clock, nullptr);
        EXPECT_TRUE(suit.ok());
        HubOptions o;
        o.mode = Capture::Mode::Stepped;
        o.magStatePath = statePath;
        o.magStateEvery = seconds(2);
        Hub hub(board, clock, *suit, std::move(o));
        Run r;
        const auto samples = [&] {
            std::vector<std::uint64_t> n;
            for (std::size_t i = 0; i < board.sensors.size(); ++i) {
                const auto st = hub.fusion().magEstimatorState(static_cast<int>(i));
                n.push_back(st ? st->samples : 0);
            }
            return n;
        };
        r.samplesAtStart = samples();
        r.loadError = hub.magStateLoadError();
        hub.runStepped(d);
        r.samplesAtEnd = samples();
        r.saves = hub.magState()->saves();
        r.written = hub.magState()->written();
        r.saveError = hub.magState()->error();
        return r;
    };
    // Every line of the file a state of one of the board's sensors.
    const auto stateLines = [&] {
        std::ifstream in(path);
        std::string line;
        int n = 0;
        while (std::getline(in, line)) {
            if (line.empty() || line[0] == '#') {
                continue;
            }
            const auto space = line.find(' ');
            EXPECT_TRUE(fusion::parseHardIronState(line.substr(space))) << line.substr(0, 40);
            ++n;
        }
        return n;
    };

    const Run first = runOnce(path, seconds(9));
    EXPECT_EQ(first.loadError, "");  // no file yet: a first run
    for (std::size_t i = 0; i < board.sensors.size(); ++i) {
        EXPECT_EQ(first.samplesAtStart[i], 0u) << board.sensors[i].name;
        EXPECT_GT(first.samplesAtEnd[i], 100u) << board.sensors[i].name;
    }
    EXPECT_EQ(first.saves, 5u);  // every 2 s of the 9, and the end
    // At least the end's: a save that comes while the file is being written replaces the one
    // pending (the stepped capture runs far faster than its clock, and a loaded machine's disk
    // may take longer than the capture's 2 s).
    EXPECT_GE(first.written, 1u);
    EXPECT_LE(first.written, first.saves);
    EXPECT_EQ(first.saveError, "");
    EXPECT_EQ(stateLines(), static_cast<int>(board.sensors.size()));

    const Run second = runOnce(path, seconds(3));
    EXPECT_EQ(second.loadError, "");
    for (std::size_t i = 0; i < board.sensors.size(); ++i) {
        // Started where the first run ended, and learnt on.
        EXPECT_EQ(second.samplesAtStart[i], first.samplesAtEnd[i]) << board.sensors[i].name;
        EXPECT_GT(second.samplesAtEnd[i], first.samplesAtEnd[i]) << board.sensors[i].name;
    }

    // A damaged file is said (file and line) and nothing of it is loaded; the capture runs and
    // its end replaces the file with what it learnt.
    {
        std::ifstream in(path);
        std::stringstream all;
        all << in.rdbuf();
        std::string text = all.str();
        text += board.sensors[0].name + " 1 2 3\n";
        std::ofstream(path, std::ios::trunc) << text;
    }
    const Run damaged = runOnce(path, seconds(2));
    EXPECT_NE(
        damaged.loadError.find(path.string() + ":" + std::to_string(board.sensors.size() + 2)),
        std::string::npos)
        << damaged.loadError;
    EXPECT_EQ(damaged.samplesAtStart[0], 0u);
    EXPECT_EQ(stateLines(), static_cast<int>(board.sensors.size()));

    // A path that is not a regular file is never written over.
    const fs::path notAFile = dir / "a-directory";
    fs::create_directories(notAFile);
    const Run refused = runOnce(notAFile, seconds(1));
    EXPECT_NE(refused.loadError.find("is a directory"), std::string::npos) << refused.loadError;
    EXPECT_NE(refused.saveError.find("not a regular file"), std::string::npos) << refused.saveError;
    EXPECT_TRUE(fs::is_directory(notAFile));
}

}  // namespace
}  // namespace caphub::firmware
