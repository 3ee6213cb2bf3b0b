// What the board loader needs to know about each supported IMU chip: addresses, rates, ranges,
// bus limits and the bus transactions one sample costs. Figures from the manufacturers'
// datasheets (TDK InvenSense DS-000189 ICM-20948 rev 1.3; ST DS13210 LSM6DSOX, DS10540 LIS3MDL).
#pragma once

#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace caphub::hal {

enum class BusProtocol { I2c, Spi };

std::string_view toString(BusProtocol p);

// One register read of a sample: dataBytes bytes after the register address.
struct ReadCost {
    int transactions = 0;
    int dataBytes = 0;  // per transaction
};

struct ChipInfo {
    std::string_view name;  // as written in board files
    std::string_view description;
    std::span<const std::uint8_t> i2cAddresses;     // the accel/gyro die
    std::span<const std::uint8_t> magI2cAddresses;  // a separate magnetometer die, or empty
    std::span<const double> accelRangesG;
    std::span<const double> gyroRangesDps;
    std::span<const double> magOdrsHz;  // the magnetometer's continuous rates
    double maxI2cHz;
    double maxSpiHz;
    // Bus cost per accel/gyro sample, and per magnetometer sample when the magnetometer is read
    // in a transaction of its own (zero when it comes with the accel/gyro read).
    ReadCost imuRead;
    ReadCost magRead;
    // Extra cost per sample when no data-ready line is wired: polling the data-ready status bit.
    ReadCost statusPoll;
    // The accel/gyro output rate the chip can run at nearest to hz, and the next one on the
    // other side (for error messages).
    double (*nearestOdrHz)(double hz);
    std::string_view odrRule;  // human description of the achievable rates
};

// All supported chips.
std::span<const ChipInfo> chipCatalog();
const ChipInfo* findChip(std::string_view name);

// True when the chip runs at hz within 0.5 %.
bool odrSupported(const ChipInfo& chip, double hz);

// The achievable rates around hz, lower first, for "nearest are ..." messages.
std::vector<double> odrNeighbours(const ChipInfo& chip, double hz);

}  // namespace caphub::hal
