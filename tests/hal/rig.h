// Test helpers: a driver started against its chip model on a stepped simulation clock.
#pragma once

#include <cerrno>

#include <gtest/gtest.h>

#include "hal/core/clock.h"
#include "hal/drivers/imu_driver.h"

namespace caphub::hal::testing {

// Runs the start-up state machine on the stepped clock until the driver is Running (or a
// simulated second has passed). Returns the last service() result.
inline int startDriver(ImuDriver& driver, SimulatedClock& clock) {
    int r = -EAGAIN;
    for (int i = 0; i < 100 && driver.state() != ImuDriver::State::Running; ++i) {
        clock.advanceTo(std::max(clock.now(), driver.nextServiceTime()));
        r = driver.service(clock.now());
    }
    return r;
}

}  // namespace caphub::hal::testing
