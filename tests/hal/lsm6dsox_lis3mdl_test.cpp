// The LSM6DSOX + LIS3MDL driver against the two chip models, over I2C and SPI.
#include "hal/drivers/lsm6dsox_lis3mdl.h"

#include <gtest/gtest.h>

#include "hal/drivers/lis3mdl_registers.h"
#include "hal/drivers/lsm6dsox_registers.h"
#include "hal/sim/sim_bus.h"
#include "rig.h"

namespace caphub::hal {
namespace {

using sim::ConstantSource;
using sim::PhysicalInput;
using testing::startDriver;

constexpr double kDegToRad = kPi / 180.0;

struct LsmRig {
    SimulatedClock clock{timestampFromNs(1'000'000'000)};
    sim::SimI2cBus bus{"sim-i2c", clock};
    sim::Lsm6dsoxModel imu;
    sim::Lis3mdlModel mag;
    ConstantSource source;
    std::unique_ptr<Lsm6dsoxLis3mdl> driver;

    explicit LsmRig(ImuConfig config = defaultConfig()) {
        imu.setSource(&source);
        mag.setSource(&source);
        bus.attach(imu, 0x6A);
        bus.attach(mag, 0x1C);
        driver = std::make_unique<Lsm6dsoxLis3mdl>(
            std::make_unique<I2cRegisterIo>(bus, 0x6A),
            std::make_unique<I2cRegisterIo>(bus, 0x1C, lis3mdl::kI2cAutoIncrement), "lsm", config);
    }

    static ImuConfig defaultConfig() {
        ImuConfig c;
        c.odrHz = 104;
        c.magOdrHz = 80;
        return c;
    }

    ImuSample next() {
        const auto t = imu.nextDataReady(clock.now());
        EXPECT_TRUE(t.has_value());
        clock.advanceTo(*t);
        ImuSample s;
        EXPECT_EQ(driver->readSample(*t, s), 0);
        return s;
    }
};

TEST(Lsm6dsoxLis3mdl, ProbesBothDies) {
    LsmRig rig;
    EXPECT_EQ(rig.driver->probe(), 0);
}

TEST(Lsm6dsoxLis3mdl, ProbeFailsWithEnodevWhenTheMagnetometerIsAnotherChip) {
    SimulatedClock clock;
    sim::SimI2cBus bus("sim", clock);
    sim::Lsm6dsoxModel imu;
    sim::Lsm6dsoxModel notAMag;  // answers 0x6C at WHO_AM_I, not 0x3D
    bus.attach(imu, 0x6A);
    bus.attach(notAMag, 0x1C);
    Lsm6dsoxLis3mdl driver(std::make_unique<I2cRegisterIo>(bus, 0x6A),
                           std::make_unique<I2cRegisterIo>(bus, 0x1C), "x",
                           LsmRig::defaultConfig());
    EXPECT_EQ(driver.probe(), -ENODEV);
}

TEST(Lsm6dsoxLis3mdl, StartsAndAppliesItsConfiguration) {
    LsmRig rig;
    ASSERT_EQ(startDriver(*rig.driver, rig.clock), 0);
    using namespace lsm6dsox;
    EXPECT_EQ(rig.imu.peek(static_cast<int>(Register::CTRL2_G)) >> 4, 4);  // 104 Hz
    EXPECT_TRUE(rig.imu.peek(static_cast<int>(Register::CTRL3_C)) & ctrl3_c::BDU);
    EXPECT_EQ(rig.imu.samplePeriod(), periodFromHz(104));
    EXPECT_EQ(rig.mag.samplePeriod(), periodFromHz(80));
}

TEST(Lsm6dsoxLis3mdl, EachFullScaleRoundTripsWithinOneLsb) {
    for (int code = 0; code < 4; ++code) {
        ImuConfig config = LsmRig::defaultConfig();
        config.accelRangeG = lsm6dsox::kAccelRangeByCode[code];
        config.gyroRangeDps = lsm6dsox::kGyroRangeByCode[code];
        LsmRig rig(config);
        ASSERT_EQ(startDriver(*rig.driver, rig.clock), 0);
        PhysicalInput in;
        const double acc = 0.7 * config.accelRangeG * kStandardGravity;
        const double gyr = 0.7 * config.gyroRangeDps * kDegToRad;
        in.accMps2 = {acc, -acc / 2, acc / 3};
        in.gyrRadps = {-gyr, gyr / 2, gyr / 5};
        in.magUt = {20, -35, 41};
        rig.source.set(in);
        rig.clock.advanceBy(std::chrono::milliseconds(20));  // past the last magnetometer sample
        ImuSample s = rig.next();
        for (int i = 0; i < 4 && !(s.flags & ImuSample::kMagFresh); ++i) {
            s = rig.next();
        }
        const double accLsb = lsm6dsox::kAccelMgPerLsbByCode[code] * 1e-3 * kStandardGravity;
        const double gyrLsb = lsm6dsox::kGyroMdpsPerLsbByCode[code] * 1e-3 * kDegToRad;
        for (int i = 0; i < 3; ++i) {
            EXPECT_NEAR(s.accMps2[i], in.accMps2[i], accLsb) << "code " << code;
            EXPECT_NEAR(s.gyrRadps[i], in.gyrRadps[i], gyrLsb) << "code " << code;
        }
        ASSERT_TRUE(s.flags & ImuSample::kMagFresh);
        for (int i = 0; i < 3; ++i) {
            EXPECT_NEAR(s.magUt[i], in.magUt[i], 100.0 / 6842);  // +-4 gauss: 1/6842 gauss/LSB
        }
    }
}

TEST(Lsm6dsoxLis3mdl, The125DpsRangeWorks) {
    ImuConfig config = LsmRig::defaultConfig();
    config.gyroRangeDps = 125;
    LsmRig rig(config);
    ASSERT_EQ(startDriver(*rig.driver, rig.clock), 0);
    PhysicalInput in;
    in.gyrRadps = {1.5, 0, -1};  // 86 dps
    rig.source.set(in);
    EXPECT_NEAR(rig.next().gyrRadps.x(), 1.5, 4.375e-3 * kDegToRad);
}

TEST(Lsm6dsoxLis3mdl, MagnetometerIsReadAtItsOwnRate) {
    LsmRig rig;
    ASSERT_EQ(startDriver(*rig.driver, rig.clock), 0);
    int fresh = 0;
    const int samples = 104;  // one second
    const auto before = snapshot(rig.bus.counters());
    for (int i = 0; i < samples; ++i) {
        fresh += (rig.next().flags & ImuSample::kMagFresh) != 0;
    }
    const auto after = snapshot(rig.bus.counters());
    // 80 Hz magnetometer sampled from a 104 Hz stream: 80 +- a couple of fresh readings.
    EXPECT_NEAR(fresh, 80, 3);
    // 104 Hz is below twice 80 Hz: the magnetometer burst follows every sample.
    EXPECT_EQ(after.transactions - before.transactions, static_cast<std::uint64_t>(2 * samples));
}

TEST(Lsm6dsoxLis3mdl, AMagnetometerResetIsDetected) {
    LsmRig rig;
    ASSERT_EQ(startDriver(*rig.driver, rig.clock), 0);
    rig.mag.resetToDefaults();
    int restarted = 0;
    for (std::size_t i = 0; i < 2 * rig.driver->settings().size() && restarted == 0; ++i) {
        restarted = rig.driver->checkNextSetting(rig.clock.now());
    }
    EXPECT_EQ(restarted, 1);
    ASSERT_EQ(startDriver(*rig.driver, rig.clock), 0);
    EXPECT_EQ(rig.mag.samplePeriod(), periodFromHz(80));
}

TEST(Lsm6dsoxLis3mdl, WorksOverSpiWithTwoChipSelects) {
    SimulatedClock clock(timestampFromNs(1'000'000));
    sim::Lsm6dsoxModel imu;
    sim::Lis3mdlModel mag;
    ConstantSource source;
    imu.setSource(&source);
    mag.setSource(&source);
    sim::SimSpiBus cs0("spi0.0", clock, imu);
    sim::SimSpiBus cs1("spi0.1", clock, mag);
    Lsm6dsoxLis3mdl driver(
        std::make_unique<SpiRegisterIo>(cs0, lsm6dsox::kSpiRead),
        std::make_unique<SpiRegisterIo>(cs1, lis3mdl::kSpiRead, lis3mdl::kSpiAutoIncrement),
        "lsm-spi", LsmRig::defaultConfig());
    ASSERT_EQ(startDriver(driver, clock), 0);
    PhysicalInput in;
    in.magUt = {-30, 12, 44};
    source.set(in);
    clock.advanceBy(std::chrono::milliseconds(20));  // past the last magnetometer sample
    ImuSample s;
    for (int i = 0; i < 5 && !(s.flags & ImuSample::kMagFresh); ++i) {
        const Timestamp t = *imu.nextDataReady(clock.now());
        clock.advanceTo(t);
        ASSERT_EQ(driver.readSample(t, s), 0);
    }
    ASSERT_TRUE(s.flags & ImuSample::kMagFresh);
    EXPECT_NEAR(s.magUt.z(), 44, 0.02);
}

}  // namespace
}  // namespace caphub::hal
