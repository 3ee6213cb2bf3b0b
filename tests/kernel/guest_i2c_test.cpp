// The guest program of the kernel-level test: runs the project's Linux I2C backend (LinuxI2cBus)
// on a real kernel's i2c-dev against i2c-stub's emulated ICM-20948, LSM6DSOX, LIS3MDL and
// TCA9548A, then the render library's framebuffer sink on vfb's /dev/fbN (guest_fb_checks.cpp),
// and prints every check line by line. Exit status 0 only when every check passed.
//
//   caphub-guest /dev/i2c-N /dev/fbN
//
// i2c-stub is not a chip model: it is 256 16-bit registers per address that byte and I2C-block
// transfers read and write through their low byte. So this program first writes what each chip
// shows at power-on (datasheet reset values) and a known sample into the stub, then reads them
// back: first with the backend alone, then through the project's mux and IMU drivers (probe,
// start-up, configuration read back, samples scaled to SI units). See kSections at the end.

extern "C" {
#include <i2c/smbus.h>
}
#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <fcntl.h>
#include <linux/i2c-dev.h>
#include <linux/i2c.h>
#include <sys/ioctl.h>
#include <unistd.h>

#include "hal/core/error.h"
#include "hal/drivers/ak09916_registers.h"
#include "hal/drivers/icm20948.h"
#include "hal/drivers/icm20948_registers.h"
#include "hal/drivers/lsm6dsox_lis3mdl.h"
#include "hal/drivers/register_io.h"
#include "hal/imu_sample.h"
#include "hal/linux/gpiod_line.h"
#include "hal/linux/linux_i2c_bus.h"
#include "hal/linux/unique_fd.h"
#include "hal/tca9548a.h"
#include "tests/kernel/guest_checks.h"
#include "tests/kernel/guest_fb_checks.h"

