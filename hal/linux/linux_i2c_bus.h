// The I2C seam on Linux: an i2c-dev adapter (/dev/i2c-N) driven through libi2c's SMBus calls.
// Works on adapters that only speak SMBus (i2c-stub, many SoC controllers' SMBus emulation).
#pragma once

#include <memory>
#include <string>

#include "hal/core/error.h"
#include "hal/i2c_bus.h"
#include "hal/linux/unique_fd.h"

namespace caphub::hal {

class LinuxI2cBus final : public I2cBus {
public:
    // The SMBus functions caphub's drivers and the mux use (I2C_FUNC_* bits): byte data and I2C
    // block read/write for the sensors, send/receive byte for the TCA9548A.
    static unsigned long defaultRequiredFunctions();

    // Opens the adapter and checks with I2C_FUNCS that it has every required function. Errors
    // name the device and the errno text, or the functions the adapter lacks.
    static Result<std::unique_ptr<LinuxI2cBus>> open(
        const std::string& path, unsigned long requiredFunctions = defaultRequiredFunctions());

    int readByte(std::uint8_t address, std::uint8_t& value) override;
    int writeByte(std::uint8_t address, std::uint8_t value) override;
    int readByteData(std::uint8_t address, std::uint8_t reg, std::uint8_t& value) override;
    int writeByteData(std::uint8_t address, std::uint8_t reg, std::uint8_t value) override;
    int readWordData(std::uint8_t address, std::uint8_t reg, std::uint16_t& value) override;
    int writeWordData(std::uint8_t address, std::uint8_t reg, std::uint16_t value) override;
    int readI2cBlock(std::uint8_t address, std::uint8_t reg, std::span<std::uint8_t> out) override;
    int writeI2cBlock(std::uint8_t address, std::uint8_t reg,
                      std::span<const std::uint8_t> data) override;

    std::string name() const override { return path_; }
    const BusCounters& counters() const override { return counters_; }

    // The adapter's I2C_FUNCS bits, and its name from sysfs ("SMBus stub driver").
    unsigned long functions() const { return functions_; }
    std::string adapterName() const;

    // Describes the I2C_FUNC_* bits of mask ("SMBus I2C block read, SMBus send byte").
    static std::string describeFunctions(unsigned long mask);

private:
    LinuxI2cBus(std::string path, UniqueFd fd, unsigned long functions);

    // Points the fd at a device (I2C_SLAVE), only when it changes.
    int target(std::uint8_t address);
    int finish(int result, std::size_t wireBytes);

    std::string path_;
    UniqueFd fd_;
    unsigned long functions_;
    int currentAddress_ = -1;
    BusCounters counters_;
};

}  // namespace caphub::hal
