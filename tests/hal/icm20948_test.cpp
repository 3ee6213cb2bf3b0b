// The ICM-20948 driver against its register-level model, over I2C and SPI.
#include "hal/drivers/icm20948.h"

#include <cmath>

#include <gtest/gtest.h>

#include "hal/drivers/icm20948_registers.h"
#include "hal/sim/sim_bus.h"
#include "rig.h"

namespace caphub::hal {
namespace {

using sim::ConstantSource;
using sim::Icm20948Model;
using sim::PhysicalInput;
using sim::SimI2cBus;
using testing::startDriver;

constexpr double kDegToRad = kPi / 180.0;

struct IcmRig {
    SimulatedClock clock{timestampFromNs(1'000'000'000)};
    SimI2cBus bus{"sim-i2c", clock};
    Icm20948Model model;
    ConstantSource source;
    std::unique_ptr<Icm20948> driver;

    explicit IcmRig(ImuConfig config = {}) {
        model.setPhysicalSource(&source);
        bus.attach(model, 0x68);
        driver = std::make_unique<Icm20948>(std::make_unique<I2cRegisterIo>(bus, 0x68),
                                            Icm20948::Interface::I2c, "icm", config);
    }

    // Advances to the next sample instant and reads it.
    ImuSample next() {
        const auto t = model.nextDataReady(clock.now());
        EXPECT_TRUE(t.has_value());
        clock.advanceTo(*t);
        ImuSample s;
        EXPECT_EQ(driver->readSample(*t, s), 0);
        return s;
    }
};

TEST(Icm20948, ProbesItsWhoAmI) {
    IcmRig rig;
    EXPECT_EQ(rig.driver->probe(), 0);
}

TEST(Icm20948, ProbeFailsWithEnodevOnAnotherChip) {
    SimulatedClock clock;
    SimI2cBus bus("sim", clock);
    sim::Lsm6dsoxModel other;  // WHO_AM_I at 0x0F, 0x00 reads 0
    bus.attach(other, 0x68);
    Icm20948 driver(std::make_unique<I2cRegisterIo>(bus, 0x68), Icm20948::Interface::I2c, "x", {});
    EXPECT_EQ(driver.probe(), -ENODEV);
}

TEST(Icm20948, ProbeOfAnAbsentChipIsANack) {
    SimulatedClock clock;
    SimI2cBus bus("sim", clock);
    Icm20948 driver(std::make_unique<I2cRegisterIo>(bus, 0x68), Icm20948::Interface::I2c, "x", {});
    EXPECT_EQ(driver.probe(), -ENXIO);
}

TEST(Icm20948, StartsAndAppliesItsConfiguration) {
    ImuConfig config;
    config.odrHz = 100;
    config.accelRangeG = 8;
    config.gyroRangeDps = 1000;
    IcmRig rig(config);
    ASSERT_EQ(startDriver(*rig.driver, rig.clock), 0);
    using namespace icm20948;
    EXPECT_EQ(rig.model.peek(2, static_cast<int>(Bank2::GYRO_SMPLRT_DIV)), 10);         // 1100/11
    EXPECT_EQ((rig.model.peek(2, static_cast<int>(Bank2::ACCEL_CONFIG)) >> 1) & 3, 2);  // 8 g
    EXPECT_EQ((rig.model.peek(2, static_cast<int>(Bank2::GYRO_CONFIG_1)) >> 1) & 3, 2);
    EXPECT_EQ(rig.model.peek(0, static_cast<int>(Bank0::PWR_MGMT_1)) & pwr_mgmt_1::SLEEP, 0);
    EXPECT_EQ(rig.model.bank(), 0);  // left in bank 0
    EXPECT_EQ(rig.model.samplePeriod(), periodFromHz(100));
    EXPECT_EQ(rig.driver->counters().starts.load(), 1u);
}

TEST(Icm20948, EachFullScaleRoundTripsWithinOneLsb) {
    for (int fs = 0; fs < 4; ++fs) {
        ImuConfig config;
        config.accelRangeG = icm20948::kAccelRangeG[fs];
        config.gyroRangeDps = icm20948::kGyroRangeDps[fs];
        IcmRig rig(config);
        ASSERT_EQ(startDriver(*rig.driver, rig.clock), 0);
        // 70% of full scale on each axis, with signs.
        PhysicalInput in;
        const double acc = 0.7 * config.accelRangeG * kStandardGravity;
        const double gyr = 0.7 * config.gyroRangeDps * kDegToRad;
        in.accMps2 = {acc, -acc / 2, acc / 3};
        in.gyrRadps = {-gyr, gyr / 2, gyr / 5};
        in.magUt = {20, -35, 41};
        rig.source.set(in);
        rig.next();
        rig.clock.advanceBy(std::chrono::milliseconds(15));  // a fresh magnetometer sample
        const ImuSample s = rig.next();
        const double accLsb = kStandardGravity / icm20948::kAccelLsbPerG[fs];
        const double gyrLsb = kDegToRad / icm20948::kGyroLsbPerDps[fs];
        for (int i = 0; i < 3; ++i) {
            EXPECT_NEAR(s.accMps2[i], in.accMps2[i], accLsb) << "fs " << fs << " axis " << i;
            EXPECT_NEAR(s.gyrRadps[i], in.gyrRadps[i], gyrLsb) << "fs " << fs << " axis " << i;
        }
        ASSERT_TRUE(s.flags & ImuSample::kMagFresh) << "fs " << fs;
        for (int i = 0; i < 3; ++i) {
            EXPECT_NEAR(s.magUt[i], in.magUt[i], 0.15) << "axis " << i;  // AK09916: 0.15 uT/LSB
        }
        EXPECT_FALSE(s.flags & (ImuSample::kAccSaturated | ImuSample::kGyrSaturated));
    }
}

TEST(Icm20948, ValuesBeyondFullScaleSaturateAndAreFlagged) {
    ImuConfig config;
    config.accelRangeG = 2;
    IcmRig rig(config);
    ASSERT_EQ(startDriver(*rig.driver, rig.clock), 0);
    PhysicalInput in;
    in.accMps2 = {0, 0, 5 * kStandardGravity};
    rig.source.set(in);
    const ImuSample s = rig.next();
    EXPECT_NEAR(s.accMps2.z(), 2 * kStandardGravity, 0.01);
    EXPECT_TRUE(s.flags & ImuSample::kAccSaturated);
}

TEST(Icm20948, TemperatureIsScaled) {
    IcmRig rig;
    ASSERT_EQ(startDriver(*rig.driver, rig.clock), 0);
    PhysicalInput in;
    in.temperatureC = 31.5;
    rig.source.set(in);
    EXPECT_NEAR(rig.next().temperatureC, 31.5, 1.0 / 333.87);
}

TEST(Icm20948, DataReadyStatusBitIsSetBySamplesAndClearedByReading) {
    IcmRig rig;
    ASSERT_EQ(startDriver(*rig.driver, rig.clock), 0);
    rig.clock.advanceTo(*rig.model.nextDataReady(rig.clock.now()));
    bool ready = false;
    ASSERT_EQ(rig.driver->dataReady(ready), 0);
    EXPECT_TRUE(ready);
    ASSERT_EQ(rig.driver->dataReady(ready), 0);
    EXPECT_FALSE(ready);
}

TEST(Icm20948, AChipResetMidRunIsDetectedAndReconfigured) {
    IcmRig rig;
    ASSERT_EQ(startDriver(*rig.driver, rig.clock), 0);
    rig.next();
    rig.model.resetToDefaults();  // a brown-out: asleep, default registers
    int restarted = 0;
    for (std::size_t i = 0; i < rig.driver->settings().size() && restarted == 0; ++i) {
        restarted = rig.driver->checkNextSetting(rig.clock.now());
    }
    EXPECT_EQ(restarted, 1);
    EXPECT_EQ(rig.driver->counters().resetsDetected.load(), 1u);
    ASSERT_EQ(startDriver(*rig.driver, rig.clock), 0);
    EXPECT_EQ(rig.driver->counters().starts.load(), 2u);
    PhysicalInput in;
    in.accMps2 = {1, 2, 3};
    rig.source.set(in);
    EXPECT_NEAR(rig.next().accMps2.y(), 2.0, 0.01);
}

TEST(Icm20948, PeriodicCheckPassesOnAHealthyChip) {
    IcmRig rig;
    ASSERT_EQ(startDriver(*rig.driver, rig.clock), 0);
    for (int i = 0; i < 50; ++i) {
        EXPECT_EQ(rig.driver->checkNextSetting(rig.clock.now()), 0);
    }
    EXPECT_EQ(rig.driver->counters().resetsDetected.load(), 0u);
}

TEST(Icm20948, StartUpRetriesWhileTheChipNacks) {
    IcmRig rig;
    rig.model.nackUntil(rig.clock.now() + std::chrono::milliseconds(250));
    EXPECT_EQ(startDriver(*rig.driver, rig.clock), 0);
    EXPECT_GE(rig.driver->counters().readErrors.load(), 1u);
    EXPECT_EQ(rig.driver->state(), ImuDriver::State::Running);
}

TEST(Icm20948, WorksOverSpi) {
    SimulatedClock clock(timestampFromNs(5'000'000));
    Icm20948Model model;
    ConstantSource source;
    model.setPhysicalSource(&source);
    sim::SimSpiBus spi("sim-spi0.0", clock, model);
    Icm20948 driver(std::make_unique<SpiRegisterIo>(spi, icm20948::kSpiRead),
                    Icm20948::Interface::Spi, "icm-spi", {});
    ASSERT_EQ(startDriver(driver, clock), 0);
    EXPECT_TRUE(model.peek(0, static_cast<int>(icm20948::Bank0::USER_CTRL)) &
                icm20948::user_ctrl::I2C_IF_DIS);
    PhysicalInput in;
    in.gyrRadps = {0.5, -1.0, 2.0};
    source.set(in);
    const Timestamp t = *model.nextDataReady(clock.now());
    clock.advanceTo(t);
    ImuSample s;
    ASSERT_EQ(driver.readSample(t, s), 0);
    EXPECT_NEAR(s.gyrRadps.z(), 2.0, kDegToRad / 16.4);
    EXPECT_EQ(spi.counters().errors.load(), 0u);
}

TEST(Icm20948, OneSampleIsOneBusTransaction) {
    IcmRig rig;
    ASSERT_EQ(startDriver(*rig.driver, rig.clock), 0);
    const auto before = snapshot(rig.bus.counters());
    rig.next();
    const auto after = snapshot(rig.bus.counters());
    EXPECT_EQ(after.transactions - before.transactions, 1u);
    EXPECT_EQ(after.bytes - before.bytes, 3u + 23u);
}

TEST(Icm20948, DividersAndFiltersFollowTheRate) {
    EXPECT_EQ(Icm20948::gyroDivider(1100), 0);
    EXPECT_EQ(Icm20948::gyroDivider(50), 21);
    EXPECT_EQ(Icm20948::accelDivider(100), 10);  // 1125/11 = 102.3 Hz, the nearest
    // The filter's bandwidth stays below half the rate.
    EXPECT_EQ(Icm20948::dlpfConfigFor(100, true), 4);   // 23.9 Hz
    EXPECT_EQ(Icm20948::dlpfConfigFor(1100, true), 0);  // 196.6 Hz
}

}  // namespace
}  // namespace caphub::hal
