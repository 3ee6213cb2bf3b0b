// What a simulated bus talks to: register-level models of the chips (ArduPilot SITL / Zephyr
// emulator style). Models see raw bus transactions, with the simulated time at which they happen.
#pragma once

#include <cstdint>
#include <optional>
#include <span>

#include <Eigen/Core>

#include "hal/core/time.h"

namespace caphub::hal::sim {

// A device on a simulated I2C bus. A register read is a write of the register address followed
// (repeated start) by a read; the model keeps its register pointer between the two.
class I2cDeviceModel {
public:
    virtual ~I2cDeviceModel() = default;
    // 0, or -ENXIO when the device does not acknowledge.
    virtual int i2cWrite(Timestamp now, std::span<const std::uint8_t> bytes) = 0;
    virtual int i2cRead(Timestamp now, std::span<std::uint8_t> out) = 0;
};

// A device on one chip select of a simulated SPI bus.
class SpiDeviceModel {
public:
    virtual ~SpiDeviceModel() = default;
    virtual int spiTransfer(Timestamp now, std::span<const std::uint8_t> tx,
                            std::span<std::uint8_t> rx) = 0;
};

// A chip that raises a data-ready line: the time of its next edge after `after`, if any.
class DataReadyModel {
public:
    virtual ~DataReadyModel() = default;
    virtual std::optional<Timestamp> nextDataReady(Timestamp after) const = 0;
};

// The physical quantities at a chip, in the chip's (accelerometer's) frame, SI units.
struct PhysicalInput {
    Eigen::Vector3d accMps2{0, 0, 9.80665};  // specific force: at rest, level, +z up reads +1 g
    Eigen::Vector3d gyrRadps = Eigen::Vector3d::Zero();
    Eigen::Vector3d magUt{0, 21.1, -45.3};  // 50 uT at 65 deg dip, heading north
    double temperatureC = 25;
};

// Where a chip model gets its physical inputs: a constant, a scripted motion, or the virtual
// suit's IMU model.
class PhysicalSource {
public:
    virtual ~PhysicalSource() = default;
    virtual PhysicalInput at(Timestamp t) = 0;
};

class ConstantSource final : public PhysicalSource {
public:
    explicit ConstantSource(const PhysicalInput& input = {}) : input_(input) {}
    PhysicalInput at(Timestamp) override { return input_; }
    void set(const PhysicalInput& input) { input_ = input; }

private:
    PhysicalInput input_;
};

// Raw count of a physical value at a sensitivity, rounded and saturated to int16.
std::int16_t quantise(double value, double lsbPerUnit);

}  // namespace caphub::hal::sim