namespace {

using caphub::hal::LinuxI2cBus;

// The addresses /init gives i2c-stub (chip_addr=0x68,0x6a,0x1c,0x70).
constexpr std::uint8_t kIcm20948Address = 0x68;
constexpr std::uint8_t kLsm6dsoxAddress = 0x6a;
constexpr std::uint8_t kLis3mdlAddress = 0x1c;
constexpr std::uint8_t kTca9548aAddress = 0x70;
// An address no chip answers on (an EEPROM's, absent here).
constexpr std::uint8_t kAbsentAddress = 0x50;

std::string hex(unsigned value, int digits = 2) {
    char buf[16];
    std::snprintf(buf, sizeof buf, "0x%0*X", digits, value);
    return buf;
}

std::string hexBytes(std::span<const std::uint8_t> bytes) {
    std::string out;
    for (std::uint8_t b : bytes) {
        char buf[4];
        std::snprintf(buf, sizeof buf, "%s%02X", out.empty() ? "" : " ", b);
        out += buf;
    }
    return out;
}

using caphub::kernel_test::Checks;

struct Context {
    std::string path;
    std::unique_ptr<LinuxI2cBus> bus;  // set by the first section
    Checks checks;
};

// ---------------------------------------------------------------------------------------------
// What each chip shows: register reset values from the datasheets, and one sample.

struct RegisterValue {
    std::uint8_t reg;
    std::uint8_t value;
    const char* name;
};

// One axis of a sample: its raw count and what that count means at the configured full scale,
// in the unit the chip's sensitivity is given in.
struct AxisSample {
    std::int16_t raw;
    double physical;
};

// ICM-20948 (TDK DS-000189 rev 1.3). REG_BANK_SEL is 0x7F, bank in bits 5:4; user bank 0 holds
// WHO_AM_I and the data, user bank 2 the sensor configuration. Data registers are big-endian.
namespace icm20948 {
constexpr std::uint8_t kRegBankSel = 0x7F;
constexpr std::uint8_t kWhoAmI = 0x00;
constexpr std::uint8_t kWhoAmIValue = 0xEA;
constexpr std::uint8_t kAccelXoutH = 0x2D;  // accel X/Y/Z then gyro X/Y/Z, 12 bytes
constexpr std::array<RegisterValue, 6> kBank0Reset = {{
    {0x00, 0xEA, "WHO_AM_I"},
    {0x03, 0x00, "USER_CTRL"},
    {0x05, 0x40, "LP_CONFIG"},
    {0x06, 0x41, "PWR_MGMT_1"},  // asleep, auto clock select
    {0x07, 0x00, "PWR_MGMT_2"},
    {0x0F, 0x00, "INT_PIN_CFG"},
}};
// Bank 2's 0x00 (GYRO_SMPLRT_DIV) shares its address with bank 0's WHO_AM_I: reading 0x00 in
// bank 2 shows whether the banks are really kept apart.
constexpr std::array<RegisterValue, 3> kBank2Reset = {{
    {0x00, 0x00, "GYRO_SMPLRT_DIV"},
    {0x01, 0x01, "GYRO_CONFIG_1"},  // +-250 dps, DLPF bypassed
    {0x14, 0x01, "ACCEL_CONFIG"},   // +-2 g
}};
// At +-2 g: 16384 LSB/g; at +-250 dps: 131 LSB/(deg/s). Counts chosen to be exact.
constexpr double kAccelLsbPerG = 16384.0;
constexpr double kGyroLsbPerDps = 131.0;
constexpr std::array<AxisSample, 3> kAccelG = {{{4096, 0.25}, {-8192, -0.5}, {16384, 1.0}}};
constexpr std::array<AxisSample, 3> kGyroDps = {{{1310, 10.0}, {-6550, -50.0}, {131, 1.0}}};
}  // namespace icm20948

// LSM6DSOX (ST DS13210). Little-endian data; CTRL3_C.IF_INC (on at reset) makes block reads
// advance through the registers.
namespace lsm6dsox {
constexpr std::uint8_t kWhoAmI = 0x0F;
constexpr std::uint8_t kWhoAmIValue = 0x6C;
constexpr std::uint8_t kCtrl1Xl = 0x10;
constexpr std::uint8_t kCtrl2G = 0x11;
constexpr std::uint8_t kOutxLG = 0x22;  // gyro X/Y/Z then accel X/Y/Z, 12 bytes
constexpr std::array<RegisterValue, 5> kReset = {{
    {0x0F, 0x6C, "WHO_AM_I"},
    {0x10, 0x00, "CTRL1_XL"},  // accelerometer powered down
    {0x11, 0x00, "CTRL2_G"},   // gyroscope powered down
    {0x12, 0x04, "CTRL3_C"},   // IF_INC
    {0x1E, 0x00, "STATUS_REG"},
}};
// 104 Hz in ODR bits 7:4, +-2 g / +-250 dps in the full-scale bits.
constexpr std::uint8_t kCtrl1Xl104Hz2g = 0x40;
constexpr std::uint8_t kCtrl2G104Hz250dps = 0x40;
// Sensitivities at +-2 g and +-250 dps: 0.061 mg/LSB and 8.75 mdps/LSB. Each count is the
// nearest integer to physical / sensitivity.
constexpr double kAccelMgPerLsb = 0.061;
constexpr double kGyroMdpsPerLsb = 8.75;
constexpr std::array<AxisSample, 3> kGyroDps = {{{1143, 10.0}, {-5714, -50.0}, {114, 1.0}}};
constexpr std::array<AxisSample, 3> kAccelG = {{{4098, 0.25}, {-8197, -0.5}, {16393, 1.0}}};
}  // namespace lsm6dsox

// LIS3MDL (ST DS10540). Little-endian data. Over I2C a multi-byte read advances only when bit 7
// of the register address is set (OUT_X_L 0x28 is read as 0xA8); i2c-stub has no such rule, so
// the sample is also written at 0xA8-0xAD, where a block read addressed like that lands.
namespace lis3mdl {
constexpr std::uint8_t kWhoAmI = 0x0F;
constexpr std::uint8_t kWhoAmIValue = 0x3D;
constexpr std::uint8_t kCtrlReg3 = 0x22;
constexpr std::uint8_t kOutXL = 0x28;
constexpr std::uint8_t kAutoIncrement = 0x80;
constexpr std::array<RegisterValue, 6> kReset = {{
    {0x0F, 0x3D, "WHO_AM_I"},
    {0x20, 0x10, "CTRL_REG1"},  // 10 Hz
    {0x21, 0x00, "CTRL_REG2"},  // +-4 gauss
    {0x22, 0x03, "CTRL_REG3"},  // power-down
    {0x23, 0x00, "CTRL_REG4"},
    {0x27, 0x00, "STATUS_REG"},
}};
constexpr std::uint8_t kCtrlReg3Continuous = 0x00;
// At +-4 gauss: 6842 LSB/gauss; counts are the nearest integers.
constexpr double kLsbPerGauss = 6842.0;
constexpr std::array<AxisSample, 3> kGauss = {{{3421, 0.5}, {-1368, -0.2}, {2737, 0.4}}};
}  // namespace lis3mdl

// TCA9548A (TI SCPS207): one control register, written with send byte and read with receive
// byte, one bit per channel, 0x00 (all channels off) at power-on. i2c-stub treats send byte as
// "set the register pointer" and receive byte as "read the register at the pointer, advance";
// with register i holding i, a receive byte right after a send byte returns what was sent,
// which is what the chip does.
namespace tca9548a {
constexpr std::uint8_t kChannel3 = 1u << 3;
constexpr std::uint8_t kAllOff = 0x00;
}  // namespace tca9548a

// ---------------------------------------------------------------------------------------------
// Helpers

std::vector<std::uint8_t> encode(std::span<const AxisSample> axes, bool bigEndian) {
    std::vector<std::uint8_t> out;
    for (const auto& a : axes) {
        const auto u = static_cast<std::uint16_t>(a.raw);
        const auto lo = static_cast<std::uint8_t>(u & 0xFF);
        const auto hi = static_cast<std::uint8_t>(u >> 8);
        out.push_back(bigEndian ? hi : lo);
        out.push_back(bigEndian ? lo : hi);
    }
    return out;
}

std::int16_t decode(std::span<const std::uint8_t> bytes, std::size_t axis, bool bigEndian) {
    const std::uint8_t first = bytes[2 * axis];
    const std::uint8_t second = bytes[2 * axis + 1];
    const auto u = bigEndian ? static_cast<std::uint16_t>(first << 8 | second)
                             : static_cast<std::uint16_t>(second << 8 | first);
    return static_cast<std::int16_t>(u);
}

bool writeRegisters(Context& ctx, std::uint8_t address, std::span<const RegisterValue> regs) {
    for (const auto& r : regs) {
        if (ctx.bus->writeByteData(address, r.reg, r.value) != 0) {
            return false;
        }
    }
    return true;
}

// Reads every register with byte-data reads and compares with its expected value.
void expectRegisters(Context& ctx, const char* chip, std::uint8_t address,
                     std::span<const RegisterValue> regs, const char* where = "") {
    for (const auto& r : regs) {
        std::uint8_t got = 0;
        const int rc = ctx.bus->readByteData(address, r.reg, got);
        const std::string what = std::string(chip) + " " + r.name + where + " (reg " + hex(r.reg) +
                                 ") reads " + hex(r.value);
        if (rc != 0) {
            ctx.checks.expect(false, what, caphub::errnoText(rc));
        } else {
            ctx.checks.expect(got == r.value, what, got == r.value ? "" : "got " + hex(got));
        }
    }
}

// Decodes a block read, checks the raw counts, and scales them with the datasheet sensitivity
// (unitsPerLsb). tolerance is half a count in the physical unit: each raw count is the nearest
// integer to physical / sensitivity, so scaling it back lands within half a count.
void expectAxes(Context& ctx, const std::string& what, std::span<const std::uint8_t> bytes,
                std::size_t firstAxis, std::span<const AxisSample> axes, bool bigEndian,
                double unitsPerLsb, const char* unit) {
    const char* names[] = {"x", "y", "z"};
    const double tolerance = 0.5 * unitsPerLsb;
    for (std::size_t i = 0; i < axes.size(); ++i) {
        const std::int16_t raw = decode(bytes, firstAxis + i, bigEndian);
        const double scaled = raw * unitsPerLsb;
        char line[160];
        std::snprintf(line, sizeof line, "%s %s: raw %6d -> %+.5f %s (expected %+.5f)",
                      what.c_str(), names[i], raw, scaled, unit, axes[i].physical);
        const bool ok = raw == axes[i].raw && std::fabs(scaled - axes[i].physical) <= tolerance;
        ctx.checks.expect(ok, line, ok ? "" : "expected raw " + std::to_string(axes[i].raw));
    }
}

// ---------------------------------------------------------------------------------------------
// Sections

bool checkOpen(Context& ctx) {
    auto opened = LinuxI2cBus::open(ctx.path);
    if (!ctx.checks.expect(opened.ok(), "open " + ctx.path,
                           opened.ok() ? "" : opened.error().message)) {
        return false;
    }
    ctx.bus = std::move(opened).value();
    const std::string adapter = ctx.bus->adapterName();
    Checks::info("adapter: \"" + adapter + "\"");
    Checks::info("functions: " + hex(static_cast<unsigned>(ctx.bus->functions()), 8) + " (" +
                 LinuxI2cBus::describeFunctions(ctx.bus->functions()) + ")");
    ctx.checks.expect(adapter == "SMBus stub driver", "adapter name from sysfs is the stub's",
                      "got \"" + adapter + "\"");
    const unsigned long required = LinuxI2cBus::defaultRequiredFunctions();
    ctx.checks.expect((ctx.bus->functions() & required) == required,
                      "adapter has the functions the drivers need (" +
                          LinuxI2cBus::describeFunctions(required) + ")");

    // Plain I2C (I2C_RDWR) is what i2c-stub lacks; asking for it must fail and say so.
    const bool stubLacksPlainI2c = (ctx.bus->functions() & I2C_FUNC_I2C) == 0;
    ctx.checks.expect(stubLacksPlainI2c,
                      "adapter lacks plain I2C (I2C_FUNC_I2C), as i2c-stub does");
    auto plain = LinuxI2cBus::open(ctx.path, I2C_FUNC_I2C);
    const std::string plainName = LinuxI2cBus::describeFunctions(I2C_FUNC_I2C);
    if (plain.ok()) {
        ctx.checks.expect(false, "open requiring plain I2C fails", "it succeeded");
    } else {
        const std::string& msg = plain.error().message;
        Checks::info("message: " + msg);
        ctx.checks.expect(plain.error().code == EOPNOTSUPP,
                          "open requiring plain I2C fails with EOPNOTSUPP",
                          "got " + caphub::errnoText(plain.error().code));
        ctx.checks.expect(msg.find(ctx.path) != std::string::npos,
                          "the message names the device " + ctx.path);
        ctx.checks.expect(!plainName.empty() && msg.find(plainName) != std::string::npos,
                          "the message names the missing function",
                          "I2C_FUNC_I2C is described as \"" + plainName + "\"");
    }

    const std::string absentPath = "/dev/i2c-99";
    auto absent = LinuxI2cBus::open(absentPath);
    if (absent.ok()) {
        ctx.checks.expect(false, "open " + absentPath + " fails", "it succeeded");
    } else {
        const std::string& msg = absent.error().message;
        Checks::info("message: " + msg);
        ctx.checks.expect(absent.error().code == ENOENT,
                          "open " + absentPath + " fails with ENOENT",
                          "got " + caphub::errnoText(absent.error().code));
        ctx.checks.expect(
            msg.find(absentPath) != std::string::npos &&
                msg.find(caphub::errnoText(ENOENT)) != std::string::npos,
            "the message names the device and says \"" + caphub::errnoText(ENOENT) + "\"");
    }
    return true;
}

bool selectIcmBank(Context& ctx, int bank) {
    return ctx.bus->writeByteData(kIcm20948Address, icm20948::kRegBankSel,
                                  static_cast<std::uint8_t>(bank << 4)) == 0;
}

bool checkPreload(Context& ctx) {
    using namespace icm20948;
    bool ok = true;
    // ICM-20948: bank 2 first, then bank 0 (left selected, as after reset).
    ok = ok && selectIcmBank(ctx, 2) && writeRegisters(ctx, kIcm20948Address, kBank2Reset);
    ok = ok && selectIcmBank(ctx, 0) && writeRegisters(ctx, kIcm20948Address, kBank0Reset);
    std::vector<std::uint8_t> icmSample = encode(kAccelG, true);
    const auto gyro = encode(kGyroDps, true);
    icmSample.insert(icmSample.end(), gyro.begin(), gyro.end());
    ok = ok && ctx.bus->writeI2cBlock(kIcm20948Address, kAccelXoutH, icmSample) == 0;
    ctx.checks.expect(ok, "ICM-20948 at " + hex(kIcm20948Address) +
                              ": wrote banks 0 and 2 reset values and a sample (" +
                              hexBytes(icmSample) + ")");

    ok = writeRegisters(ctx, kLsm6dsoxAddress, lsm6dsox::kReset);
    std::vector<std::uint8_t> lsmSample = encode(lsm6dsox::kGyroDps, false);
    const auto accel = encode(lsm6dsox::kAccelG, false);
    lsmSample.insert(lsmSample.end(), accel.begin(), accel.end());
    ok = ok && ctx.bus->writeI2cBlock(kLsm6dsoxAddress, lsm6dsox::kOutxLG, lsmSample) == 0;
    ctx.checks.expect(ok, "LSM6DSOX at " + hex(kLsm6dsoxAddress) +
                              ": wrote reset values and a sample (" + hexBytes(lsmSample) + ")");

    ok = writeRegisters(ctx, kLis3mdlAddress, lis3mdl::kReset);
    const auto magSample = encode(lis3mdl::kGauss, false);
    ok = ok && ctx.bus->writeI2cBlock(kLis3mdlAddress, lis3mdl::kOutXL, magSample) == 0;
    ok = ok && ctx.bus->writeI2cBlock(kLis3mdlAddress, lis3mdl::kOutXL | lis3mdl::kAutoIncrement,
                                      magSample) == 0;
    ctx.checks.expect(ok, "LIS3MDL at " + hex(kLis3mdlAddress) +
                              ": wrote reset values and a sample (" + hexBytes(magSample) + ")");

    // TCA9548A: register i holds i (see tca9548a above), in 32-byte blocks, the longest.
    ok = true;
    for (unsigned start = 0; start < 256 && ok; start += caphub::hal::kI2cBlockMax) {
        std::array<std::uint8_t, caphub::hal::kI2cBlockMax> identity{};
        for (unsigned i = 0; i < identity.size(); ++i) {
            identity[i] = static_cast<std::uint8_t>(start + i);
        }
        ok = ctx.bus->writeI2cBlock(kTca9548aAddress, static_cast<std::uint8_t>(start), identity) ==
             0;
    }
    // The stub's register pointer back at 0: the control register reads 0x00 as at power-on.
    ok = ok && ctx.bus->writeByte(kTca9548aAddress, tca9548a::kAllOff) == 0;
    ctx.checks.expect(ok, "TCA9548A at " + hex(kTca9548aAddress) +
                              ": wrote the control register emulation (256 registers)");
    return true;
}

bool checkIcm20948Registers(Context& ctx) {
    using namespace icm20948;
    std::uint8_t who = 0;
    const int rc = ctx.bus->readByteData(kIcm20948Address, kWhoAmI, who);
    ctx.checks.expect(rc == 0 && who == kWhoAmIValue,
                      "ICM-20948 WHO_AM_I (bank 0, reg 0x00) is 0xEA (byte-data read)",
                      rc != 0 ? caphub::errnoText(rc) : "got " + hex(who));
    expectRegisters(ctx, "ICM-20948", kIcm20948Address, kBank0Reset, " [bank 0]");

    ctx.checks.expect(selectIcmBank(ctx, 2), "ICM-20948 select bank 2 (REG_BANK_SEL = 0x20)");
    expectRegisters(ctx, "ICM-20948", kIcm20948Address, kBank2Reset, " [bank 2]");
    ctx.checks.expect(selectIcmBank(ctx, 0), "ICM-20948 select bank 0 (REG_BANK_SEL = 0x00)");
    who = 0;
    const int rc0 = ctx.bus->readByteData(kIcm20948Address, kWhoAmI, who);
    ctx.checks.expect(rc0 == 0 && who == kWhoAmIValue,
                      "ICM-20948 WHO_AM_I reads 0xEA again after the bank 2 round trip",
                      rc0 != 0 ? caphub::errnoText(rc0) : "got " + hex(who));

    std::array<std::uint8_t, 12> data{};
    const int rcData = ctx.bus->readI2cBlock(kIcm20948Address, kAccelXoutH, data);
    if (ctx.checks.expectOk(rcData,
                            "ICM-20948 I2C block read of ACCEL_XOUT_H..GYRO_ZOUT_L (12 "
                            "bytes at 0x2D): " +
                                hexBytes(data))) {
        expectAxes(ctx, "ICM-20948 accel", data, 0, kAccelG, true, 1.0 / kAccelLsbPerG, "g");
        expectAxes(ctx, "ICM-20948 gyro ", data, 3, kGyroDps, true, 1.0 / kGyroLsbPerDps, "deg/s");
    }
    return true;
}

bool checkLsm6dsoxRegisters(Context& ctx) {
    using namespace lsm6dsox;
    expectRegisters(ctx, "LSM6DSOX", kLsm6dsoxAddress, kReset);
    // Configure as a driver would, and read the configuration back.
    ctx.checks.expectOk(ctx.bus->writeByteData(kLsm6dsoxAddress, kCtrl1Xl, kCtrl1Xl104Hz2g),
                        "LSM6DSOX write CTRL1_XL = 0x40 (104 Hz, +-2 g)");
    ctx.checks.expectOk(ctx.bus->writeByteData(kLsm6dsoxAddress, kCtrl2G, kCtrl2G104Hz250dps),
                        "LSM6DSOX write CTRL2_G = 0x40 (104 Hz, +-250 dps)");
    const std::array<RegisterValue, 2> configured = {{
        {kCtrl1Xl, kCtrl1Xl104Hz2g, "CTRL1_XL"},
        {kCtrl2G, kCtrl2G104Hz250dps, "CTRL2_G"},
    }};
    expectRegisters(ctx, "LSM6DSOX", kLsm6dsoxAddress, configured, " [configured]");

    std::array<std::uint8_t, 12> data{};
    const int rc = ctx.bus->readI2cBlock(kLsm6dsoxAddress, kOutxLG, data);
    if (ctx.checks.expectOk(rc,
                            "LSM6DSOX I2C block read of OUTX_L_G..OUTZ_H_A (12 bytes at "
                            "0x22): " +
                                hexBytes(data))) {
        expectAxes(ctx, "LSM6DSOX gyro ", data, 0, kGyroDps, false, kGyroMdpsPerLsb / 1000.0,
                   "deg/s");
        expectAxes(ctx, "LSM6DSOX accel", data, 3, kAccelG, false, kAccelMgPerLsb / 1000.0, "g");
    }
    return true;
}

bool checkLis3mdlRegisters(Context& ctx) {
    using namespace lis3mdl;
    expectRegisters(ctx, "LIS3MDL", kLis3mdlAddress, kReset);
    ctx.checks.expectOk(ctx.bus->writeByteData(kLis3mdlAddress, kCtrlReg3, kCtrlReg3Continuous),
                        "LIS3MDL write CTRL_REG3 = 0x00 (continuous conversion)");
    const std::array<RegisterValue, 1> configured = {
        {{kCtrlReg3, kCtrlReg3Continuous, "CTRL_REG3"}}};
    expectRegisters(ctx, "LIS3MDL", kLis3mdlAddress, configured, " [configured]");

    std::array<std::uint8_t, 6> data{};
    const int rc = ctx.bus->readI2cBlock(kLis3mdlAddress, kOutXL | kAutoIncrement, data);
    if (ctx.checks.expectOk(rc,
                            "LIS3MDL I2C block read of OUT_X_L..OUT_Z_H (6 bytes, "
                            "addressed 0xA8 for auto-increment): " +
                                hexBytes(data))) {
        expectAxes(ctx, "LIS3MDL mag", data, 0, kGauss, false, 1.0 / kLsbPerGauss, "gauss");
    }
    // The same bytes one register at a time, at their own addresses.
    std::array<std::uint8_t, 6> single{};
    bool ok = true;
    for (std::size_t i = 0; i < single.size() && ok; ++i) {
        ok = ctx.bus->readByteData(kLis3mdlAddress, static_cast<std::uint8_t>(kOutXL + i),
                                   single[i]) == 0;
    }
    ctx.checks.expect(ok && single == data,
                      "LIS3MDL byte-data reads of 0x28..0x2D give the same bytes",
                      ok ? "got " + hexBytes(single) : "a read failed");
    return true;
}

// Word data and the block limits, on a register the LSM6DSOX leaves unused (0x00, reserved).
bool checkTransferKinds(Context& ctx) {
    constexpr std::uint8_t kScratch = 0x00;
    constexpr std::uint16_t kWord = 0xBEEF;
    ctx.checks.expectOk(ctx.bus->writeWordData(kLsm6dsoxAddress, kScratch, kWord),
                        "word-data write of 0xBEEF to LSM6DSOX reg 0x00");
    std::uint16_t word = 0;
    const int rc = ctx.bus->readWordData(kLsm6dsoxAddress, kScratch, word);
    // i2c-stub keeps 16-bit registers: its word read returns the register itself.
    ctx.checks.expect(rc == 0 && word == kWord, "word-data read returns 0xBEEF",
                      rc != 0 ? caphub::errnoText(rc) : "got " + hex(word, 4));
    std::uint8_t low = 0;
    const int rcLow = ctx.bus->readByteData(kLsm6dsoxAddress, kScratch, low);
    ctx.checks.expect(rcLow == 0 && low == 0xEF,
                      "byte-data read of the same register returns its low byte 0xEF",
                      rcLow != 0 ? caphub::errnoText(rcLow) : "got " + hex(low));

    std::array<std::uint8_t, caphub::hal::kI2cBlockMax> longest{};
    const int rcLong = ctx.bus->readI2cBlock(kTca9548aAddress, 0x20, longest);
    bool identity = rcLong == 0;
    for (std::size_t i = 0; i < longest.size() && identity; ++i) {
        identity = longest[i] == 0x20 + i;
    }
    ctx.checks.expect(identity, "a 32-byte I2C block read (the SMBus maximum) returns all 32 bytes",
                      rcLong != 0 ? caphub::errnoText(rcLong) : "got " + hexBytes(longest));
    std::array<std::uint8_t, caphub::hal::kI2cBlockMax + 1> tooLong{};
    const int rcTooLong = ctx.bus->readI2cBlock(kTca9548aAddress, 0x00, tooLong);
    ctx.checks.expect(rcTooLong == -EINVAL, "a 33-byte I2C block read is refused with EINVAL",
                      "got " + std::to_string(rcTooLong));
    return true;
}

bool checkMuxControl(Context& ctx) {
    using namespace tca9548a;
    std::uint8_t control = 0xFF;
    int rc = ctx.bus->readByte(kTca9548aAddress, control);
    ctx.checks.expect(rc == 0 && control == kAllOff,
                      "TCA9548A control register reads 0x00 (all channels off) at power-on",
                      rc != 0 ? caphub::errnoText(rc) : "got " + hex(control));
    ctx.checks.expectOk(ctx.bus->writeByte(kTca9548aAddress, kChannel3),
                        "TCA9548A send byte 0x08 (channel 3 on)");
    rc = ctx.bus->readByte(kTca9548aAddress, control);
    ctx.checks.expect(rc == 0 && control == kChannel3, "TCA9548A receive byte reads 0x08 back",
                      rc != 0 ? caphub::errnoText(rc) : "got " + hex(control));
    ctx.checks.expectOk(ctx.bus->writeByte(kTca9548aAddress, kAllOff),
                        "TCA9548A send byte 0x00 (all channels off)");
    rc = ctx.bus->readByte(kTca9548aAddress, control);
    ctx.checks.expect(rc == 0 && control == kAllOff, "TCA9548A receive byte reads 0x00 back",
                      rc != 0 ? caphub::errnoText(rc) : "got " + hex(control));
    return true;
}

// The errno the kernel itself gives for a transfer to addr, through i2c-dev without the backend.
int kernelErrnoFor(const std::string& path, std::uint8_t address) {
    caphub::hal::UniqueFd fd(::open(path.c_str(), O_RDWR | O_CLOEXEC));
    if (!fd.isValid() || ::ioctl(fd.get(), I2C_SLAVE, static_cast<unsigned long>(address)) < 0) {
        return -errno;
    }
    return i2c_smbus_read_byte_data(fd.get(), 0x00) < 0 ? -errno : 0;
}

bool checkAbsentAddress(Context& ctx) {
    const auto errorsBefore = ctx.bus->counters().errors.load();
    std::uint8_t value = 0;
    const int rc = ctx.bus->readByteData(kAbsentAddress, 0x00, value);
    const int kernelRc = kernelErrnoFor(ctx.path, kAbsentAddress);
    Checks::info("the kernel's own answer (i2c-dev ioctl, no backend): " +
                 (kernelRc == 0 ? std::string("success") : caphub::errnoText(kernelRc)));
    ctx.checks.expect(rc < 0, "byte-data read at absent address " + hex(kAbsentAddress) + " fails",
                      rc == 0 ? "it succeeded" : "");
    ctx.checks.expect(rc == kernelRc && kernelRc < 0,
                      "the backend returns the kernel's errno unchanged",
                      "backend " + std::to_string(rc) + ", kernel " + std::to_string(kernelRc));
    // Hardware adapters report a missing address ACK as ENXIO; i2c-stub reports an address it
    // does not emulate as ENODEV. Either is "nobody is there", anything else is a different fault.
    ctx.checks.expect(rc == -ENXIO || rc == -ENODEV,
                      "the errno says no device answers (ENXIO or ENODEV)",
                      "got " + caphub::errnoText(rc));
    const auto error =
        caphub::errnoError(rc, "no chip answers at " + hex(kAbsentAddress) + " on " + ctx.path +
                                   " (\"" + ctx.bus->adapterName() + "\")");
    Checks::info("message: " + error.message);
    ctx.checks.expect(error.message.find(caphub::errnoText(rc)) != std::string::npos &&
                          error.message.find(ctx.path) != std::string::npos,
                      "the message names the bus and the kernel's error text");
    ctx.checks.expect(ctx.bus->counters().errors.load() == errorsBefore + 1,
                      "the bus counts the failed transfer as one error");
    return true;
}

// The project's mux decorator (hal/tca9548a.h) on the kernel's bus: a channel's transfers write
// the control register first, once per change of channel. i2c-stub does not route: every chip
// answers whatever the control register holds, so only the mux's own writes are checked here.
bool checkMuxDriver(Context& ctx) {
    caphub::hal::Tca9548a mux(*ctx.bus, kTca9548aAddress, "mux0");
    const auto writesBefore = mux.selectWrites();
    std::uint8_t who = 0;
    int rc = mux.channel(2).readByteData(kLsm6dsoxAddress, lsm6dsox::kWhoAmI, who);
    ctx.checks.expect(rc == 0 && who == lsm6dsox::kWhoAmIValue,
                      "LSM6DSOX WHO_AM_I reads 0x6C through mux0 channel 2",
                      rc != 0 ? caphub::errnoText(rc) : "got " + hex(who));
    rc = mux.channel(2).readByteData(kLis3mdlAddress, lis3mdl::kWhoAmI, who);
    ctx.checks.expect(rc == 0 && who == lis3mdl::kWhoAmIValue,
                      "LIS3MDL WHO_AM_I reads 0x3D through mux0 channel 2",
                      rc != 0 ? caphub::errnoText(rc) : "got " + hex(who));
    ctx.checks.expect(mux.selectWrites() == writesBefore + 1 && mux.selectedChannel() == 2,
                      "two transfers on channel 2 wrote the control register once",
                      std::to_string(mux.selectWrites() - writesBefore) + " writes, channel " +
                          std::to_string(mux.selectedChannel()));
    std::uint8_t control = 0;
    rc = ctx.bus->readByte(kTca9548aAddress, control);
    ctx.checks.expect(rc == 0 && control == 1u << 2, "the control register holds 0x04 (channel 2)",
                      rc != 0 ? caphub::errnoText(rc) : "got " + hex(control));
    rc = mux.channel(5).readByteData(kIcm20948Address, icm20948::kWhoAmI, who);
    ctx.checks.expect(rc == 0 && who == icm20948::kWhoAmIValue,
                      "ICM-20948 WHO_AM_I reads 0xEA through mux0 channel 5",
                      rc != 0 ? caphub::errnoText(rc) : "got " + hex(who));
    rc = ctx.bus->readByte(kTca9548aAddress, control);
    ctx.checks.expect(rc == 0 && control == 1u << 5, "the control register holds 0x20 (channel 5)",
                      rc != 0 ? caphub::errnoText(rc) : "got " + hex(control));
    ctx.checks.expectOk(mux.deselect(), "mux0 deselect");
    rc = ctx.bus->readByte(kTca9548aAddress, control);
    ctx.checks.expect(rc == 0 && control == 0x00, "the control register holds 0x00 (none open)",
                      rc != 0 ? caphub::errnoText(rc) : "got " + hex(control));

    // A switch that is not there: the channel's transfer fails with the switch's error.
    caphub::hal::Tca9548a missing(*ctx.bus, kAbsentAddress, "mux1");
    rc = missing.channel(0).readByteData(kLsm6dsoxAddress, lsm6dsox::kWhoAmI, who);
    ctx.checks.expect(rc < 0 && rc == missing.lastSelectError() && missing.selectErrors() == 1,
                      "a transfer behind an absent switch (0x50) fails with the switch's error",
                      "rc " + std::to_string(rc) + ", lastSelectError " +
                          std::to_string(missing.lastSelectError()));
    Checks::info("mux1 (0x50): " + caphub::errnoText(rc));
    return true;
}

// The Linux data-ready line (hal/linux/gpiod_line.h) on its error path: Debian's kernel has no
// gpio-sim, so the guest has no GPIO chip at all and only the failure can be checked.
bool checkGpiodErrors(Context& ctx) {
    constexpr int kChip = 99;
    auto line = caphub::hal::GpiodDataReadyLine::open(kChip, 0, "caphub-kernel-test");
    if (line.ok()) {
        ctx.checks.expect(false, "opening gpiochip99 line 0 fails", "it succeeded");
        return true;
    }
    const auto& error = line.error();
    Checks::info("message: " + error.message);
    ctx.checks.expect(error.code == ENOENT, "opening gpiochip99 line 0 fails with ENOENT",
                      "got " + caphub::errnoText(error.code));
    ctx.checks.expect(error.message.find("gpiochip99") != std::string::npos &&
                          error.message.find(caphub::errnoText(ENOENT)) != std::string::npos,
                      "the message names the chip and says \"" + caphub::errnoText(ENOENT) + "\"");
    return true;
}

// ---------------------------------------------------------------------------------------------
// Driver level: the project's drivers (hal/drivers/) through I2cRegisterIo on the kernel's bus.

// Start-up runs on the driver's own schedule; the stub needs no real waiting, so time is
// simulated: each call is made at the time the driver asked for.
int startDriver(caphub::hal::ImuDriver& driver) {
    caphub::Timestamp now{};
    int rc = -EAGAIN;
    for (int step = 0; step < 8 && rc == -EAGAIN; ++step) {
        rc = driver.service(now);
        now = std::max(now, driver.nextServiceTime());
    }
    return rc;
}

// Every entry of the driver's configuration table, read back over the bus by the test itself.
void expectSettingsHeld(Context& ctx, const caphub::hal::ImuDriver& driver,
                        int (*readBack)(Context&, const caphub::hal::RegisterSetting&,
                                        std::uint8_t&)) {
    int held = 0;
    std::string firstBad;
    for (const auto& setting : driver.settings()) {
        std::uint8_t value = 0;
        if (readBack(ctx, setting, value) == 0 && setting.matches(value)) {
            ++held;
        } else if (firstBad.empty()) {
            firstBad = "space " + std::to_string(setting.space) + " reg " + hex(setting.reg) +
                       " = " + hex(value);
        }
    }
    const auto total = static_cast<int>(driver.settings().size());
    ctx.checks.expect(total > 0 && held == total,
                      driver.name() + ": all " + std::to_string(total) +
                          " configuration registers read back as set",
                      firstBad.empty() ? "empty table" : "first mismatch: " + firstBad);
}

// Each axis of a scaled sample against the physical value the raw count stands for. tolerance
// covers the count's rounding (half a count) and float's 24-bit mantissa (< 1e-5 of values
// below 100 in these units).
void expectVector(Context& ctx, const std::string& what, const Eigen::Vector3f& got,
                  const std::array<double, 3>& expected, double halfCount, const char* unit) {
    const char* names[] = {"x", "y", "z"};
    for (int i = 0; i < 3; ++i) {
        const double tolerance =
            halfCount + 1e-5 * std::fabs(expected[static_cast<std::size_t>(i)]);
        char line[160];
        std::snprintf(line, sizeof line, "%s %s = %+.5f %s (expected %+.5f)", what.c_str(),
                      names[i], static_cast<double>(got[i]), unit,
                      expected[static_cast<std::size_t>(i)]);
        ctx.checks.expect(std::fabs(static_cast<double>(got[i]) -
                                    expected[static_cast<std::size_t>(i)]) <= tolerance,
                          line);
    }
}

constexpr double kG = 9.80665;  // m/s^2, the datasheets' g
constexpr double kRadPerDeg = 3.14159265358979323846 / 180.0;

int readIcmSetting(Context& ctx, const caphub::hal::RegisterSetting& setting, std::uint8_t& value) {
    if (!selectIcmBank(ctx, setting.space)) {
        return -EIO;
    }
    const int rc = ctx.bus->readByteData(kIcm20948Address, setting.reg, value);
    return selectIcmBank(ctx, 0) ? rc : -EIO;
}

bool checkIcm20948Driver(Context& ctx) {
    namespace ak = caphub::hal::ak09916;
    using namespace caphub::hal::icm20948;
    // What the auxiliary I2C master would show: the stub cannot run it, so its slave-4 transfer
    // is preloaded as done, with the AK09916's WIA2 (0x09) as the byte read; the master's copy
    // of the magnetometer block (ST1 with DRDY, x/y/z, TMPS, ST2) sits in EXT_SLV_SENS_DATA.
    constexpr std::array<std::int16_t, 3> kMagRaw = {100, -200, 300};  // 0.15 uT/LSB
    std::vector<std::uint8_t> magBlock = {ak::ST1_DRDY};
    for (std::int16_t v : kMagRaw) {
        magBlock.push_back(static_cast<std::uint8_t>(static_cast<std::uint16_t>(v) & 0xFF));
        magBlock.push_back(static_cast<std::uint8_t>(static_cast<std::uint16_t>(v) >> 8));
    }
    magBlock.push_back(0x00);                                   // TMPS
    magBlock.push_back(0x00);                                   // ST2: no overflow
    const std::array<std::uint8_t, 2> tempZero = {0x00, 0x00};  // 21 degC
    bool ok =
        selectIcmBank(ctx, 3) &&
        ctx.bus->writeByteData(kIcm20948Address, static_cast<std::uint8_t>(Bank3::I2C_SLV4_DI),
                               ak::kDeviceId) == 0;
    ok = ok && selectIcmBank(ctx, 0) &&
         ctx.bus->writeByteData(kIcm20948Address, static_cast<std::uint8_t>(Bank0::I2C_MST_STATUS),
                                I2C_SLV4_DONE) == 0 &&
         ctx.bus->writeByteData(kIcm20948Address, static_cast<std::uint8_t>(Bank0::INT_STATUS_1),
                                RAW_DATA_0_RDY) == 0 &&
         ctx.bus->writeI2cBlock(kIcm20948Address, static_cast<std::uint8_t>(Bank0::TEMP_OUT_H),
                                tempZero) == 0 &&
         ctx.bus->writeI2cBlock(kIcm20948Address,
                                static_cast<std::uint8_t>(Bank0::EXT_SLV_SENS_DATA_00),
                                magBlock) == 0;
    ctx.checks.expect(ok,
                      "preload: auxiliary master done, WIA2 0x09, data ready, magnetometer "
                      "block " +
                          hexBytes(magBlock));

    caphub::hal::ImuConfig config;
    config.odrHz = 100;
    config.magOdrHz = 100;
    config.accelRangeG = 2;
    config.gyroRangeDps = 250;
    caphub::hal::Icm20948 icm(
        std::make_unique<caphub::hal::I2cRegisterIo>(*ctx.bus, kIcm20948Address),
        caphub::hal::Icm20948::Interface::I2c, "icm20948@0x68", config);
    ctx.checks.expectOk(icm.probe(), "icm20948@0x68: probe finds WHO_AM_I 0xEA");
    const int rc = startDriver(icm);
    ctx.checks.expect(rc == 0 && icm.state() == caphub::hal::ImuDriver::State::Running,
                      "icm20948@0x68: start-up (reset, probe, configure, magnetometer) reaches "
                      "Running",
                      rc == 0 ? "not Running" : caphub::errnoText(rc));
    expectSettingsHeld(ctx, icm, readIcmSetting);
    std::uint8_t magMode = 0;
    const bool modeRead =
        selectIcmBank(ctx, 3) &&
        ctx.bus->readByteData(kIcm20948Address, static_cast<std::uint8_t>(Bank3::I2C_SLV4_DO),
                              magMode) == 0 &&
        selectIcmBank(ctx, 0);
    ctx.checks.expect(modeRead && magMode == static_cast<std::uint8_t>(ak::Mode::Continuous100Hz),
                      "icm20948@0x68: the AK09916 mode written through slave 4 is 100 Hz "
                      "continuous (0x08)",
                      "got " + hex(magMode));

    bool ready = false;
    ctx.checks.expect(icm.dataReady(ready) == 0 && ready,
                      "icm20948@0x68: data ready (INT_STATUS_1.RAW_DATA_0_RDY)");
    caphub::hal::ImuSample sample;
    const int rcSample = icm.readSample(caphub::timestampFromNs(1'000'000), sample);
    if (!ctx.checks.expectOk(rcSample, "icm20948@0x68: readSample (one 23-byte burst)")) {
        return true;
    }
    expectVector(ctx, "icm20948 acc", sample.accMps2,
                 {icm20948::kAccelG[0].physical * kG, icm20948::kAccelG[1].physical * kG,
                  icm20948::kAccelG[2].physical * kG},
                 0.5 * kG / icm20948::kAccelLsbPerG, "m/s^2");
    expectVector(
        ctx, "icm20948 gyr", sample.gyrRadps,
        {icm20948::kGyroDps[0].physical * kRadPerDeg, icm20948::kGyroDps[1].physical * kRadPerDeg,
         icm20948::kGyroDps[2].physical * kRadPerDeg},
        0.5 * kRadPerDeg / icm20948::kGyroLsbPerDps, "rad/s");
    // AK09916 axes are the accelerometer's x, -y, -z.
    expectVector(ctx, "icm20948 mag", sample.magUt, {15.0, 30.0, -45.0}, 0.5 * 0.15, "uT");
    ctx.checks.expect((sample.flags & caphub::hal::ImuSample::kMagFresh) != 0,
                      "icm20948@0x68: the sample carries a fresh magnetometer reading");
    ctx.checks.expect(std::fabs(sample.temperatureC - 21.0f) < 1e-4f,
                      "icm20948@0x68: temperature 0 counts is 21 degC");
    return true;
}

int readLsmSetting(Context& ctx, const caphub::hal::RegisterSetting& setting, std::uint8_t& value) {
    const std::uint8_t address = setting.space == caphub::hal::Lsm6dsoxLis3mdl::kImuSpace
                                     ? kLsm6dsoxAddress
                                     : kLis3mdlAddress;
    return ctx.bus->readByteData(address, setting.reg, value);
}

bool checkLsm6dsoxLis3mdlDriver(Context& ctx) {
    // Data ready on both dies; the LIS3MDL's status is read in its multi-byte burst, addressed
    // 0xA7 (STATUS_REG 0x27 with the auto-increment bit).
    constexpr std::uint8_t kXldaGda = 0x03;
    constexpr std::uint8_t kZyxda = 0x08;
    bool ok = ctx.bus->writeByteData(kLsm6dsoxAddress, 0x1E, kXldaGda) == 0 &&
              ctx.bus->writeI2cBlock(kLsm6dsoxAddress, 0x20,
                                     std::array<std::uint8_t, 2>{0x00, 0x00}) == 0 &&  // 25 degC
              ctx.bus->writeByteData(kLis3mdlAddress, 0x27, kZyxda) == 0 &&
              ctx.bus->writeByteData(kLis3mdlAddress, 0x27 | lis3mdl::kAutoIncrement, kZyxda) == 0;
    ctx.checks.expect(ok, "preload: LSM6DSOX XLDA|GDA, LIS3MDL ZYXDA");

    caphub::hal::ImuConfig config;
    config.odrHz = 104;
    config.magOdrHz = 80;
    config.accelRangeG = 2;
    config.gyroRangeDps = 250;
    caphub::hal::Lsm6dsoxLis3mdl imu(
        std::make_unique<caphub::hal::I2cRegisterIo>(*ctx.bus, kLsm6dsoxAddress),
        std::make_unique<caphub::hal::I2cRegisterIo>(*ctx.bus, kLis3mdlAddress,
                                                     lis3mdl::kAutoIncrement),
        "lsm6dsox@0x6a+lis3mdl@0x1c", config);
    ctx.checks.expectOk(imu.probe(), imu.name() + ": probe finds WHO_AM_I 0x6C and 0x3D");
    const int rc = startDriver(imu);
    ctx.checks.expect(rc == 0 && imu.state() == caphub::hal::ImuDriver::State::Running,
                      imu.name() + ": start-up (reset, probe, configure) reaches Running",
                      rc == 0 ? "not Running" : caphub::errnoText(rc));
    expectSettingsHeld(ctx, imu, readLsmSetting);

    bool ready = false;
    ctx.checks.expect(imu.dataReady(ready) == 0 && ready, imu.name() + ": data ready (XLDA, GDA)");
    caphub::hal::ImuSample sample;
    const int rcSample = imu.readSample(caphub::timestampFromNs(1'000'000), sample);
    if (!ctx.checks.expectOk(rcSample,
                             imu.name() + ": readSample (IMU burst, then magnetometer)")) {
        return true;
    }
    expectVector(ctx, "lsm6dsox acc", sample.accMps2,
                 {lsm6dsox::kAccelG[0].physical * kG, lsm6dsox::kAccelG[1].physical * kG,
                  lsm6dsox::kAccelG[2].physical * kG},
                 0.5 * lsm6dsox::kAccelMgPerLsb * 1e-3 * kG, "m/s^2");
    expectVector(
        ctx, "lsm6dsox gyr", sample.gyrRadps,
        {lsm6dsox::kGyroDps[0].physical * kRadPerDeg, lsm6dsox::kGyroDps[1].physical * kRadPerDeg,
         lsm6dsox::kGyroDps[2].physical * kRadPerDeg},
        0.5 * lsm6dsox::kGyroMdpsPerLsb * 1e-3 * kRadPerDeg, "rad/s");
    // 1 gauss = 100 uT.
    expectVector(ctx, "lis3mdl  mag", sample.magUt,
                 {lis3mdl::kGauss[0].physical * 100.0, lis3mdl::kGauss[1].physical * 100.0,
                  lis3mdl::kGauss[2].physical * 100.0},
                 0.5 * 100.0 / lis3mdl::kLsbPerGauss, "uT");
    ctx.checks.expect((sample.flags & caphub::hal::ImuSample::kMagFresh) != 0,
                      imu.name() + ": the sample carries a fresh magnetometer reading");
    ctx.checks.expect(std::fabs(sample.temperatureC - 25.0f) < 1e-4f,
                      imu.name() + ": temperature 0 counts is 25 degC");
    return true;
}

struct Section {
    const char* title;
    bool (*run)(Context&);  // false: later sections cannot run
};

// Register level first (the backend alone), then the project's mux, line and IMU drivers on the
// same bus. A new driver's checks are one more row.
constexpr std::array<Section, 12> kSections = {{
    {"open the adapter", checkOpen},
    {"preload the emulated chips", checkPreload},
    {"ICM-20948 at 0x68: registers, banks, sample", checkIcm20948Registers},
    {"LSM6DSOX at 0x6A: registers, configuration, sample", checkLsm6dsoxRegisters},
    {"LIS3MDL at 0x1C: registers, configuration, sample", checkLis3mdlRegisters},
    {"TCA9548A at 0x70: control register", checkMuxControl},
    {"transfer kinds: word data, block limits", checkTransferKinds},
    {"absent address 0x50", checkAbsentAddress},
    {"TCA9548A through the project's mux (hal/tca9548a)", checkMuxDriver},
    {"data-ready line on a missing GPIO chip (hal/linux/gpiod_line)", checkGpiodErrors},
    {"ICM-20948 driver (hal/drivers/icm20948) on 0x68", checkIcm20948Driver},
    {"LSM6DSOX+LIS3MDL driver (hal/drivers/lsm6dsox_lis3mdl) on 0x6A+0x1C",
     checkLsm6dsoxLis3mdlDriver},
}};

}  // namespace

