// Register-level models of the IMU chips caphub drives: the ICM-20948 with its AK09916 behind
// the auxiliary I2C master, the LSM6DSOX and the LIS3MDL. They include the drivers' register
// headers, so both sides agree on one map. Simplifications are listed in docs/hal.md.
#pragma once

#include <array>

#include "hal/sim/chip_model.h"

namespace caphub::hal::sim {

// The AK09916 die: continuous modes, ST1 data-ready released by reading ST2, soft reset.
class Ak09916Model {
public:
    Ak09916Model() { reset(); }
    void reset();
    std::uint8_t read(Timestamp now, std::uint8_t reg);
    void write(Timestamp now, std::uint8_t reg, std::uint8_t value);
    void setSource(PhysicalSource* source) { source_ = source; }
    Duration samplePeriod() const;

private:
    void update(Timestamp now);

    std::array<std::uint8_t, 0x33> regs_{};
    PhysicalSource* source_ = nullptr;
    Timestamp epoch_{};
    std::int64_t latched_ = -1;
    bool fresh_ = false;
};

class Icm20948Model final : public ChipModel {
public:
    Icm20948Model() { resetToDefaults(); }

    void resetToDefaults() override;
    Duration samplePeriod() const override;
    void setPhysicalSource(PhysicalSource* source) {
        setSource(source);
        mag_.setSource(source);
    }
    Ak09916Model& magnetometer() { return mag_; }
    // Register value in a bank, without side effects (for tests).
    std::uint8_t peek(int bank, std::uint8_t reg) const { return regs_[bank][reg & 0x7F]; }
    int bank() const { return bank_; }

protected:
    std::uint8_t readRegister(Timestamp now, std::uint8_t reg) override;
    void writeRegister(Timestamp now, std::uint8_t reg, std::uint8_t value) override;
    void latchSample(Timestamp t, const PhysicalInput& in) override;
    bool dataReadyEnabled() const override;

private:
    void auxSlave4(Timestamp now);

    std::array<std::array<std::uint8_t, 128>, 4> regs_{};
    int bank_ = 0;
    Ak09916Model mag_;
};

class Lsm6dsoxModel final : public ChipModel {
public:
    Lsm6dsoxModel() { resetToDefaults(); }
    void resetToDefaults() override;
    Duration samplePeriod() const override;
    std::uint8_t peek(std::uint8_t reg) const { return regs_[reg & 0x7F]; }

protected:
    std::uint8_t readRegister(Timestamp now, std::uint8_t reg) override;
    void writeRegister(Timestamp now, std::uint8_t reg, std::uint8_t value) override;
    void latchSample(Timestamp t, const PhysicalInput& in) override;
    bool dataReadyEnabled() const override;
    bool autoIncrement(std::uint8_t) const override;
    void decodeSpi(std::uint8_t cmd, bool& read, std::uint8_t& reg, bool& inc) const override;

private:
    std::array<std::uint8_t, 128> regs_{};
};

class Lis3mdlModel final : public ChipModel {
public:
    Lis3mdlModel() { resetToDefaults(); }
    void resetToDefaults() override;
    Duration samplePeriod() const override;
    std::uint8_t peek(std::uint8_t reg) const { return regs_[reg & 0x3F]; }

protected:
    std::uint8_t readRegister(Timestamp now, std::uint8_t reg) override;
    void writeRegister(Timestamp now, std::uint8_t reg, std::uint8_t value) override;
    void latchSample(Timestamp t, const PhysicalInput& in) override;
    bool dataReadyEnabled() const override { return samplePeriod().count() > 0; }
    bool autoIncrement(std::uint8_t firstByte) const override { return (firstByte & 0x80) != 0; }
    std::uint8_t decodeI2cRegister(std::uint8_t firstByte) const override {
        return static_cast<std::uint8_t>(firstByte & 0x7F);
    }
    void decodeSpi(std::uint8_t cmd, bool& read, std::uint8_t& reg, bool& inc) const override;

private:
    std::array<std::uint8_t, 64> regs_{};
};

// TCA9548A: one control register, written and read without a register address.
class Tca9548aModel final : public I2cDeviceModel {
public:
    int i2cWrite(Timestamp now, std::span<const std::uint8_t> bytes) override;
    int i2cRead(Timestamp now, std::span<std::uint8_t> out) override;
    std::uint8_t control() const { return control_; }
    std::uint64_t controlWrites() const { return writes_; }
    void reset() { control_ = 0; }

private:
    std::uint8_t control_ = 0;
    std::uint64_t writes_ = 0;
};

}  // namespace caphub::hal::sim
