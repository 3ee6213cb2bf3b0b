#include "hal/sim/sim_bus.h"

#include <algorithm>
#include <array>
#include <cerrno>

namespace caphub::hal::sim {

void SimI2cBus::attach(I2cDeviceModel& device, std::uint8_t address, const Tca9548aModel* mux,
                       int channel) {
    devices_.push_back({&device, address, mux, channel});
}

int SimI2cBus::route(std::uint8_t address, I2cDeviceModel*& device) const {
    int found = 0;
    for (const Attached& a : devices_) {
        if (a.address != address) {
            continue;
        }
        if (a.mux != nullptr && (a.mux->control() & (1u << a.channel)) == 0) {
            continue;  // behind a closed channel
        }
        device = a.device;
        ++found;
    }
    if (found == 0) {
        return -ENXIO;
    }
    return found == 1 ? 0 : -EIO;
}

int SimI2cBus::transfer(std::uint8_t address, std::span<const std::uint8_t> write,
                        std::span<std::uint8_t> read, std::size_t wireBytes) {
    I2cDeviceModel* device = nullptr;
    int r = route(address, device);
    const Timestamp now = clock_.now();
    if (r == 0 && !write.empty()) {
        r = device->i2cWrite(now, write);
    }
    if (r == 0 && !read.empty()) {
        r = device->i2cRead(now, read);
    }
    counters_.count(r == 0 ? wireBytes : 1, r == 0);
    return r;
}

int SimI2cBus::readByte(std::uint8_t address, std::uint8_t& value) {
    return transfer(address, {}, std::span(&value, 1), 2);
}

int SimI2cBus::writeByte(std::uint8_t address, std::uint8_t value) {
    return transfer(address, std::span(&value, 1), {}, 2);
}

int SimI2cBus::readByteData(std::uint8_t address, std::uint8_t reg, std::uint8_t& value) {
    return transfer(address, std::span(&reg, 1), std::span(&value, 1), 4);
}

int SimI2cBus::writeByteData(std::uint8_t address, std::uint8_t reg, std::uint8_t value) {
    const std::array<std::uint8_t, 2> bytes{reg, value};
    return transfer(address, bytes, {}, 3);
}

int SimI2cBus::readWordData(std::uint8_t address, std::uint8_t reg, std::uint16_t& value) {
    std::array<std::uint8_t, 2> bytes{};
    const int r = transfer(address, std::span(&reg, 1), bytes, 5);
    if (r == 0) {
        value = static_cast<std::uint16_t>(bytes[0] | (bytes[1] << 8));  // SMBus: low byte first
    }
    return r;
}

int SimI2cBus::writeWordData(std::uint8_t address, std::uint8_t reg, std::uint16_t value) {
    const std::array<std::uint8_t, 3> bytes{reg, static_cast<std::uint8_t>(value & 0xFF),
                                            static_cast<std::uint8_t>(value >> 8)};
    return transfer(address, bytes, {}, 4);
}

int SimI2cBus::readI2cBlock(std::uint8_t address, std::uint8_t reg, std::span<std::uint8_t> out) {
    if (out.empty() || out.size() > kI2cBlockMax) {
        return -EINVAL;
    }
    return transfer(address, std::span(&reg, 1), out, 3 + out.size());
}

int SimI2cBus::writeI2cBlock(std::uint8_t address, std::uint8_t reg,
                             std::span<const std::uint8_t> data) {
    if (data.empty() || data.size() > kI2cBlockMax) {
        return -EINVAL;
    }
    std::array<std::uint8_t, kI2cBlockMax + 1> bytes{};
    bytes[0] = reg;
    std::copy(data.begin(), data.end(), bytes.begin() + 1);
    return transfer(address, std::span(bytes.data(), data.size() + 1), {}, 2 + data.size());
}

int SimSpiBus::transfer(std::span<const std::uint8_t> tx, std::span<std::uint8_t> rx) {
    const int r = device_.spiTransfer(clock_.now(), tx, rx);
    counters_.count(tx.size(), r == 0);
    return r;
}

std::optional<Timestamp> SimDataReadyLine::nextEdge() const {
    return chip_.nextDataReady(std::max(last_, clock_.now() - kBacklog));
}

int SimDataReadyLine::readEdge(Timestamp& edgeTime) {
    const auto next = nextEdge();
    if (!next || *next > clock_.now()) {
        return -EAGAIN;
    }
    edgeTime = *next;
    last_ = *next;
    return 0;
}

int SimDataReadyLine::waitEdge(Duration timeout, Timestamp& edgeTime) {
    const Timestamp deadline = clock_.now() + timeout;
    const auto next = nextEdge();
    if (!next || *next > deadline) {
        clock_.sleepUntil(deadline);
        return -ETIMEDOUT;
    }
    clock_.sleepUntil(*next);
    if (clock_.now() < *next) {
        return -ETIMEDOUT;  // the clock was interrupted: the capture is stopping
    }
    edgeTime = *next;
    last_ = *next;
    return 0;
}

int SimDataReadyWaiter::add(DataReadyLine& line) {
    auto* sim = dynamic_cast<SimDataReadyLine*>(&line);
    if (sim == nullptr) {
        return -EINVAL;
    }
    lines_.push_back(sim);
    return static_cast<int>(lines_.size()) - 1;
}

int SimDataReadyWaiter::wait(Duration timeout, std::span<int> ready) {
    if (ready.empty()) {
        return -EINVAL;
    }
    const Timestamp deadline = clock_.now() + timeout;
    std::optional<Timestamp> earliest;
    for (auto* line : lines_) {
        const auto next = line->nextEdge();
        if (next && (!earliest || *next < *earliest)) {
            earliest = next;
        }
    }
    if (!earliest || *earliest > deadline) {
        clock_.sleepUntil(deadline);
        return 0;
    }
    clock_.sleepUntil(*earliest);
    int n = 0;
    const Timestamp now = clock_.now();
    for (std::size_t i = 0; i < lines_.size() && static_cast<std::size_t>(n) < ready.size(); ++i) {
        const auto next = lines_[i]->nextEdge();
        if (next && *next <= now) {
            ready[static_cast<std::size_t>(n++)] = static_cast<int>(i);
        }
    }
    return n;
}

}  // namespace caphub::hal::sim
