// LIS3MDL magnetometer register map (ST DS10540 rev 6, section 7-8). Shared by the driver and
// the chip model.
#pragma once

#include <cstdint>

namespace caphub::hal::lis3mdl {

inline constexpr std::uint8_t kWhoAmI = 0x3D;
inline constexpr std::uint8_t kI2cAddressLow = 0x1C;  // SDO/SA1 low
inline constexpr std::uint8_t kI2cAddressHigh = 0x1E;
// Multi-byte access: on I2C the MSB of the register address enables auto-increment; on SPI the
// address byte is R/W (bit 7), M/S auto-increment (bit 6), address (5:0).
inline constexpr std::uint8_t kI2cAutoIncrement = 0x80;
inline constexpr std::uint8_t kSpiRead = 0x80;
inline constexpr std::uint8_t kSpiAutoIncrement = 0x40;

enum class Register : std::uint8_t {
    WHO_AM_I = 0x0F,
    CTRL_REG1 = 0x20,
    CTRL_REG2 = 0x21,
    CTRL_REG3 = 0x22,
    CTRL_REG4 = 0x23,
    CTRL_REG5 = 0x24,
    STATUS_REG = 0x27,
    OUT_X_L = 0x28,
    OUT_Z_H = 0x2D,
    TEMP_OUT_L = 0x2E,
    TEMP_OUT_H = 0x2F,
};

// CTRL_REG1: TEMP_EN 7, OM 6:5 (X/Y operating mode), DO 4:2 (rate), FAST_ODR 1, ST 0.
namespace ctrl_reg1 {
inline constexpr std::uint8_t TEMP_EN = 1u << 7;
inline constexpr std::uint8_t OM_MASK = 0x60;
inline constexpr std::uint8_t DO_MASK = 0x1C;
inline constexpr std::uint8_t FAST_ODR = 1u << 1;
}  // namespace ctrl_reg1
constexpr std::uint8_t omBits(int om) {
    return static_cast<std::uint8_t>((om & 3) << 5);
}
constexpr std::uint8_t doBits(int d) {
    return static_cast<std::uint8_t>((d & 7) << 2);
}

// CTRL_REG2: FS 6:5, REBOOT 3, SOFT_RST 2.
namespace ctrl_reg2 {
inline constexpr std::uint8_t FS_MASK = 0x60;
inline constexpr std::uint8_t REBOOT = 1u << 3;
inline constexpr std::uint8_t SOFT_RST = 1u << 2;
}  // namespace ctrl_reg2
constexpr std::uint8_t fsBits(int fs) {
    return static_cast<std::uint8_t>((fs & 3) << 5);
}

// CTRL_REG3: MD 1:0 (00 continuous, 01 single, 1x power-down; reset value 0x03).
inline constexpr std::uint8_t MD_MASK = 0x03;
inline constexpr std::uint8_t MD_CONTINUOUS = 0x00;
inline constexpr std::uint8_t kCtrlReg3ResetValue = 0x03;
// CTRL_REG4: OMZ 3:2 (Z operating mode).
constexpr std::uint8_t omzBits(int om) {
    return static_cast<std::uint8_t>((om & 3) << 2);
}
// CTRL_REG5: BDU 6.
inline constexpr std::uint8_t BDU = 1u << 6;
// STATUS_REG
inline constexpr std::uint8_t ZYXDA = 1u << 3;
inline constexpr std::uint8_t ZYXOR = 1u << 7;

// Rates: DO codes 0..7 when FAST_ODR is 0; with FAST_ODR the operating mode sets the rate.
inline constexpr double kDoRateHz[8] = {0.625, 1.25, 2.5, 5, 10, 20, 40, 80};
inline constexpr double kFastOdrHzByOm[4] = {1000, 560, 300, 155};  // LP, MP, HP, UHP

// FS codes: +-4, 8, 12, 16 gauss; sensitivity in LSB/gauss (1 gauss = 100 uT).
inline constexpr double kRangeGauss[4] = {4, 8, 12, 16};
inline constexpr double kLsbPerGauss[4] = {6842, 3421, 2281, 1711};

}  // namespace caphub::hal::lis3mdl
