#include "hal/chip_info.h"

#include <algorithm>
#include <array>
#include <cmath>

namespace caphub::hal {

namespace {

// ICM-20948: gyro ODR = 1.1 kHz / (1 + GYRO_SMPLRT_DIV), an 8-bit divider (user bank 2, 0x00);
// the accelerometer's 12-bit divider from 1.125 kHz is set to the nearest rate.
constexpr std::array<std::uint8_t, 2> kIcmAddresses = {0x68, 0x69};
constexpr std::array<double, 4> kIcmAccelG = {2, 4, 8, 16};
constexpr std::array<double, 4> kIcmGyroDps = {250, 500, 1000, 2000};
// AK09916 continuous measurement modes 1-4.
constexpr std::array<double, 4> kAk09916OdrHz = {10, 20, 50, 100};

double icmNearestOdr(double hz) {
    if (!(hz > 0)) {
        return 1100.0;
    }
    const double div = std::clamp(std::round(1100.0 / hz - 1.0), 0.0, 255.0);
    return 1100.0 / (1.0 + div);
}

// LSM6DSOX accel/gyro high-performance rates (CTRL1_XL / CTRL2_G ODR field), Hz.
constexpr std::array<double, 10> kLsmOdrHz = {12.5, 26, 52, 104, 208, 416, 833, 1666, 3332, 6664};
constexpr std::array<std::uint8_t, 2> kLsmAddresses = {0x6A, 0x6B};
constexpr std::array<std::uint8_t, 2> kLis3mdlAddresses = {0x1C, 0x1E};
constexpr std::array<double, 4> kLsmAccelG = {2, 4, 8, 16};
constexpr std::array<double, 5> kLsmGyroDps = {125, 250, 500, 1000, 2000};
// LIS3MDL CTRL_REG1 DO field and the FAST_ODR rates (ultra-high-performance at 155 Hz etc.).
constexpr std::array<double, 12> kLis3mdlOdrHz = {0.625, 1.25, 2.5, 5,   10,  20,
                                                  40,    80,   155, 300, 560, 1000};

double lsmNearestOdr(double hz) {
    double best = kLsmOdrHz.front();
    for (double r : kLsmOdrHz) {
        if (std::abs(r - hz) < std::abs(best - hz)) {
            best = r;
        }
    }
    return best;
}

// Samples another system recorded (caphub import): whatever rate its file says.
double importedOdr(double hz) {
    return std::clamp(hz, 1.0, 10000.0);
}

constexpr std::array<double, 5> kImportedAccelG = {2, 4, 8, 16, 32};
constexpr std::array<double, 6> kImportedGyroDps = {250, 500, 1000, 2000, 4000, 8000};

constexpr std::array<ChipInfo, 3> kChips = {{
    {
        "icm20948",
        "TDK InvenSense ICM-20948 9-axis (accel, gyro, AK09916 magnetometer read through the "
        "chip's auxiliary I2C master)",
        kIcmAddresses,
        {},
        kIcmAccelG,
        kIcmGyroDps,
        kAk09916OdrHz,
        400e3,
        7e6,
        // ACCEL_XOUT_H (0x2D) .. EXT_SLV_SENS_DATA_08 (0x43): accel 6, gyro 6, temperature 2,
        // then the AK09916 block ST1, HXL..HZH, TMPS, ST2 (9): 23 bytes in one burst.
        {1, 23},
        {0, 0},
        {1, 1},  // INT_STATUS_1 (0x1A), RAW_DATA_0_RDY_INT
        icmNearestOdr,
        "1100/(1+n) Hz, n = 0..255",
    },
    {
        "lsm6dsox+lis3mdl",
        "ST LSM6DSOX accel/gyro with an ST LIS3MDL magnetometer on the same bus, as one 9-axis "
        "sensor",
        kLsmAddresses,
        kLis3mdlAddresses,
        kLsmAccelG,
        kLsmGyroDps,
        kLis3mdlOdrHz,
        400e3,  // the LSM6DSOX does 1 MHz, but the LIS3MDL on the same bus only 400 kHz
        10e6,
        {1, 14},  // OUT_TEMP_L (0x20) .. OUTZ_H_A (0x2D)
        {1, 7},   // LIS3MDL STATUS_REG (0x27) .. OUT_Z_H (0x2D), auto-increment
        {1, 1},   // STATUS_REG (0x1E), XLDA/GDA
        lsmNearestOdr,
        "12.5, 26, 52, 104, 208, 416, 833, 1666, 3332 or 6664 Hz",
    },
    {
        "imported",
        "Samples recorded by another system and imported (caphub import): no hardware to drive; "
        "its magnetometer read with every sample",
        kIcmAddresses,
        {},
        kImportedAccelG,
        kImportedGyroDps,
        {},
        3.4e6,  // no bus: the stand-in I2C bus of an imported board fits 10 kHz at this clock
        10e6,
        {1, 23},
        {0, 0},
        {1, 1},
        importedOdr,
        "any rate from 1 to 10000 Hz",
    },
}};

}  // namespace

std::string_view toString(BusProtocol p) {
    return p == BusProtocol::I2c ? "i2c" : "spi";
}

std::span<const ChipInfo> chipCatalog() {
    return kChips;
}

const ChipInfo* findChip(std::string_view name) {
    for (const auto& c : kChips) {
        if (c.name == name) {
            return &c;
        }
    }
    return nullptr;
}

bool odrSupported(const ChipInfo& chip, double hz) {
    if (!(hz > 0) || !std::isfinite(hz)) {
        return false;
    }
    return std::abs(chip.nearestOdrHz(hz) - hz) <= 0.005 * hz;
}

std::vector<double> odrNeighbours(const ChipInfo& chip, double hz) {
    // Probe slightly below and above to find the achievable rates that bracket hz.
    std::vector<double> out;
    const double nearest = chip.nearestOdrHz(hz);
    double lower = nearest;
    double upper = nearest;
    for (double f = 0.999; f > 0.3 && (lower >= hz || upper <= hz); f -= 0.001) {
        if (lower >= hz) {
            lower = std::min(lower, chip.nearestOdrHz(hz * f));
        }
        if (upper <= hz) {
            upper = std::max(upper, chip.nearestOdrHz(hz / f));
        }
    }
    if (lower < hz) {
        out.push_back(lower);
    }
    if (upper > hz && upper != lower) {
        out.push_back(upper);
    }
    return out;
}

}  // namespace caphub::hal
