// LSM6DSOX accelerometer + gyroscope register map (ST DS13210 rev 3, section 8-9). Shared by the
// driver and the chip model.
#pragma once

#include <cstdint>

namespace caphub::hal::lsm6dsox {

inline constexpr std::uint8_t kWhoAmI = 0x6C;
inline constexpr std::uint8_t kI2cAddressLow = 0x6A;  // SDO/SA0 low
inline constexpr std::uint8_t kI2cAddressHigh = 0x6B;
inline constexpr std::uint8_t kSpiRead = 0x80;

enum class Register : std::uint8_t {
    FUNC_CFG_ACCESS = 0x01,
    COUNTER_BDR_REG1 = 0x0B,
    INT1_CTRL = 0x0D,
    INT2_CTRL = 0x0E,
    WHO_AM_I = 0x0F,
    CTRL1_XL = 0x10,
    CTRL2_G = 0x11,
    CTRL3_C = 0x12,
    CTRL4_C = 0x13,
    CTRL5_C = 0x14,
    CTRL6_C = 0x15,
    CTRL7_G = 0x16,
    CTRL8_XL = 0x17,
    CTRL9_XL = 0x18,
    CTRL10_C = 0x19,
    STATUS_REG = 0x1E,
    OUT_TEMP_L = 0x20,
    OUTX_L_G = 0x22,
    OUTX_L_A = 0x28,
    OUTZ_H_A = 0x2D,
};

// COUNTER_BDR_REG1: data-ready as a 75 us pulse instead of a latched level.
inline constexpr std::uint8_t DATAREADY_PULSED = 1u << 7;
// CTRL6_C / CTRL7_G: high-performance mode disabled when set.
inline constexpr std::uint8_t XL_HM_MODE = 1u << 4;
inline constexpr std::uint8_t G_HM_MODE = 1u << 7;

// INT1_CTRL
inline constexpr std::uint8_t INT1_DRDY_XL = 1u << 0;
inline constexpr std::uint8_t INT1_DRDY_G = 1u << 1;

// CTRL3_C (reset value 0x04: IF_INC)
namespace ctrl3_c {
inline constexpr std::uint8_t BOOT = 1u << 7;
inline constexpr std::uint8_t BDU = 1u << 6;
inline constexpr std::uint8_t H_LACTIVE = 1u << 5;
inline constexpr std::uint8_t PP_OD = 1u << 4;
inline constexpr std::uint8_t SIM = 1u << 3;
inline constexpr std::uint8_t IF_INC = 1u << 2;
inline constexpr std::uint8_t SW_RESET = 1u << 0;
inline constexpr std::uint8_t kResetValue = IF_INC;
}  // namespace ctrl3_c

// STATUS_REG
inline constexpr std::uint8_t XLDA = 1u << 0;
inline constexpr std::uint8_t GDA = 1u << 1;
inline constexpr std::uint8_t TDA = 1u << 2;

// CTRL1_XL / CTRL2_G: ODR in bits 7:4, full scale in bits 3:2.
inline constexpr std::uint8_t ODR_MASK = 0xF0;
inline constexpr std::uint8_t FS_MASK = 0x0C;
inline constexpr std::uint8_t FS_125 = 1u << 1;  // CTRL2_G: +-125 dps
constexpr std::uint8_t odrBits(int code) {
    return static_cast<std::uint8_t>((code & 0xF) << 4);
}
constexpr std::uint8_t fsBits(int code) {
    return static_cast<std::uint8_t>((code & 3) << 2);
}

// ODR codes 1..10 (high-performance mode).
inline constexpr double kOdrHz[11] = {0, 12.5, 26, 52, 104, 208, 416, 833, 1666, 3332, 6664};

// Accelerometer FS_XL codes: 00 +-2 g, 01 +-16 g, 10 +-4 g, 11 +-8 g.
inline constexpr double kAccelRangeByCode[4] = {2, 16, 4, 8};
inline constexpr double kAccelMgPerLsbByCode[4] = {0.061, 0.488, 0.122, 0.244};
// Gyroscope FS_G codes: 00 250, 01 500, 10 1000, 11 2000 dps (FS_125 selects 125 dps).
inline constexpr double kGyroRangeByCode[4] = {250, 500, 1000, 2000};
inline constexpr double kGyroMdpsPerLsbByCode[4] = {8.75, 17.5, 35.0, 70.0};
inline constexpr double kGyroMdpsPerLsb125 = 4.375;
// Temperature: 256 LSB/degC, 0 = 25 degC.
inline constexpr double kTempLsbPerDegC = 256.0;
inline constexpr double kTempOffsetDegC = 25.0;

// One sample in one burst from OUT_TEMP_L: temperature, gyro, accel, all little-endian.
struct SampleBurst {
    std::uint8_t temp[2];
    std::uint8_t gyro[6];
    std::uint8_t accel[6];
};
static_assert(sizeof(SampleBurst) == 14, "OUT_TEMP_L..OUTZ_H_A");
static_assert(static_cast<int>(Register::OUTZ_H_A) - static_cast<int>(Register::OUT_TEMP_L) + 1 ==
                  14,
              "burst covers the output registers");

}  // namespace caphub::hal::lsm6dsox
