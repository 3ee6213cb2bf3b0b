// The simulated buses and data-ready lines, and the chip models' fault injection, as the
// drivers and the runtime will meet them.
#include "hal/sim/sim_bus.h"

#include <gtest/gtest.h>

#include "hal/drivers/icm20948.h"
#include "rig.h"

namespace caphub::hal {
namespace {

struct TwoSensorRig {
    SimulatedClock clock{timestampFromNs(1'000'000'000)};
    sim::SimI2cBus bus{"sim-i2c", clock};
    sim::Icm20948Model a;
    sim::Icm20948Model b;
    Icm20948 da{std::make_unique<I2cRegisterIo>(bus, 0x68), Icm20948::Interface::I2c, "a", {}};
    Icm20948 db{std::make_unique<I2cRegisterIo>(bus, 0x69), Icm20948::Interface::I2c, "b", {}};

    TwoSensorRig() {
        bus.attach(a, 0x68);
        bus.attach(b, 0x69);
    }
};

TEST(SimI2cBus, TwoDevicesAtOneAddressGarbleTheRead) {
    SimulatedClock clock;
    sim::SimI2cBus bus("sim", clock);
    sim::Icm20948Model a;
    sim::Icm20948Model b;
    bus.attach(a, 0x68);
    bus.attach(b, 0x68);
    std::uint8_t v = 0;
    EXPECT_EQ(bus.readByteData(0x68, 0, v), -EIO);
    EXPECT_EQ(bus.counters().errors.load(), 1u);
}

TEST(SimI2cBus, CountsTransactionsAndWireBytes) {
    TwoSensorRig rig;
    std::uint8_t v = 0;
    std::array<std::uint8_t, 6> block{};
    ASSERT_EQ(rig.bus.readByteData(0x68, 0, v), 0);
    ASSERT_EQ(rig.bus.readI2cBlock(0x68, 0x2D, block), 0);
    ASSERT_EQ(rig.bus.writeByteData(0x68, 0x7F, 0), 0);
    const auto s = snapshot(rig.bus.counters());
    EXPECT_EQ(s.transactions, 3u);
    EXPECT_EQ(s.bytes, 4u + 9u + 3u);
    EXPECT_EQ(s.errors, 0u);
}

TEST(SimI2cBus, ANackingSensorIsReportedWhileTheOtherKeepsDelivering) {
    TwoSensorRig rig;
    ASSERT_EQ(testing::startDriver(rig.da, rig.clock), 0);
    ASSERT_EQ(testing::startDriver(rig.db, rig.clock), 0);
    rig.b.nackUntil(rig.clock.now() + std::chrono::milliseconds(200));
    int okA = 0;
    int failB = 0;
    for (int i = 0; i < 10; ++i) {
        rig.clock.advanceBy(std::chrono::milliseconds(10));
        ImuSample s;
        okA += rig.da.readSample(rig.clock.now(), s) == 0;
        failB += rig.db.readSample(rig.clock.now(), s) == -ENXIO;
    }
    EXPECT_EQ(okA, 10);
    EXPECT_EQ(failB, 10);
    EXPECT_EQ(rig.db.counters().readErrors.load(), 10u);
    EXPECT_EQ(rig.da.counters().readErrors.load(), 0u);
    // After the outage, b delivers again.
    rig.clock.advanceBy(std::chrono::milliseconds(200));
    ImuSample s;
    EXPECT_EQ(rig.db.readSample(rig.clock.now(), s), 0);
}

TEST(ChipModel, CorruptedBytesChangeTheSample) {
    TwoSensorRig rig;
    ASSERT_EQ(testing::startDriver(rig.da, rig.clock), 0);
    rig.clock.advanceBy(std::chrono::milliseconds(10));
    ImuSample clean;
    ASSERT_EQ(rig.da.readSample(rig.clock.now(), clean), 0);
    rig.a.corruptNextReads(6);
    ImuSample corrupt;
    ASSERT_EQ(rig.da.readSample(rig.clock.now(), corrupt), 0);
    EXPECT_NE(clean.accMps2, corrupt.accMps2);
    EXPECT_EQ(rig.a.faults().corruptedBytes, 6u);
}

TEST(SimDataReadyLine, EdgesComeAtTheChipsSampleInstants) {
    TwoSensorRig rig;
    ASSERT_EQ(testing::startDriver(rig.da, rig.clock), 0);
    sim::SimDataReadyLine line("a-drdy", rig.clock, rig.a);
    Timestamp prev{};
    for (int i = 0; i < 20; ++i) {
        Timestamp t{};
        ASSERT_EQ(line.waitEdge(std::chrono::milliseconds(50), t), 0);
        EXPECT_EQ(rig.clock.now(), t);  // stepped clock: woken exactly at the edge
        if (i > 0) {
            EXPECT_EQ(t - prev, periodFromHz(100));
        }
        prev = t;
    }
}

TEST(SimDataReadyLine, AStuckLineTimesOut) {
    TwoSensorRig rig;
    ASSERT_EQ(testing::startDriver(rig.da, rig.clock), 0);
    sim::SimDataReadyLine line("a-drdy", rig.clock, rig.a);
    rig.a.setDataReadyStuck(true);
    Timestamp t{};
    const Timestamp before = rig.clock.now();
    EXPECT_EQ(line.waitEdge(std::chrono::milliseconds(50), t), -ETIMEDOUT);
    EXPECT_EQ(rig.clock.now() - before, std::chrono::milliseconds(50));
}

TEST(SimDataReadyLine, NoEdgesBeforeTheInterruptIsEnabled) {
    TwoSensorRig rig;  // drivers not started: the chips sleep, INT1 is off
    sim::SimDataReadyLine line("a-drdy", rig.clock, rig.a);
    Timestamp t{};
    EXPECT_EQ(line.readEdge(t), -EAGAIN);
    EXPECT_EQ(line.waitEdge(std::chrono::milliseconds(20), t), -ETIMEDOUT);
}

TEST(SimDataReadyWaiter, WakesForTheEarliestOfSeveralLines) {
    TwoSensorRig rig;
    ImuConfig fast;
    fast.odrHz = 1100.0 / 4;  // 275 Hz
    rig.db.setConfig(fast);
    ASSERT_EQ(testing::startDriver(rig.da, rig.clock), 0);
    ASSERT_EQ(testing::startDriver(rig.db, rig.clock), 0);
    sim::SimDataReadyLine la("a", rig.clock, rig.a);
    sim::SimDataReadyLine lb("b", rig.clock, rig.b);
    sim::SimDataReadyWaiter waiter(rig.clock);
    ASSERT_EQ(waiter.add(la), 0);
    ASSERT_EQ(waiter.add(lb), 1);
    int edgesA = 0;
    int edgesB = 0;
    const Timestamp end = rig.clock.now() + std::chrono::seconds(1);
    while (rig.clock.now() < end) {
        std::array<int, 4> ready{};
        const int n = waiter.wait(std::chrono::milliseconds(100), ready);
        ASSERT_GE(n, 1);
        for (int i = 0; i < n; ++i) {
            Timestamp t{};
            auto& line = ready[static_cast<std::size_t>(i)] == 0 ? la : lb;
            ASSERT_EQ(line.readEdge(t), 0);
            (ready[static_cast<std::size_t>(i)] == 0 ? edgesA : edgesB)++;
        }
    }
    EXPECT_NEAR(edgesA, 100, 1);
    EXPECT_NEAR(edgesB, 275, 1);
}

}  // namespace
}  // namespace caphub::hal
