#include "hal/linux/linux_spi_bus.h"

#include <cerrno>
#include <utility>

#include <fcntl.h>
#include <linux/spi/spidev.h>
#include <sys/ioctl.h>

namespace caphub::hal {

namespace {

// Writes a setting, reads it back, and checks the device took it.
template <typename T>
Result<void> configure(int fd, unsigned long writeReq, unsigned long readReq, T value,
                       const std::string& path, const char* what) {
    if (::ioctl(fd, writeReq, &value) < 0) {
        return errnoError(errno, "SPI device '" + path + "': cannot set " + what);
    }
    T readBack{};
    if (::ioctl(fd, readReq, &readBack) < 0) {
        return errnoError(errno, "SPI device '" + path + "': cannot read back " + what);
    }
    if (readBack != value) {
        return Error{EINVAL, "SPI device '" + path + "' did not accept " + what + " " +
                                 std::to_string(value) + " (it has " + std::to_string(readBack) +
                                 ")"};
    }
    return {};
}

}  // namespace

Result<std::unique_ptr<LinuxSpiBus>> LinuxSpiBus::open(const std::string& path,
                                                       const SpiConfig& config) {
    UniqueFd fd(::open(path.c_str(), O_RDWR | O_CLOEXEC));
    if (!fd.isValid()) {
        return errnoError(errno, "cannot open SPI device '" + path + "'");
    }
    if (auto r = configure<std::uint8_t>(fd.get(), SPI_IOC_WR_MODE, SPI_IOC_RD_MODE, config.mode,
                                         path, "mode");
        !r) {
        return r.error();
    }
    if (auto r =
            configure<std::uint8_t>(fd.get(), SPI_IOC_WR_BITS_PER_WORD, SPI_IOC_RD_BITS_PER_WORD,
                                    config.bitsPerWord, path, "bits per word");
        !r) {
        return r.error();
    }
    if (auto r =
            configure<std::uint32_t>(fd.get(), SPI_IOC_WR_MAX_SPEED_HZ, SPI_IOC_RD_MAX_SPEED_HZ,
                                     config.clockHz, path, "clock (Hz)");
        !r) {
        return r.error();
    }
    return std::unique_ptr<LinuxSpiBus>(new LinuxSpiBus(path, std::move(fd), config));
}

LinuxSpiBus::LinuxSpiBus(std::string path, UniqueFd fd, const SpiConfig& config)
    : path_(std::move(path)), fd_(std::move(fd)), config_(config) {}

int LinuxSpiBus::transfer(std::span<const std::uint8_t> tx, std::span<std::uint8_t> rx) {
    if (tx.size() != rx.size() || tx.empty()) {
        return -EINVAL;
    }
    spi_ioc_transfer xfer{};
    xfer.tx_buf = reinterpret_cast<std::uintptr_t>(tx.data());
    xfer.rx_buf = reinterpret_cast<std::uintptr_t>(rx.data());
    xfer.len = static_cast<std::uint32_t>(tx.size());
    xfer.speed_hz = config_.clockHz;
    xfer.bits_per_word = config_.bitsPerWord;
    const int r = ::ioctl(fd_.get(), SPI_IOC_MESSAGE(1), &xfer);
    const int result = r < 0 ? -errno : 0;
    counters_.count(tx.size(), result == 0);
    return result;
}

}  // namespace caphub::hal
