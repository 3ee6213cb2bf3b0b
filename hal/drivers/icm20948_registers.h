// ICM-20948 register map (TDK InvenSense DS-000189 rev 1.3, section 7). The user bank is part of
// each register's type, so a bank-2 register cannot be accessed with bank 0 selected: the
// driver's accessors select the bank from the type. Shared by the driver and the chip model.
#pragma once

#include <cstdint>

namespace caphub::hal::icm20948 {

inline constexpr std::uint8_t kWhoAmI = 0xEA;
inline constexpr std::uint8_t kI2cAddressLow = 0x68;  // AD0 low
inline constexpr std::uint8_t kI2cAddressHigh = 0x69;
inline constexpr std::uint8_t kSpiRead = 0x80;  // R/W bit of the SPI address byte

// REG_BANK_SEL is at 0x7F in every bank; USER_BANK is bits 5:4.
inline constexpr std::uint8_t kRegBankSel = 0x7F;
constexpr std::uint8_t bankSelValue(int bank) {
    return static_cast<std::uint8_t>(bank << 4);
}

enum class Bank0 : std::uint8_t {
    WHO_AM_I = 0x00,
    USER_CTRL = 0x03,
    LP_CONFIG = 0x05,
    PWR_MGMT_1 = 0x06,
    PWR_MGMT_2 = 0x07,
    INT_PIN_CFG = 0x0F,
    INT_ENABLE = 0x10,
    INT_ENABLE_1 = 0x11,
    I2C_MST_STATUS = 0x17,
    INT_STATUS = 0x19,
    INT_STATUS_1 = 0x1A,
    ACCEL_XOUT_H = 0x2D,
    GYRO_XOUT_H = 0x33,
    TEMP_OUT_H = 0x39,
    EXT_SLV_SENS_DATA_00 = 0x3B,
    FIFO_EN_1 = 0x66,
    FIFO_EN_2 = 0x67,
    FIFO_RST = 0x68,
    FIFO_MODE = 0x69,
    DATA_RDY_STATUS = 0x74,
};

enum class Bank2 : std::uint8_t {
    GYRO_SMPLRT_DIV = 0x00,
    GYRO_CONFIG_1 = 0x01,
    GYRO_CONFIG_2 = 0x02,
    ODR_ALIGN_EN = 0x09,
    ACCEL_SMPLRT_DIV_1 = 0x10,
    ACCEL_SMPLRT_DIV_2 = 0x11,
    ACCEL_CONFIG = 0x14,
    ACCEL_CONFIG_2 = 0x15,
};

enum class Bank3 : std::uint8_t {
    I2C_MST_ODR_CONFIG = 0x00,
    I2C_MST_CTRL = 0x01,
    I2C_MST_DELAY_CTRL = 0x02,
    I2C_SLV0_ADDR = 0x03,
    I2C_SLV0_REG = 0x04,
    I2C_SLV0_CTRL = 0x05,
    I2C_SLV0_DO = 0x06,
    I2C_SLV4_ADDR = 0x13,
    I2C_SLV4_REG = 0x14,
    I2C_SLV4_CTRL = 0x15,
    I2C_SLV4_DO = 0x16,
    I2C_SLV4_DI = 0x17,
};

constexpr int bankOf(Bank0) {
    return 0;
}
constexpr int bankOf(Bank2) {
    return 2;
}
constexpr int bankOf(Bank3) {
    return 3;
}

// USER_CTRL
namespace user_ctrl {
inline constexpr std::uint8_t DMP_EN = 1u << 7;
inline constexpr std::uint8_t FIFO_EN = 1u << 6;
inline constexpr std::uint8_t I2C_MST_EN = 1u << 5;
inline constexpr std::uint8_t I2C_IF_DIS = 1u << 4;  // SPI only: disable the I2C slave interface
inline constexpr std::uint8_t I2C_MST_RST = 1u << 1;
}  // namespace user_ctrl

// PWR_MGMT_1 (reset value 0x41: SLEEP, CLKSEL = 1)
namespace pwr_mgmt_1 {
inline constexpr std::uint8_t DEVICE_RESET = 1u << 7;
inline constexpr std::uint8_t SLEEP = 1u << 6;
inline constexpr std::uint8_t LP_EN = 1u << 5;
inline constexpr std::uint8_t TEMP_DIS = 1u << 3;
inline constexpr std::uint8_t CLKSEL_MASK = 0x07;
inline constexpr std::uint8_t CLKSEL_AUTO = 0x01;  // best available clock (PLL when ready)
inline constexpr std::uint8_t kResetValue = 0x41;
}  // namespace pwr_mgmt_1

// INT_PIN_CFG
namespace int_pin_cfg {
inline constexpr std::uint8_t INT1_ACTL = 1u << 7;  // active low
inline constexpr std::uint8_t INT1_OPEN = 1u << 6;  // open drain
inline constexpr std::uint8_t INT1_LATCH_EN = 1u << 5;
inline constexpr std::uint8_t INT_ANYRD_2CLEAR = 1u << 4;
inline constexpr std::uint8_t BYPASS_EN = 1u << 1;
}  // namespace int_pin_cfg

// INT_ENABLE_1 / INT_STATUS_1
inline constexpr std::uint8_t RAW_DATA_0_RDY = 1u << 0;

// I2C_MST_STATUS
inline constexpr std::uint8_t I2C_SLV4_DONE = 1u << 6;
inline constexpr std::uint8_t I2C_SLV4_NACK = 1u << 4;

// GYRO_CONFIG_1: GYRO_DLPFCFG 5:3, GYRO_FS_SEL 2:1, GYRO_FCHOICE 0
namespace gyro_config_1 {
inline constexpr std::uint8_t DLPFCFG_MASK = 0x38;
inline constexpr std::uint8_t FS_SEL_MASK = 0x06;
inline constexpr std::uint8_t FCHOICE = 0x01;
}  // namespace gyro_config_1

// ACCEL_CONFIG: ACCEL_DLPFCFG 5:3, ACCEL_FS_SEL 2:1, ACCEL_FCHOICE 0
namespace accel_config {
inline constexpr std::uint8_t DLPFCFG_MASK = 0x38;
inline constexpr std::uint8_t FS_SEL_MASK = 0x06;
inline constexpr std::uint8_t FCHOICE = 0x01;
}  // namespace accel_config

constexpr std::uint8_t dlpfcfg(int cfg) {
    return static_cast<std::uint8_t>((cfg & 7) << 3);
}
constexpr std::uint8_t fsSel(int sel) {
    return static_cast<std::uint8_t>((sel & 3) << 1);
}

// Full scales by FS_SEL and their sensitivities (datasheet tables 1 and 2).
inline constexpr double kGyroRangeDps[4] = {250, 500, 1000, 2000};
inline constexpr double kGyroLsbPerDps[4] = {131.0, 65.5, 32.8, 16.4};
inline constexpr double kAccelRangeG[4] = {2, 4, 8, 16};
inline constexpr double kAccelLsbPerG[4] = {16384, 8192, 4096, 2048};
// Temperature: degC = TEMP_OUT / 333.87 + 21 (room-temperature offset 0).
inline constexpr double kTempLsbPerDegC = 333.87;
inline constexpr double kTempOffsetDegC = 21.0;

// Internal sample clocks of the dividers: gyro 1.1 kHz / (1 + GYRO_SMPLRT_DIV) (8 bits),
// accel 1.125 kHz / (1 + ACCEL_SMPLRT_DIV) (12 bits).
inline constexpr double kGyroBaseRateHz = 1100.0;
inline constexpr double kAccelBaseRateHz = 1125.0;

// I2C_SLVx_CTRL
namespace slv_ctrl {
inline constexpr std::uint8_t EN = 1u << 7;
inline constexpr std::uint8_t LENG_MASK = 0x0F;
}  // namespace slv_ctrl
inline constexpr std::uint8_t I2C_SLV_RNW = 1u << 7;      // in I2C_SLVx_ADDR: read
inline constexpr std::uint8_t I2C_MST_CLK_345KHZ = 0x07;  // recommended master clock

// One sample as read in a single burst from ACCEL_XOUT_H: accel, gyro and temperature
// (big-endian), then the AK09916 block ST1..ST2 copied by the auxiliary I2C master into
// EXT_SLV_SENS_DATA_00..08 (little-endian magnetometer axes).
struct SampleBurst {
    std::uint8_t accel[6];
    std::uint8_t gyro[6];
    std::uint8_t temp[2];
    std::uint8_t magSt1;
    std::uint8_t mag[6];
    std::uint8_t magTmps;
    std::uint8_t magSt2;
};
static_assert(sizeof(SampleBurst) == 23, "one burst covers 0x2D..0x43");
static_assert(static_cast<int>(Bank0::EXT_SLV_SENS_DATA_00) -
                      static_cast<int>(Bank0::ACCEL_XOUT_H) ==
                  14,
              "external sensor data follows the temperature");

}  // namespace caphub::hal::icm20948