int main(int argc, char** argv) {
    if (argc != 3) {
        std::fprintf(stderr, "usage: %s /dev/i2c-N /dev/fbN\n", argv[0]);
        return 2;
    }
    Context ctx;
    ctx.path = argv[1];
    std::printf("caphub kernel-level I2C test on %s\n", ctx.path.c_str());
    for (const auto& section : kSections) {
        std::printf("== %s\n", section.title);
        if (!section.run(ctx)) {
            std::printf("  (stopping: later I2C sections need this one)\n");
            break;
        }
    }
    // The framebuffer needs nothing from the I2C sections: it runs whatever they found.
    caphub::kernel_test::checkFramebuffer(argv[2], ctx.checks);
    std::printf("guest: %d checks, %d failed\n", ctx.checks.count(), ctx.checks.failures());
    if (ctx.bus) {
        const auto counters = caphub::hal::snapshot(ctx.bus->counters());
        std::printf("guest: bus counters: %llu transactions, %llu bytes, %llu errors\n",
                    static_cast<unsigned long long>(counters.transactions),
                    static_cast<unsigned long long>(counters.bytes),
                    static_cast<unsigned long long>(counters.errors));
    }
    return ctx.checks.failures() == 0 && ctx.checks.count() > 0 ? 0 : 1;
}
