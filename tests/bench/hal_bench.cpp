// The driver read path on the chip models: ns per sample per chip, through the simulated bus
// (and mux), including the model's register emulation and quantisation.
#include <benchmark/benchmark.h>

#include "hal/drivers/icm20948.h"
#include "hal/drivers/icm20948_registers.h"
#include "hal/drivers/lis3mdl_registers.h"
#include "hal/drivers/lsm6dsox_lis3mdl.h"
#include "hal/drivers/lsm6dsox_registers.h"
#include "hal/sim/sim_bus.h"
#include "hal/tca9548a.h"

namespace caphub::hal {
namespace {

void start(ImuDriver& d, SimulatedClock& clock) {
    for (int i = 0; i < 100 && d.state() != ImuDriver::State::Running; ++i) {
        clock.advanceTo(std::max(clock.now(), d.nextServiceTime()));
        (void)d.service(clock.now());
    }
}

// Reads samples at the chip's rate on a stepped clock: each iteration is one sample.
void readLoop(benchmark::State& state, ImuDriver& driver, SimulatedClock& clock,
              const sim::DataReadyModel& chip) {
    start(driver, clock);
    if (driver.state() != ImuDriver::State::Running) {
        state.SkipWithError("driver did not start");
        return;
    }
    ImuSample s;
    for (auto _ : state) {
        const Timestamp t = *chip.nextDataReady(clock.now());
        clock.advanceTo(t);
        if (driver.readSample(t, s) != 0) {
            state.SkipWithError("read failed");
            return;
        }
        benchmark::DoNotOptimize(s);
    }
    state.SetItemsProcessed(state.iterations());
}

void BM_Icm20948_I2c(benchmark::State& state) {
    SimulatedClock clock(timestampFromNs(1'000'000));
    sim::SimI2cBus bus("sim", clock);
    sim::Icm20948Model model;
    bus.attach(model, 0x68);
    Icm20948 driver(std::make_unique<I2cRegisterIo>(bus, 0x68), Icm20948::Interface::I2c, "icm",
                    {});
    readLoop(state, driver, clock, model);
}
BENCHMARK(BM_Icm20948_I2c);

void BM_Icm20948_I2cBehindMux(benchmark::State& state) {
    SimulatedClock clock(timestampFromNs(1'000'000));
    sim::SimI2cBus bus("sim", clock);
    sim::Tca9548aModel muxModel;
    sim::Icm20948Model model;
    bus.attach(muxModel, 0x70);
    bus.attach(model, 0x68, &muxModel, 3);
    Tca9548a mux(bus, 0x70, "mux0");
    Icm20948 driver(std::make_unique<I2cRegisterIo>(mux.channel(3), 0x68), Icm20948::Interface::I2c,
                    "icm", {});
    readLoop(state, driver, clock, model);
}
BENCHMARK(BM_Icm20948_I2cBehindMux);

void BM_Icm20948_Spi(benchmark::State& state) {
    SimulatedClock clock(timestampFromNs(1'000'000));
    sim::Icm20948Model model;
    sim::SimSpiBus spi("spi", clock, model);
    Icm20948 driver(std::make_unique<SpiRegisterIo>(spi, icm20948::kSpiRead),
                    Icm20948::Interface::Spi, "icm", {});
    readLoop(state, driver, clock, model);
}
BENCHMARK(BM_Icm20948_Spi);

void BM_Lsm6dsoxLis3mdl_I2c(benchmark::State& state) {
    SimulatedClock clock(timestampFromNs(1'000'000));
    sim::SimI2cBus bus("sim", clock);
    sim::Lsm6dsoxModel imu;
    sim::Lis3mdlModel mag;
    bus.attach(imu, 0x6A);
    bus.attach(mag, 0x1C);
    ImuConfig config;
    config.odrHz = 104;
    config.magOdrHz = 80;
    Lsm6dsoxLis3mdl driver(std::make_unique<I2cRegisterIo>(bus, 0x6A),
                           std::make_unique<I2cRegisterIo>(bus, 0x1C, lis3mdl::kI2cAutoIncrement),
                           "lsm", config);
    readLoop(state, driver, clock, imu);
}
BENCHMARK(BM_Lsm6dsoxLis3mdl_I2c);

}  // namespace
}  // namespace caphub::hal
