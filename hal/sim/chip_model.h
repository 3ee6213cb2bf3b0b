// The common part of the register-level chip models: a register file per bank with a register
// pointer, a sample schedule at the configured rate, and fault injection (NACK for a while,
// reset to defaults, corrupted bytes, a stuck data-ready line).
#pragma once

#include <array>
#include <cstdint>

#include "hal/sim/device_model.h"

namespace caphub::hal::sim {

struct FaultCounters {
    std::uint64_t nacks = 0;
    std::uint64_t corruptedBytes = 0;
};

class ChipModel : public I2cDeviceModel, public SpiDeviceModel, public DataReadyModel {
public:
    ChipModel() = default;

    // --- Faults ---
    // The chip does not acknowledge any transaction before `until`.
    void nackUntil(Timestamp until) { nackUntil_ = until; }
    // The next `count` bytes read from the chip have a bit flipped.
    void corruptNextReads(int count) { corruptReads_ = count; }
    // The data-ready line stops toggling (stuck at a level) until released.
    void setDataReadyStuck(bool stuck) { dataReadyStuck_ = stuck; }
    // The chip loses its configuration, as after a brown-out.
    virtual void resetToDefaults() = 0;

    const FaultCounters& faults() const { return faults_; }

    // --- I2C / SPI ---
    int i2cWrite(Timestamp now, std::span<const std::uint8_t> bytes) override;
    int i2cRead(Timestamp now, std::span<std::uint8_t> out) override;
    int spiTransfer(Timestamp now, std::span<const std::uint8_t> tx,
                    std::span<std::uint8_t> rx) override;

    // --- Samples ---
    std::optional<Timestamp> nextDataReady(Timestamp after) const override;
    // The sample period while sampling, or zero when not sampling.
    virtual Duration samplePeriod() const = 0;
    // Brings the data registers up to `now` (the latest sample instant at or before now).
    void update(Timestamp now);
    void setSource(PhysicalSource* source) { source_ = source; }

protected:
    // Register access with side effects, in the current bank.
    virtual std::uint8_t readRegister(Timestamp now, std::uint8_t reg) = 0;
    virtual void writeRegister(Timestamp now, std::uint8_t reg, std::uint8_t value) = 0;
    // Whether a multi-byte access starting at reg increments the address (I2C flag already
    // stripped by decodeI2cRegister).
    virtual bool autoIncrement(std::uint8_t firstByte) const { return (void)firstByte, true; }
    virtual std::uint8_t decodeI2cRegister(std::uint8_t firstByte) const { return firstByte; }
    // SPI address byte -> (is read, register, auto-increment).
    virtual void decodeSpi(std::uint8_t cmd, bool& read, std::uint8_t& reg, bool& inc) const;
    // Latches one sample taken at t into the data registers.
    virtual void latchSample(Timestamp t, const PhysicalInput& in) = 0;
    // Whether the data-ready line toggles (interrupt enabled and sampling).
    virtual bool dataReadyEnabled() const = 0;

    // Restarts the sample schedule at t (when the rate or power state changes).
    void restartSchedule(Timestamp t) {
        epoch_ = t;
        latched_ = -1;
    }

    PhysicalSource* source_ = nullptr;

private:
    bool nacking(Timestamp now);
    std::uint8_t maybeCorrupt(std::uint8_t v);

    std::uint8_t pointer_ = 0;
    bool pointerIncrements_ = true;
    Timestamp nackUntil_{};
    int corruptReads_ = 0;
    bool dataReadyStuck_ = false;
    FaultCounters faults_;
    Timestamp epoch_{};
    std::int64_t latched_ = -1;  // index of the latched sample
    ConstantSource defaultSource_;
};

}  // namespace caphub::hal::sim
