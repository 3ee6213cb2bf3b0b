#include "hal/tca9548a.h"

#include <utility>

namespace caphub::hal {

Tca9548a::Tca9548a(I2cBus& parent, std::uint8_t address, std::string name)
    : parent_(parent), address_(address), name_(std::move(name)) {
    for (int ch = 0; ch < kChannels; ++ch) {
        channels_[static_cast<std::size_t>(ch)].bind(this, ch);
    }
}

int Tca9548a::writeControl(std::uint8_t value, int selected) {
    ++selectWrites_;
    const int r = parent_.writeByte(address_, value);
    if (r < 0) {
        ++selectErrors_;
        lastSelectError_ = r;
        current_ = kUnknown;
        return r;
    }
    lastSelectError_ = 0;
    current_ = selected;
    return 0;
}

int Tca9548a::select(int ch) {
    if (ch < 0 || ch >= kChannels) {
        return -EINVAL;
    }
    if (current_ == ch) {
        return 0;
    }
    for (Tca9548a* other : siblings_) {
        if (other->current_ != kNone) {
            if (int r = other->deselect(); r < 0) {
                return r;
            }
        }
    }
    return writeControl(static_cast<std::uint8_t>(1u << ch), ch);
}

int Tca9548a::deselect() {
    if (current_ == kNone) {
        return 0;
    }
    return writeControl(0, kNone);
}

std::string Tca9548a::Channel::name() const {
    return mux_->name_ + " channel " + std::to_string(ch_) + " (on " + mux_->parent_.name() + ")";
}

int Tca9548a::Channel::readByte(std::uint8_t address, std::uint8_t& value) {
    return forward([&](I2cBus& bus) { return bus.readByte(address, value); });
}
int Tca9548a::Channel::writeByte(std::uint8_t address, std::uint8_t value) {
    return forward([&](I2cBus& bus) { return bus.writeByte(address, value); });
}
int Tca9548a::Channel::readByteData(std::uint8_t address, std::uint8_t reg, std::uint8_t& value) {
    return forward([&](I2cBus& bus) { return bus.readByteData(address, reg, value); });
}
int Tca9548a::Channel::writeByteData(std::uint8_t address, std::uint8_t reg, std::uint8_t value) {
    return forward([&](I2cBus& bus) { return bus.writeByteData(address, reg, value); });
}
int Tca9548a::Channel::readWordData(std::uint8_t address, std::uint8_t reg, std::uint16_t& value) {
    return forward([&](I2cBus& bus) { return bus.readWordData(address, reg, value); });
}
int Tca9548a::Channel::writeWordData(std::uint8_t address, std::uint8_t reg, std::uint16_t value) {
    return forward([&](I2cBus& bus) { return bus.writeWordData(address, reg, value); });
}
int Tca9548a::Channel::readI2cBlock(std::uint8_t address, std::uint8_t reg,
                                    std::span<std::uint8_t> out) {
    return forward([&](I2cBus& bus) { return bus.readI2cBlock(address, reg, out); });
}
int Tca9548a::Channel::writeI2cBlock(std::uint8_t address, std::uint8_t reg,
                                     std::span<const std::uint8_t> data) {
    return forward([&](I2cBus& bus) { return bus.writeI2cBlock(address, reg, data); });
}

}  // namespace caphub::hal
