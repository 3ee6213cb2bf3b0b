#include "hal/linux/linux_i2c_bus.h"

extern "C" {
#include <i2c/smbus.h>
}
#include <array>
#include <cerrno>
#include <fstream>
#include <utility>

#include <fcntl.h>
#include <linux/i2c-dev.h>
#include <linux/i2c.h>
#include <sys/ioctl.h>

namespace caphub::hal {

namespace {

struct FunctionName {
    unsigned long bit;
    const char* name;
};

constexpr std::array<FunctionName, 9> kFunctionNames = {{
    {I2C_FUNC_I2C, "plain I2C (I2C_RDWR)"},
    {I2C_FUNC_SMBUS_READ_BYTE, "SMBus receive byte"},
    {I2C_FUNC_SMBUS_WRITE_BYTE, "SMBus send byte"},
    {I2C_FUNC_SMBUS_READ_BYTE_DATA, "SMBus read byte data"},
    {I2C_FUNC_SMBUS_WRITE_BYTE_DATA, "SMBus write byte data"},
    {I2C_FUNC_SMBUS_READ_WORD_DATA, "SMBus read word data"},
    {I2C_FUNC_SMBUS_WRITE_WORD_DATA, "SMBus write word data"},
    {I2C_FUNC_SMBUS_READ_I2C_BLOCK, "SMBus I2C block read"},
    {I2C_FUNC_SMBUS_WRITE_I2C_BLOCK, "SMBus I2C block write"},
}};

}  // namespace

unsigned long LinuxI2cBus::defaultRequiredFunctions() {
    return I2C_FUNC_SMBUS_BYTE | I2C_FUNC_SMBUS_BYTE_DATA | I2C_FUNC_SMBUS_I2C_BLOCK;
}

std::string LinuxI2cBus::describeFunctions(unsigned long mask) {
    std::string out;
    for (const auto& f : kFunctionNames) {
        if ((mask & f.bit) != 0) {
            out += out.empty() ? "" : ", ";
            out += f.name;
        }
    }
    return out;
}

Result<std::unique_ptr<LinuxI2cBus>> LinuxI2cBus::open(const std::string& path,
                                                       unsigned long requiredFunctions) {
    UniqueFd fd(::open(path.c_str(), O_RDWR | O_CLOEXEC));
    if (!fd.isValid()) {
        return errnoError(errno, "cannot open I2C bus '" + path + "'");
    }
    unsigned long functions = 0;
    if (::ioctl(fd.get(), I2C_FUNCS, &functions) < 0) {
        return errnoError(errno, "I2C bus '" + path + "': I2C_FUNCS failed");
    }
    const unsigned long missing = requiredFunctions & ~functions;
    if (missing != 0) {
        return Error{EOPNOTSUPP, "I2C bus '" + path + "' lacks " + describeFunctions(missing) +
                                     " (it has: " + describeFunctions(functions) + ")"};
    }
    return std::unique_ptr<LinuxI2cBus>(new LinuxI2cBus(path, std::move(fd), functions));
}

LinuxI2cBus::LinuxI2cBus(std::string path, UniqueFd fd, unsigned long functions)
    : path_(std::move(path)), fd_(std::move(fd)), functions_(functions) {}

std::string LinuxI2cBus::adapterName() const {
    // /dev/i2c-N -> /sys/class/i2c-dev/i2c-N/name
    const auto slash = path_.rfind('/');
    std::ifstream in("/sys/class/i2c-dev/" + path_.substr(slash + 1) + "/name");
    std::string name;
    std::getline(in, name);
    return name;
}

int LinuxI2cBus::target(std::uint8_t address) {
    if (currentAddress_ == address) {
        return 0;
    }
    if (::ioctl(fd_.get(), I2C_SLAVE, static_cast<unsigned long>(address)) < 0) {
        currentAddress_ = -1;
        return -errno;  // EBUSY: a kernel driver owns the address
    }
    currentAddress_ = address;
    return 0;
}

int LinuxI2cBus::finish(int result, std::size_t wireBytes) {
    counters_.count(wireBytes, result >= 0);
    return result < 0 ? result : 0;
}

int LinuxI2cBus::readByte(std::uint8_t address, std::uint8_t& value) {
    if (int err = target(address); err < 0) {
        return finish(err, 0);
    }
    const int r = i2c_smbus_read_byte(fd_.get());
    if (r >= 0) {
        value = static_cast<std::uint8_t>(r);
    }
    return finish(r, 2);
}

int LinuxI2cBus::writeByte(std::uint8_t address, std::uint8_t value) {
    if (int err = target(address); err < 0) {
        return finish(err, 0);
    }
    return finish(i2c_smbus_write_byte(fd_.get(), value), 2);
}

int LinuxI2cBus::readByteData(std::uint8_t address, std::uint8_t reg, std::uint8_t& value) {
    if (int err = target(address); err < 0) {
        return finish(err, 0);
    }
    const int r = i2c_smbus_read_byte_data(fd_.get(), reg);
    if (r >= 0) {
        value = static_cast<std::uint8_t>(r);
    }
    return finish(r, 4);
}

int LinuxI2cBus::writeByteData(std::uint8_t address, std::uint8_t reg, std::uint8_t value) {
    if (int err = target(address); err < 0) {
        return finish(err, 0);
    }
    return finish(i2c_smbus_write_byte_data(fd_.get(), reg, value), 3);
}

int LinuxI2cBus::readWordData(std::uint8_t address, std::uint8_t reg, std::uint16_t& value) {
    if ((functions_ & I2C_FUNC_SMBUS_READ_WORD_DATA) == 0) {
        return finish(-EOPNOTSUPP, 0);
    }
    if (int err = target(address); err < 0) {
        return finish(err, 0);
    }
    const int r = i2c_smbus_read_word_data(fd_.get(), reg);
    if (r >= 0) {
        value = static_cast<std::uint16_t>(r);
    }
    return finish(r, 5);
}

int LinuxI2cBus::writeWordData(std::uint8_t address, std::uint8_t reg, std::uint16_t value) {
    if ((functions_ & I2C_FUNC_SMBUS_WRITE_WORD_DATA) == 0) {
        return finish(-EOPNOTSUPP, 0);
    }
    if (int err = target(address); err < 0) {
        return finish(err, 0);
    }
    return finish(i2c_smbus_write_word_data(fd_.get(), reg, value), 4);
}

int LinuxI2cBus::readI2cBlock(std::uint8_t address, std::uint8_t reg, std::span<std::uint8_t> out) {
    if (out.empty() || out.size() > kI2cBlockMax) {
        return -EINVAL;
    }
    if (int err = target(address); err < 0) {
        return finish(err, 0);
    }
    const int r = i2c_smbus_read_i2c_block_data(fd_.get(), reg,
                                                static_cast<std::uint8_t>(out.size()), out.data());
    if (r >= 0 && static_cast<std::size_t>(r) != out.size()) {
        return finish(-EIO, 3 + static_cast<std::size_t>(r));  // a short block
    }
    return finish(r, 3 + out.size());
}

int LinuxI2cBus::writeI2cBlock(std::uint8_t address, std::uint8_t reg,
                               std::span<const std::uint8_t> data) {
    if (data.empty() || data.size() > kI2cBlockMax) {
        return -EINVAL;
    }
    if (int err = target(address); err < 0) {
        return finish(err, 0);
    }
    return finish(i2c_smbus_write_i2c_block_data(
                      fd_.get(), reg, static_cast<std::uint8_t>(data.size()), data.data()),
                  2 + data.size());
}

}  // namespace caphub::hal
