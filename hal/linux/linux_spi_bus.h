// The SPI seam on Linux: one spidev device (/dev/spidevB.C), configured once for mode, clock and
// word size, with full-duplex transfers through SPI_IOC_MESSAGE.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "hal/core/error.h"
#include "hal/linux/unique_fd.h"
#include "hal/spi_bus.h"

namespace caphub::hal {

struct SpiConfig {
    std::uint8_t mode = 3;  // CPOL=1, CPHA=1: what the ICM-20948, LSM6DSOX and LIS3MDL accept
    std::uint32_t clockHz = 1'000'000;
    std::uint8_t bitsPerWord = 8;
};

class LinuxSpiBus final : public SpiBus {
public:
    // Opens and configures the device, reading each setting back. Errors name the device, the
    // setting and the errno text.
    static Result<std::unique_ptr<LinuxSpiBus>> open(const std::string& path,
                                                     const SpiConfig& config);

    int transfer(std::span<const std::uint8_t> tx, std::span<std::uint8_t> rx) override;
    std::string name() const override { return path_; }
    const BusCounters& counters() const override { return counters_; }

private:
    LinuxSpiBus(std::string path, UniqueFd fd, const SpiConfig& config);

    std::string path_;
    UniqueFd fd_;
    SpiConfig config_;
    BusCounters counters_;
};

}  // namespace caphub::hal
