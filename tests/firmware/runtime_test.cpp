// The bus workers on the virtual suit: every sample of every sensor arrives, a sensor that
// stops answering is reported while the others keep going, and comes back by itself.
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

}  // namespace caphub::firmware
