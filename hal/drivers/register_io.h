// Register access for the chip drivers, over I2C (SMBus byte data / I2C block) or SPI (address
// byte with a read flag, then data), so that one driver serves both buses.
#pragma once

#include <cstdint>
#include <span>
#include <string>

#include "hal/i2c_bus.h"
#include "hal/spi_bus.h"

namespace caphub::hal {

class RegisterIo {
public:
    virtual ~RegisterIo() = default;

    // Reads out.size() consecutive registers from reg (auto-increment), in as few transactions
    // as the bus allows (one up to 32 bytes on I2C).
    [[nodiscard]] virtual int read(std::uint8_t reg, std::span<std::uint8_t> out) = 0;
    [[nodiscard]] virtual int write(std::uint8_t reg, std::uint8_t value) = 0;
    virtual std::string describe() const = 0;

    [[nodiscard]] int readByte(std::uint8_t reg, std::uint8_t& value) {
        return read(reg, std::span<std::uint8_t>(&value, 1));
    }
};

class I2cRegisterIo final : public RegisterIo {
public:
    // multiByteFlag is ORed into the register address of multi-byte reads (LIS3MDL: 0x80).
    I2cRegisterIo(I2cBus& bus, std::uint8_t address, std::uint8_t multiByteFlag = 0)
        : bus_(bus), address_(address), multiByteFlag_(multiByteFlag) {}

    int read(std::uint8_t reg, std::span<std::uint8_t> out) override;
    int write(std::uint8_t reg, std::uint8_t value) override;
    std::string describe() const override;

private:
    I2cBus& bus_;
    std::uint8_t address_;
    std::uint8_t multiByteFlag_;
};

class SpiRegisterIo final : public RegisterIo {
public:
    // The address byte of a read is reg | readFlag, and of a multi-byte read also
    // | multiByteFlag (LIS3MDL: 0x40).
    SpiRegisterIo(SpiBus& bus, std::uint8_t readFlag = 0x80, std::uint8_t multiByteFlag = 0)
        : bus_(bus), readFlag_(readFlag), multiByteFlag_(multiByteFlag) {}

    int read(std::uint8_t reg, std::span<std::uint8_t> out) override;
    int write(std::uint8_t reg, std::uint8_t value) override;
    std::string describe() const override { return bus_.name(); }

    static constexpr std::size_t kMaxTransfer = 64;

private:
    SpiBus& bus_;
    std::uint8_t readFlag_;
    std::uint8_t multiByteFlag_;
};

}  // namespace caphub::hal
