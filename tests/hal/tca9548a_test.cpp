// The TCA9548A decorator: channels are selected once per change, devices behind it are reached
// as on a plain bus, and failures of the switch are counted as the switch's.
#include "hal/tca9548a.h"

#include <gtest/gtest.h>

#include "hal/drivers/icm20948.h"
#include "hal/sim/sim_bus.h"
#include "rig.h"

namespace caphub::hal {
namespace {

struct MuxRig {
    SimulatedClock clock{timestampFromNs(1'000'000'000)};
    sim::SimI2cBus bus{"sim-i2c-1", clock};
    sim::Tca9548aModel muxModel;
    std::array<sim::Icm20948Model, 3> chips;
    Tca9548a mux{bus, 0x70, "mux0"};

    MuxRig() {
        bus.attach(muxModel, 0x70);
        // Three ICM-20948 at the same address, on channels 0, 1 and 5.
        bus.attach(chips[0], 0x68, &muxModel, 0);
        bus.attach(chips[1], 0x68, &muxModel, 1);
        bus.attach(chips[2], 0x68, &muxModel, 5);
    }
};

TEST(Tca9548a, SelectsAChannelOnlyWhenItChanges) {
    MuxRig rig;
    std::uint8_t who = 0;
    for (int i = 0; i < 10; ++i) {
        ASSERT_EQ(rig.mux.channel(1).readByteData(0x68, 0x00, who), 0);
    }
    EXPECT_EQ(who, 0xEA);
    EXPECT_EQ(rig.muxModel.controlWrites(), 1u);
    EXPECT_EQ(rig.muxModel.control(), 1u << 1);
    ASSERT_EQ(rig.mux.channel(5).readByteData(0x68, 0x00, who), 0);
    ASSERT_EQ(rig.mux.channel(5).readByteData(0x68, 0x00, who), 0);
    ASSERT_EQ(rig.mux.channel(0).readByteData(0x68, 0x00, who), 0);
    EXPECT_EQ(rig.muxModel.controlWrites(), 3u);
    EXPECT_EQ(rig.mux.selectWrites(), 3u);
}

TEST(Tca9548a, DriversBehindTheMuxReachTheirOwnChip) {
    MuxRig rig;
    std::vector<std::unique_ptr<Icm20948>> drivers;
    for (int ch : {0, 1, 5}) {
        drivers.push_back(std::make_unique<Icm20948>(
            std::make_unique<I2cRegisterIo>(rig.mux.channel(ch), 0x68), Icm20948::Interface::I2c,
            "icm" + std::to_string(ch), ImuConfig{}));
    }
    for (auto& d : drivers) {
        ASSERT_EQ(testing::startDriver(*d, rig.clock), 0) << d->name();
    }
    for (const auto& chip : rig.chips) {
        EXPECT_EQ(chip.samplePeriod(), periodFromHz(100));  // each was configured
    }
}

TEST(Tca9548a, AnUnopenedChannelLeavesItsDevicesUnreachable) {
    MuxRig rig;
    std::uint8_t who = 0;
    EXPECT_EQ(rig.mux.channel(3).readByteData(0x68, 0x00, who), -ENXIO);  // nothing on ch 3
}

TEST(Tca9548a, MuxErrorsAreCountedAsTheMuxs) {
    MuxRig rig;
    sim::SimI2cBus emptyBus("empty", rig.clock);  // no switch answers at 0x70
    Tca9548a missing(emptyBus, 0x70, "mux9");
    std::uint8_t v = 0;
    EXPECT_EQ(missing.channel(2).readByteData(0x68, 0x00, v), -ENXIO);
    EXPECT_EQ(missing.selectErrors(), 1u);
    EXPECT_EQ(missing.lastSelectError(), -ENXIO);
    EXPECT_EQ(missing.selectedChannel(), -2);  // unknown after a failure: re-selected next time
    EXPECT_NE(missing.channel(2).name().find("mux9 channel 2"), std::string::npos);
    // A device error behind a working mux is not the mux's.
    EXPECT_EQ(rig.mux.channel(3).readByteData(0x68, 0x00, v), -ENXIO);
    EXPECT_EQ(rig.mux.selectErrors(), 0u);
    EXPECT_EQ(rig.mux.lastSelectError(), 0);
}

TEST(Tca9548a, SelectingOnOneMuxClosesItsSiblings) {
    SimulatedClock clock;
    sim::SimI2cBus bus("sim", clock);
    sim::Tca9548aModel ma;
    sim::Tca9548aModel mb;
    sim::Icm20948Model a;
    sim::Icm20948Model b;
    bus.attach(ma, 0x70);
    bus.attach(mb, 0x71);
    bus.attach(a, 0x68, &ma, 0);
    bus.attach(b, 0x68, &mb, 0);
    Tca9548a muxA(bus, 0x70, "a");
    Tca9548a muxB(bus, 0x71, "b");
    muxA.setSiblings({&muxB});
    muxB.setSiblings({&muxA});
    std::uint8_t who = 0;
    ASSERT_EQ(muxA.channel(0).readByteData(0x68, 0, who), 0);
    ASSERT_EQ(muxB.channel(0).readByteData(0x68, 0, who), 0);  // would collide without closing A
    EXPECT_EQ(ma.control(), 0u);
    EXPECT_EQ(mb.control(), 1u);
}

}  // namespace
}  // namespace caphub::hal
