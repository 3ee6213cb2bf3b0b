// The I2C bus seam: SMBus-level operations on the devices of one bus. Drivers speak only to
// this; the Linux backend (i2c-dev), the simulated bus and the TCA9548A channels implement it.
// Every operation returns 0 or -errno and never logs.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>

#include "hal/bus_counters.h"

namespace caphub::hal {

// The longest SMBus "I2C block" transfer (I2C_SMBUS_BLOCK_MAX).
inline constexpr std::size_t kI2cBlockMax = 32;

class I2cBus {
public:
    virtual ~I2cBus() = default;

    // SMBus receive/send byte: no register (a TCA9548A's control register works this way).
    [[nodiscard]] virtual int readByte(std::uint8_t address, std::uint8_t& value) = 0;
    [[nodiscard]] virtual int writeByte(std::uint8_t address, std::uint8_t value) = 0;

    [[nodiscard]] virtual int readByteData(std::uint8_t address, std::uint8_t reg,
                                           std::uint8_t& value) = 0;
    [[nodiscard]] virtual int writeByteData(std::uint8_t address, std::uint8_t reg,
                                            std::uint8_t value) = 0;

    // Word data is little-endian on the wire (SMBus).
    [[nodiscard]] virtual int readWordData(std::uint8_t address, std::uint8_t reg,
                                           std::uint16_t& value) = 0;
    [[nodiscard]] virtual int writeWordData(std::uint8_t address, std::uint8_t reg,
                                            std::uint16_t value) = 0;

    // I2C block read/write of 1..kI2cBlockMax bytes starting at reg (-EINVAL beyond).
    [[nodiscard]] virtual int readI2cBlock(std::uint8_t address, std::uint8_t reg,
                                           std::span<std::uint8_t> out) = 0;
    [[nodiscard]] virtual int writeI2cBlock(std::uint8_t address, std::uint8_t reg,
                                            std::span<const std::uint8_t> data) = 0;

    // For messages: "/dev/i2c-1", "sim-i2c-1", "mux0 (0x70 on /dev/i2c-1) channel 3".
    virtual std::string name() const = 0;

    // The physical bus's accounting (a mux channel reports its parent bus's).
    virtual const BusCounters& counters() const = 0;
};

}  // namespace caphub::hal
