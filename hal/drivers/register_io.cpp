#include "hal/drivers/register_io.h"

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstdio>
#include <cstring>

namespace caphub::hal {

int I2cRegisterIo::read(std::uint8_t reg, std::span<std::uint8_t> out) {
    if (out.size() == 1) {
        return bus_.readByteData(address_, reg, out[0]);
    }
    std::size_t done = 0;
    while (done < out.size()) {
        const std::size_t n = std::min(kI2cBlockMax, out.size() - done);
        const auto start = static_cast<std::uint8_t>(reg + done);
        if (int r = bus_.readI2cBlock(address_, static_cast<std::uint8_t>(start | multiByteFlag_),
                                      out.subspan(done, n));
            r < 0) {
            return r;
        }
        done += n;
    }
    return 0;
}

int I2cRegisterIo::write(std::uint8_t reg, std::uint8_t value) {
    return bus_.writeByteData(address_, reg, value);
}

std::string I2cRegisterIo::describe() const {
    char addr[8];
    std::snprintf(addr, sizeof addr, "0x%02x", address_);
    return bus_.name() + " " + addr;
}

int SpiRegisterIo::read(std::uint8_t reg, std::span<std::uint8_t> out) {
    if (out.empty() || out.size() + 1 > kMaxTransfer) {
        return -EINVAL;
    }
    std::array<std::uint8_t, kMaxTransfer> tx{};
    std::array<std::uint8_t, kMaxTransfer> rx{};
    tx[0] = static_cast<std::uint8_t>(reg | readFlag_ | (out.size() > 1 ? multiByteFlag_ : 0));
    const std::size_t len = out.size() + 1;
    if (int r = bus_.transfer(std::span(tx.data(), len), std::span(rx.data(), len)); r < 0) {
        return r;
    }
    std::memcpy(out.data(), rx.data() + 1, out.size());
    return 0;
}

int SpiRegisterIo::write(std::uint8_t reg, std::uint8_t value) {
    const std::array<std::uint8_t, 2> tx{static_cast<std::uint8_t>(reg & ~readFlag_), value};
    std::array<std::uint8_t, 2> rx{};
    return bus_.transfer(tx, rx);
}

}  // namespace caphub::hal
