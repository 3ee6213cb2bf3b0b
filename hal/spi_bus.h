// The SPI seam: one chip select of an SPI controller, full-duplex transfers. The Linux backend
// is spidev (/dev/spidevB.C); the simulated one routes to a chip model. 0 or -errno, no logging.
#pragma once

#include <cstdint>
#include <span>
#include <string>

#include "hal/bus_counters.h"

namespace caphub::hal {

class SpiBus {
public:
    virtual ~SpiBus() = default;

    // Clocks tx.size() bytes out while clocking as many in; rx.size() must equal tx.size().
    [[nodiscard]] virtual int transfer(std::span<const std::uint8_t> tx,
                                       std::span<std::uint8_t> rx) = 0;

    virtual std::string name() const = 0;
    virtual const BusCounters& counters() const = 0;
};

}  // namespace caphub::hal
