// Simulated buses and data-ready lines: the same seams as the Linux backends, routed to chip
// models on the simulation clock. An I2C transaction reaches the device at its address that is
// on the bus itself or behind a mux channel that is open; none answering is a NACK (-ENXIO),
// two answering garble the read (-EIO).
#pragma once

#include <string>
#include <vector>

#include "hal/core/clock.h"
#include "hal/data_ready.h"
#include "hal/i2c_bus.h"
#include "hal/sim/device_model.h"
#include "hal/sim/imu_models.h"
#include "hal/spi_bus.h"

namespace caphub::hal::sim {

class SimI2cBus final : public I2cBus {
public:
    SimI2cBus(std::string name, Clock& clock) : name_(std::move(name)), clock_(clock) {}

    // A device at an address, on the bus itself (mux == nullptr) or behind a mux channel.
    void attach(I2cDeviceModel& device, std::uint8_t address, const Tca9548aModel* mux = nullptr,
                int channel = -1);

    int readByte(std::uint8_t address, std::uint8_t& value) override;
    int writeByte(std::uint8_t address, std::uint8_t value) override;
    int readByteData(std::uint8_t address, std::uint8_t reg, std::uint8_t& value) override;
    int writeByteData(std::uint8_t address, std::uint8_t reg, std::uint8_t value) override;
    int readWordData(std::uint8_t address, std::uint8_t reg, std::uint16_t& value) override;
    int writeWordData(std::uint8_t address, std::uint8_t reg, std::uint16_t value) override;
    int readI2cBlock(std::uint8_t address, std::uint8_t reg, std::span<std::uint8_t> out) override;
    int writeI2cBlock(std::uint8_t address, std::uint8_t reg,
                      std::span<const std::uint8_t> data) override;

    std::string name() const override { return name_; }
    const BusCounters& counters() const override { return counters_; }

private:
    struct Attached {
        I2cDeviceModel* device;
        std::uint8_t address;
        const Tca9548aModel* mux;
        int channel;
    };

    // The one device answering at address, or -ENXIO / -EIO.
    int route(std::uint8_t address, I2cDeviceModel*& device) const;
    // Register write, then optional read with a repeated start.
    int transfer(std::uint8_t address, std::span<const std::uint8_t> write,
                 std::span<std::uint8_t> read, std::size_t wireBytes);

    std::string name_;
    Clock& clock_;
    std::vector<Attached> devices_;
    BusCounters counters_;
};

// One chip select of a simulated SPI bus.
class SimSpiBus final : public SpiBus {
public:
    SimSpiBus(std::string name, Clock& clock, SpiDeviceModel& device)
        : name_(std::move(name)), clock_(clock), device_(device) {}

    int transfer(std::span<const std::uint8_t> tx, std::span<std::uint8_t> rx) override;
    std::string name() const override { return name_; }
    const BusCounters& counters() const override { return counters_; }

private:
    std::string name_;
    Clock& clock_;
    SpiDeviceModel& device_;
    BusCounters counters_;
};

// A chip model's data-ready line on the simulation clock: its edges are the chip's sample
// instants while its interrupt is enabled; waiting sleeps on the clock (instantly when stepped).
class SimDataReadyLine final : public DataReadyLine {
public:
    SimDataReadyLine(std::string name, Clock& clock, const DataReadyModel& chip)
        : name_(std::move(name)), clock_(clock), chip_(chip), last_(clock.now()) {}

    int waitEdge(Duration timeout, Timestamp& edgeTime) override;
    int readEdge(Timestamp& edgeTime) override;
    bool isTimer() const override { return false; }
    std::string name() const override { return name_; }

    // The next edge not yet taken, if the chip will raise one. Like the kernel's bounded event
    // queue, edges older than kBacklog are dropped rather than replayed.
    std::optional<Timestamp> nextEdge() const;
    static constexpr Duration kBacklog = std::chrono::milliseconds(100);

private:
    std::string name_;
    Clock& clock_;
    const DataReadyModel& chip_;
    Timestamp last_;  // the last edge taken (edges before the line existed are not replayed)
};

// Waits on several simulated lines: sleeps until the earliest pending edge.
class SimDataReadyWaiter final : public DataReadyWaiter {
public:
    explicit SimDataReadyWaiter(Clock& clock) : clock_(clock) {}
    int add(DataReadyLine& line) override;
    int wait(Duration timeout, std::span<int> ready) override;

private:
    Clock& clock_;
    std::vector<SimDataReadyLine*> lines_;
};

}  // namespace caphub::hal::sim
