// AK09916 magnetometer register map (AKM AK09916C datasheet): the magnetometer die inside the
// ICM-20948, on its auxiliary I2C bus at 0x0C. Shared by the driver and the chip model.
#pragma once

#include <cstdint>

namespace caphub::hal::ak09916 {

inline constexpr std::uint8_t kI2cAddress = 0x0C;
inline constexpr std::uint8_t kCompanyId = 0x48;  // WIA1
inline constexpr std::uint8_t kDeviceId = 0x09;   // WIA2

enum class Register : std::uint8_t {
    WIA1 = 0x00,
    WIA2 = 0x01,
    ST1 = 0x10,
    HXL = 0x11,
    HZH = 0x16,
    TMPS = 0x17,
    ST2 = 0x18,
    CNTL2 = 0x31,
    CNTL3 = 0x32,
};

inline constexpr std::uint8_t ST1_DRDY = 1u << 0;
inline constexpr std::uint8_t ST1_DOR = 1u << 1;
inline constexpr std::uint8_t ST2_HOFL = 1u << 3;  // magnetic sensor overflow
inline constexpr std::uint8_t CNTL3_SRST = 1u << 0;

// CNTL2 MODE values.
enum class Mode : std::uint8_t {
    PowerDown = 0x00,
    Single = 0x01,
    Continuous10Hz = 0x02,
    Continuous20Hz = 0x04,
    Continuous50Hz = 0x06,
    Continuous100Hz = 0x08,
    SelfTest = 0x10,
};

inline constexpr double kMicroteslaPerLsb = 0.15;
inline constexpr int kMaxCounts = 32752;  // +-4912 uT

// ST1 .. ST2: the 9 bytes the ICM-20948's master copies per sample.
inline constexpr int kBlockLength = 9;

}  // namespace caphub::hal::ak09916
