#include "board/hardware.h"

#include <fmt/format.h>

#include "hal/drivers/icm20948.h"
#include "hal/drivers/icm20948_registers.h"
#include "hal/drivers/lis3mdl_registers.h"
#include "hal/drivers/lsm6dsox_lis3mdl.h"
#include "hal/drivers/lsm6dsox_registers.h"
#include "hal/drivers/register_io.h"
#include "hal/linux/gpiod_line.h"
#include "hal/linux/linux_i2c_bus.h"
#include "hal/linux/linux_spi_bus.h"

namespace caphub::board {

namespace {

bool isIcm(const SensorConfig& s) {
    return s.chip != nullptr && s.chip->name == "icm20948";
}

}  // namespace

const hal::BusCounters* BusHardware::counters() const {
    if (i2c) {
        return &i2c->counters();
    }
    return spi.empty() ? nullptr : &spi.front()->counters();
}

hal::ImuConfig imuConfigFor(const SensorConfig& sensor) {
    hal::ImuConfig c;
    c.odrHz = sensor.achievedOdrHz > 0 ? sensor.achievedOdrHz : sensor.odrHz;
    c.magOdrHz = sensor.magOdrHz;
    c.accelRangeG = sensor.accelRangeG;
    c.gyroRangeDps = sensor.gyroRangeDps;
    c.dataReadyInterrupt = true;  // also raised when polled: harmless, and one table for both
    return c;
}

std::unique_ptr<hal::RegisterIo> i2cRegisters(const SensorConfig& sensor, hal::I2cBus& bus,
                                              bool magnetometer) {
    if (magnetometer) {
        return std::make_unique<hal::I2cRegisterIo>(bus, sensor.magAddress.value_or(0),
                                                    hal::lis3mdl::kI2cAutoIncrement);
    }
    return std::make_unique<hal::I2cRegisterIo>(bus, sensor.address);
}

std::unique_ptr<hal::RegisterIo> spiRegisters(const SensorConfig& sensor, hal::SpiBus& bus,
                                              bool magnetometer) {
    if (magnetometer) {
        return std::make_unique<hal::SpiRegisterIo>(bus, hal::lis3mdl::kSpiRead,
                                                    hal::lis3mdl::kSpiAutoIncrement);
    }
    (void)sensor;
    return std::make_unique<hal::SpiRegisterIo>(bus, 0x80);  // ICM-20948 and LSM6DSOX
}

Result<std::unique_ptr<hal::ImuDriver>> makeDriver(const SensorConfig& sensor,
                                                   hal::BusProtocol protocol,
                                                   std::unique_ptr<hal::RegisterIo> imu,
                                                   std::unique_ptr<hal::RegisterIo> mag) {
    if (isIcm(sensor)) {
        // On SPI the driver also disables the chip's I2C slave interface.
        const bool spi = protocol == hal::BusProtocol::Spi;
        return std::unique_ptr<hal::ImuDriver>(std::make_unique<hal::Icm20948>(
            std::move(imu), spi ? hal::Icm20948::Interface::Spi : hal::Icm20948::Interface::I2c,
            sensor.name, imuConfigFor(sensor)));
    }
    if (sensor.chip != nullptr && sensor.chip->name == "lsm6dsox+lis3mdl") {
        if (!mag) {
            return Error{EINVAL, "sensor '" + sensor.name + "': no magnetometer interface"};
        }
        return std::unique_ptr<hal::ImuDriver>(std::make_unique<hal::Lsm6dsoxLis3mdl>(
            std::move(imu), std::move(mag), sensor.name, imuConfigFor(sensor)));
    }
    return Error{EINVAL, "sensor '" + sensor.name + "': no driver for this chip"};
}

void addMuxes(BusHardware& hw, const Board& board) {
    for (const MuxConfig& m : board.muxes) {
        if (m.bus == hw.bus) {
            hw.muxes.push_back(std::make_unique<hal::Tca9548a>(*hw.i2c, m.address, m.name));
        }
    }
    for (auto& m : hw.muxes) {
        std::vector<hal::Tca9548a*> siblings;
        for (auto& o : hw.muxes) {
            if (o != m) {
                siblings.push_back(o.get());
            }
        }
        m->setSiblings(std::move(siblings));
    }
}

hal::I2cBus& sensorBus(BusHardware& hw, const Board& board, const SensorConfig& sensor) {
    if (sensor.mux >= 0) {
        const std::string& name = board.muxes[static_cast<std::size_t>(sensor.mux)].name;
        for (auto& m : hw.muxes) {
            if (m->name() == name) {
                return m->channel(sensor.channel);
            }
        }
    }
    return *hw.i2c;
}

Result<SuitHardware> openLinuxSuit(const Board& board, Clock& clock) {
    SuitHardware suit;
    suit.clock = &clock;
    for (std::size_t b = 0; b < board.buses.size(); ++b) {
        const BusConfig& bc = board.buses[b];
        if (bc.type == BusType::Sim) {
            return Error{EINVAL, "bus '" + bc.name +
                                     "' is simulated: run it on the virtual suit, not the hub's "
                                     "buses"};
        }
        BusHardware hw;
        hw.bus = static_cast<int>(b);
        auto waiter = hal::EpollDataReadyWaiter::create();
        if (!waiter) {
            return waiter.error();
        }
        hw.waiter = std::move(*waiter);
        if (bc.type == BusType::I2c) {
            auto bus = hal::LinuxI2cBus::open(bc.device);
            if (!bus) {
                return bus.error();
            }
            hw.i2c = std::move(*bus);
            addMuxes(hw, board);
        }
        for (std::size_t s = 0; s < board.sensors.size(); ++s) {
            const SensorConfig& sc = board.sensors[s];
            if (sc.bus != hw.bus) {
                continue;
            }
            std::unique_ptr<hal::RegisterIo> imu;
            std::unique_ptr<hal::RegisterIo> mag;
            if (bc.type == BusType::I2c) {
                hal::I2cBus* bus = &sensorBus(hw, board, sc);
                imu = i2cRegisters(sc, *bus, false);
                if (sc.magAddress) {
                    mag = i2cRegisters(sc, *bus, true);
                }
            } else {
                hal::SpiConfig spiConfig;
                spiConfig.clockHz = static_cast<std::uint32_t>(bc.clockHz);
                auto open = [&](int cs) -> Result<hal::SpiBus*> {
                    auto dev =
                        hal::LinuxSpiBus::open(fmt::format("{}.{}", bc.device, cs), spiConfig);
                    if (!dev) {
                        return dev.error();
                    }
                    hw.spi.push_back(std::move(*dev));
                    return hw.spi.back().get();
                };
                auto imuBus = open(sc.chipSelect);
                if (!imuBus) {
                    return imuBus.error();
                }
                imu = spiRegisters(sc, **imuBus, false);
                if (sc.magChipSelect >= 0) {
                    auto magBus = open(sc.magChipSelect);
                    if (!magBus) {
                        return magBus.error();
                    }
                    mag = spiRegisters(sc, **magBus, true);
                }
            }
            auto driver = makeDriver(sc, bc.protocol, std::move(imu), std::move(mag));
            if (!driver) {
                return driver.error();
            }
            SensorHardware sh;
            sh.sensor = static_cast<int>(s);
            sh.driver = std::move(*driver);
            if (sc.dataReady) {
                auto line = hal::GpiodDataReadyLine::open(sc.dataReady->chip, sc.dataReady->offset,
                                                          "caphub:" + sc.name);
                if (!line) {
                    return line.error();
                }
                sh.line = std::move(*line);
            } else {
                auto timer = hal::TimerDataReadyLine::open(periodFromHz(sc.achievedOdrHz),
                                                           "timer:" + sc.name);
                if (!timer) {
                    return timer.error();
                }
                sh.line = std::move(*timer);
            }
            if (int r = hw.waiter->add(*sh.line); r < 0) {
                return errnoError(r, "data-ready line " + sh.line->name() + ": epoll");
            }
            hw.sensors.push_back(std::move(sh));
        }
        suit.buses.push_back(std::move(hw));
    }
    return suit;
}

}  // namespace caphub::board
