// A suit's hardware as the runtime drives it: for every physical bus, the bus itself (and its
// muxes), each sensor's driver and data-ready line, and a waiter over those lines. Built from a
// Board either on the hub's real buses (openLinuxSuit) or on the virtual suit (board/sim).
#pragma once

#include <memory>
#include <vector>

#include "board/board.h"
#include "hal/core/clock.h"
#include "hal/core/error.h"
#include "hal/data_ready.h"
#include "hal/drivers/imu_driver.h"
#include "hal/drivers/register_io.h"
#include "hal/i2c_bus.h"
#include "hal/spi_bus.h"
#include "hal/tca9548a.h"

namespace caphub::board {

struct SensorHardware {
    int sensor = -1;  // index into Board::sensors
    std::unique_ptr<hal::ImuDriver> driver;
    std::unique_ptr<hal::DataReadyLine> line;  // the chip's line, or a timer at its rate
};

struct BusHardware {
    int bus = -1;  // index into Board::buses
    std::unique_ptr<hal::I2cBus> i2c;
    std::vector<std::unique_ptr<hal::SpiBus>> spi;  // one per chip select
    std::vector<std::unique_ptr<hal::Tca9548a>> muxes;
    std::vector<SensorHardware> sensors;
    std::unique_ptr<hal::DataReadyWaiter> waiter;

    // The bus's accounting (for SPI, the first chip select's device).
    const hal::BusCounters* counters() const;
};

struct SuitHardware {
    std::vector<BusHardware> buses;
    Clock* clock = nullptr;
    // What else must live as long as the buses (the virtual suit's chip models and motion).
    std::shared_ptr<void> keepAlive;
};

// The driver configuration of a sensor of the board.
hal::ImuConfig imuConfigFor(const SensorConfig& sensor);

// The driver for a sensor's chip, on the register interfaces of its dies (the magnetometer's
// interface is used only by chips that have a separate magnetometer die).
Result<std::unique_ptr<hal::ImuDriver>> makeDriver(const SensorConfig& sensor,
                                                   hal::BusProtocol protocol,
                                                   std::unique_ptr<hal::RegisterIo> imu,
                                                   std::unique_ptr<hal::RegisterIo> mag);

// Register interfaces of a sensor on an I2C bus (or mux channel) or on SPI chip selects,
// with each chip's read and auto-increment flags.
std::unique_ptr<hal::RegisterIo> i2cRegisters(const SensorConfig& sensor, hal::I2cBus& bus,
                                              bool magnetometer);
std::unique_ptr<hal::RegisterIo> spiRegisters(const SensorConfig& sensor, hal::SpiBus& bus,
                                              bool magnetometer);

// Adds a TCA9548A decorator for each of the board's muxes on the bus and makes them siblings
// (selecting a channel on one closes the others).
void addMuxes(BusHardware& hw, const Board& board);

// The bus a sensor's registers are reached on: its mux channel, or the bus itself.
hal::I2cBus& sensorBus(BusHardware& hw, const Board& board, const SensorConfig& sensor);

// Opens the board's real buses (i2c-dev, spidev), muxes, drivers and data-ready lines (libgpiod,
// or a timer for sensors without one). Errors name the device and what failed.
Result<SuitHardware> openLinuxSuit(const Board& board, Clock& clock);

}  // namespace caphub::board
