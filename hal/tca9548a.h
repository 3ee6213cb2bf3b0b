// TCA9548A 1-to-8 I2C switch as a bus decorator: each channel is an I2cBus whose operations
// first select that channel on the switch (only when it changes, the selection is cached), so a
// driver behind the mux does not know it is there. Failures of the switch itself are counted and
// named as the mux's.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "hal/i2c_bus.h"

namespace caphub::hal {

class Tca9548a {
public:
    static constexpr int kChannels = 8;

    Tca9548a(I2cBus& parent, std::uint8_t address, std::string name);
    Tca9548a(const Tca9548a&) = delete;
    Tca9548a& operator=(const Tca9548a&) = delete;

    // The bus seen through channel 0-7.
    I2cBus& channel(int ch) { return channels_[static_cast<std::size_t>(ch)]; }

    // Other switches on the same parent bus: selecting a channel here first closes theirs, or
    // two devices at one address behind two switches would answer together.
    void setSiblings(std::vector<Tca9548a*> siblings) { siblings_ = std::move(siblings); }

    // Writes the control register when the wanted channel is not the cached one.
    [[nodiscard]] int select(int ch);
    // Opens no channel (control register 0).
    [[nodiscard]] int deselect();
    // Forgets the cached selection (after a bus error, the switch's state is unknown).
    void invalidate() { current_ = kUnknown; }

    int selectedChannel() const { return current_; }  // -1: none, -2: unknown
    std::uint8_t address() const { return address_; }
    const std::string& name() const { return name_; }
    std::uint64_t selectWrites() const { return selectWrites_; }
    std::uint64_t selectErrors() const { return selectErrors_; }
    // The -errno of the last failed select (0 if none): tells a device error from a mux error.
    int lastSelectError() const { return lastSelectError_; }

private:
    static constexpr int kNone = -1;
    static constexpr int kUnknown = -2;

    class Channel final : public I2cBus {
    public:
        Channel() = default;
        void bind(Tca9548a* mux, int ch) {
            mux_ = mux;
            ch_ = ch;
        }
        int readByte(std::uint8_t address, std::uint8_t& value) override;
        int writeByte(std::uint8_t address, std::uint8_t value) override;
        int readByteData(std::uint8_t address, std::uint8_t reg, std::uint8_t& value) override;
        int writeByteData(std::uint8_t address, std::uint8_t reg, std::uint8_t value) override;
        int readWordData(std::uint8_t address, std::uint8_t reg, std::uint16_t& value) override;
        int writeWordData(std::uint8_t address, std::uint8_t reg, std::uint16_t value) override;
        int readI2cBlock(std::uint8_t address, std::uint8_t reg,
                         std::span<std::uint8_t> out) override;
        int writeI2cBlock(std::uint8_t address, std::uint8_t reg,
                          std::span<const std::uint8_t> data) override;
        std::string name() const override;
        const BusCounters& counters() const override { return mux_->parent_.counters(); }

    private:
        // Selects this channel, then runs the operation on the parent bus.
        template <typename Op>
        int forward(Op&& op) {
            if (int sel = mux_->select(ch_); sel < 0) {
                return sel;
            }
            return op(mux_->parent_);
        }

        Tca9548a* mux_ = nullptr;
        int ch_ = 0;
    };

    int writeControl(std::uint8_t value, int selected);

    I2cBus& parent_;
    std::uint8_t address_;
    std::string name_;
    std::array<Channel, kChannels> channels_;
    std::vector<Tca9548a*> siblings_;
    int current_ = kUnknown;
    std::uint64_t selectWrites_ = 0;
    std::uint64_t selectErrors_ = 0;
    int lastSelectError_ = 0;
};

}  // namespace caphub::hal
