// The bus workers on the virtual suit: every sample of every sensor arrives, a sensor that
// stops answering is reported while the others keep going, and comes back by itself.
#include <cstdio>
#include <cstdlib>
#include <future>
#include <thread>

#include <gtest/gtest.h>

#include "board/loader.h"
#include "board/sim/virtual_suit.h"
#include "firmware/runtime/bus_worker.h"
#include "firmware/runtime/capture.h"

namespace caphub::firmware {
namespace {

using std::chrono::milliseconds;
using std::chrono::seconds;

const char* kBoard = R"(schema = 1
name = "runtime-test"
[[bus]]
name = "sim0"
type = "sim"
clock_hz = 400000
[[mux]]
name = "m0"
bus = "sim0"
address = 0x70
[[sensor]]
name = "a"
segment = "pelvis"
chip = "icm20948"
bus = "sim0"
mux = "m0"
channel = 0
address = 0x68
drdy = "gpiochip0:1"
odr_hz = 100
[[sensor]]
name = "b"
segment = "t12"
chip = "icm20948"
bus = "sim0"
mux = "m0"
channel = 1
address = 0x68
drdy = "gpiochip0:2"
odr_hz = 100
[[sensor]]
name = "c"
segment = "skull"
chip = "lsm6dsox+lis3mdl"
bus = "sim0"
address = 0x6a
drdy = "gpiochip0:3"
odr_hz = 104
[[sensor]]
name = "d"
segment = "l_hand"
chip = "icm20948"
bus = "sim0"
mux = "m0"
channel = 2
address = 0x69
odr_hz = 50
)";

struct Rig {
    SimulatedClock clock{timestampFromNs(1'000'000'000)};
    board::Board board;
    board::SuitHardware suit;
    board::sim::VirtualChips chips;
    std::unique_ptr<BusWorker> worker;
    std::vector<std::uint64_t> received;
    std::vector<RuntimeEvent> events;

    explicit Rig(const char* text = kBoard) {
        auto loaded = board::loadBoardText(text, "runtime-test.toml");
        EXPECT_TRUE(loaded.ok()) << (loaded.errors.empty() ? "" : loaded.errors[0].str());
        board = *loaded.board;
        auto built = board::sim::buildVirtualSuit(board, clock, nullptr, &chips);
        EXPECT_TRUE(built.ok()) << built.error().message;
        suit = std::move(*built);
        worker = std::make_unique<BusWorker>(suit.buses[0], clock);
        received.assign(board.sensors.size(), 0);
    }

    // Runs the worker (and drains its rings) until `until` on the stepped clock.
    void runUntil(Timestamp until) {
        while (clock.now() < until) {
            worker->runOnce();
            SensorSample s;
            while (worker->samples().pop(s)) {
                ++received[static_cast<std::size_t>(s.sensor)];
            }
            RuntimeEvent e;
            while (worker->events().pop(e)) {
                events.push_back(e);
            }
        }
    }

    int countEvents(RuntimeEvent::Kind kind, int sensor) const {
        int n = 0;
        for (const auto& e : events) {
            n += e.kind == kind && e.sensor == sensor;
        }
        return n;
    }
};

TEST(BusWorker, EverySensorComesOnlineAndDeliversAtItsRate) {
    Rig rig;
    rig.runUntil(rig.clock.now() + milliseconds(500));  // start-up
    for (int s = 0; s < 4; ++s) {
        EXPECT_EQ(rig.countEvents(RuntimeEvent::Kind::SensorOnline, s), 1) << s;
    }
    const auto before = rig.received;
    rig.runUntil(rig.clock.now() + seconds(2));
    EXPECT_NEAR(double(rig.received[0] - before[0]), 200, 1);
    EXPECT_NEAR(double(rig.received[1] - before[1]), 200, 1);
    EXPECT_NEAR(double(rig.received[2] - before[2]), 208, 1);
    EXPECT_NEAR(double(rig.received[3] - before[3]), 100, 1);  // no line: polled at its rate
    for (std::size_t i = 0; i < 4; ++i) {
        EXPECT_EQ(rig.worker->counters(i).dropped.load(), 0u);
        EXPECT_EQ(rig.worker->counters(i).readErrors.load(), 0u);
    }
}

TEST(BusWorker, SamplesCarryTheirDataReadyTimestamps) {
    Rig rig;
    rig.runUntil(rig.clock.now() + milliseconds(500));
    SensorSample s;
    while (rig.worker->samples().pop(s)) {
    }
    std::vector<Timestamp> times;
    for (int i = 0; i < 40; ++i) {
        rig.worker->runOnce();
        while (rig.worker->samples().pop(s)) {
            if (s.sensor == 0) {
                times.push_back(s.sample.t);
            }
        }
    }
    ASSERT_GE(times.size(), 10u);
    for (std::size_t i = 1; i < times.size(); ++i) {
        EXPECT_EQ(times[i] - times[i - 1], periodFromHz(100));
    }
}

TEST(BusWorker, ASensorThatNacksForTwoSecondsIsReportedAndTheOthersLoseNothing) {
    Rig rig;
    rig.runUntil(rig.clock.now() + milliseconds(500));
    const auto before = rig.received;
    const Timestamp outageStart = rig.clock.now();
    rig.chips.imu[1]->nackUntil(outageStart + seconds(2));
    rig.runUntil(outageStart + seconds(4));
    EXPECT_EQ(rig.countEvents(RuntimeEvent::Kind::SensorLost, 1), 1);
    EXPECT_EQ(rig.countEvents(RuntimeEvent::Kind::SensorOnline, 1), 2);  // start, and back
    EXPECT_EQ(rig.worker->counters(1).lost.load(), 1u);
    EXPECT_TRUE(rig.worker->counters(1).online.load());
    // The neighbours on the same bus delivered every sample of the 4 s.
    EXPECT_NEAR(double(rig.received[0] - before[0]), 400, 1);
    EXPECT_NEAR(double(rig.received[2] - before[2]), 416, 1);
    EXPECT_NEAR(double(rig.received[3] - before[3]), 200, 1);
    // The lost sensor delivered before and after the gap, not during it.
    EXPECT_GT(rig.received[1] - before[1], 150u);
    EXPECT_LT(rig.received[1] - before[1], 250u);
}

TEST(BusWorker, AChipThatResetsItselfIsReconfigured) {
    Rig rig;
    rig.runUntil(rig.clock.now() + milliseconds(500));
    rig.chips.imu[0]->resetToDefaults();
    rig.runUntil(rig.clock.now() + seconds(3));
    EXPECT_GE(rig.countEvents(RuntimeEvent::Kind::SensorReset, 0) +
                  rig.countEvents(RuntimeEvent::Kind::LineSilent, 0),
              1);
    EXPECT_TRUE(rig.worker->counters(0).online.load());
    const auto before = rig.received[0];
    rig.runUntil(rig.clock.now() + seconds(1));
    EXPECT_NEAR(double(rig.received[0] - before), 100, 1);
}

TEST(BusWorker, AStuckDataReadyLineIsReported) {
    Rig rig;
    rig.runUntil(rig.clock.now() + milliseconds(500));
    rig.chips.imu[2]->setDataReadyStuck(true);
    rig.runUntil(rig.clock.now() + seconds(1));
    EXPECT_GE(rig.countEvents(RuntimeEvent::Kind::LineSilent, 2), 1);
    EXPECT_GE(rig.worker->counters(2).lost.load(), 1u);
}

TEST(VirtualSuit, TheDefaultSuitBuildsAndEverySensorStarts) {
    auto loaded = board::loadBoardFile(CAPHUB_SOURCE_DIR "/board/sim-suit.toml");
    ASSERT_TRUE(loaded.ok());
    SimulatedClock clock(timestampFromNs(1'000'000'000));
    auto suit = board::sim::buildVirtualSuit(*loaded.board, clock, nullptr);
    ASSERT_TRUE(suit.ok()) << suit.error().message;
    ASSERT_EQ(suit->buses.size(), 4u);
    std::size_t online = 0;
    for (auto& bus : suit->buses) {
        BusWorker worker(bus, clock);
        const Timestamp end = clock.now() + milliseconds(500);
        while (clock.now() < end) {
            worker.runOnce();
            SensorSample s;
            while (worker.samples().pop(s)) {
            }
        }
        for (std::size_t i = 0; i < worker.sensorCount(); ++i) {
            online += worker.counters(i).online.load();
        }
    }
    EXPECT_EQ(online, 17u);
}

TEST(VirtualSuit, RefusesARealBus) {
    auto loaded = board::loadBoardText(R"(schema = 1
name = "real"
[[bus]]
name = "i2c1"
type = "i2c"
device = "/dev/i2c-1"
clock_hz = 400000
[[sensor]]
name = "a"
segment = "pelvis"
chip = "icm20948"
bus = "i2c1"
address = 0x68
odr_hz = 100
)",
                                       "real.toml");
    ASSERT_TRUE(loaded.ok());
    SimulatedClock clock;
    auto suit = board::sim::buildVirtualSuit(*loaded.board, clock, nullptr);
    ASSERT_FALSE(suit.ok());
    EXPECT_NE(suit.error().message.find("'i2c1'"), std::string::npos);
}

}  // namespace
// A stage slower than the workers (1 ms per sample against 5000 samples a second): the capture
// still ends at its duration, handing the stages bounded batches between its checks of the end,
// and the rings drop what the pipeline cannot take.
class SlowStage final : public PipelineStage {
public:
    void onSample(const SensorSample&) override {
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
        ++samples;
    }
    void onEvent(const RuntimeEvent&) override {}
    std::uint64_t samples = 0;
};

TEST(Capture, ASlowPipelineStillStopsAtTheDuration) {
    auto loaded = board::loadBoardFile(CAPHUB_SOURCE_DIR "/board/sim-upper10.toml");
    ASSERT_TRUE(loaded.ok());
    // 10 sensors at 50 Hz paced 10 times faster than real time: 5000 samples per second.
    SimulatedClock clock(timestampFromNs(1'000'000'000), 10.0);
    auto suit = board::sim::buildVirtualSuit(*loaded.board, clock, nullptr);
    ASSERT_TRUE(suit.ok()) << suit.error().message;
    Capture capture(*suit, clock);
    SlowStage slow;
    capture.addStage(slow);
    capture.start(seconds(2));
    const CaptureStats stats = capture.wait();
    // It ended (before the fix it never did): within one batch of 256 samples per worker
    // (256 ms real, 2.6 s simulated) after the 2 s, and every sample was handed on or dropped.
    EXPECT_GE(stats.elapsed, seconds(2));
    EXPECT_LT(stats.elapsed, seconds(2) + milliseconds(2600 + 500));
    EXPECT_EQ(stats.samples, slow.samples);
}

// The capture's wait() on another thread, with a bound: a capture that never ends must fail the
// test, not hang it (its threads cannot be joined, so the process ends here).
CaptureStats waitAtMost(Capture& capture, std::chrono::seconds bound, const char* what) {
    auto done = std::async(std::launch::async, [&capture] { return capture.wait(); });
    if (done.wait_for(bound) != std::future_status::ready) {
        std::fprintf(stderr, "FAILED: %s: the capture did not end within %lld s\n", what,
                     static_cast<long long>(bound.count()));
        std::fflush(stderr);
        std::_Exit(1);
    }
    return done.get();
}

struct PacedSuit {
    board::Board board;
    SimulatedClock clock;
    board::SuitHardware suit;

    explicit PacedSuit(double rate) : clock(timestampFromNs(1'000'000'000), rate) {
        auto loaded = board::loadBoardFile(CAPHUB_SOURCE_DIR "/board/sim-suit-220.toml");
        EXPECT_TRUE(loaded.ok());
        board = *loaded.board;
        auto built = board::sim::buildVirtualSuit(board, clock, nullptr);
        EXPECT_TRUE(built.ok()) << built.error().message;
        suit = std::move(*built);
    }
};

TEST(Capture, ASuitPacedFarFasterThanItCanBeReadStillStopsAtItsDuration) {
    // 17 sensors at 220 Hz, 10,000 simulated seconds a real second: edges arrive far faster than
    // a worker reads them. Before the fix each worker chased them forever and the capture never
    // ended.
    for (double rate : {1e4, 1e6}) {
        PacedSuit rig(rate);
        Capture capture(rig.suit, rig.clock);
        const auto duration = std::chrono::seconds(static_cast<std::int64_t>(rate / 2));  // 0.5 s
        capture.start(duration);
        const CaptureStats stats = waitAtMost(capture, seconds(20), "--speed 1e4");
        EXPECT_GE(stats.elapsed, duration) << rate;
    }
}

TEST(Capture, ARequestedStopEndsAFastCaptureWithinASecond) {
    PacedSuit rig(1e5);
    Capture capture(rig.suit, rig.clock);
    capture.start();  // until requested
    std::this_thread::sleep_for(milliseconds(300));
    MonotonicClock real;
    const Timestamp asked = real.now();
    capture.requestStop();
    (void)waitAtMost(capture, seconds(20), "stop at 1e5");
    EXPECT_LT(real.now() - asked, seconds(1));
}

TEST(Capture, ARequestedStopEndsASlowCaptureWithinASecond) {
    // A thousandth of real time: one 220 Hz sample period is 4.5 s of real time, and each wait
    // of a worker up to 50 s. Before the fix the workers slept through the stop.
    PacedSuit rig(0.001);
    Capture capture(rig.suit, rig.clock);
    capture.start();
    std::this_thread::sleep_for(milliseconds(300));
    MonotonicClock real;
    const Timestamp asked = real.now();
    capture.requestStop();
    (void)waitAtMost(capture, seconds(60), "stop at 0.001");
    EXPECT_LT(real.now() - asked, seconds(1));
}

TEST(Capture, ThePipelineSleepsUntilTheWorkersWakeIt) {
    // Woken by the workers' data, not by polling: over a second of 17 x 220 Hz the pipeline is
    // woken through its eventfd (it would never be if it polled), every sample arrives, and each
    // wake-up finds samples waiting.
    PacedSuit rig(1.0);
    Capture capture(rig.suit, rig.clock);
    capture.start(seconds(1));
    const CaptureStats stats = waitAtMost(capture, seconds(20), "woken pipeline");
    EXPECT_GT(capture.wake().wakeups(), 50u);
    EXPECT_GT(stats.samples, 17u * 150u);
    EXPECT_EQ(stats.dropped, 0u);
}

}  // namespace caphub::firmware
