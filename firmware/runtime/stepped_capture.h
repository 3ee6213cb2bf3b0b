// The capture of a virtual suit on one thread against a stepped clock: the same bus workers,
// drivers and chip models as `caphub run`, but deterministic (the same seed gives the same
// samples, bit for bit) and as fast as the machine allows, handing each sample to a callback.
// For `caphub sim`, calibrate, selftest, tests and benchmarks that want the raw samples; the
// stepped run of a whole pipeline (stages, commands) is Capture's stepped mode (the Hub's).
#pragma once

#include <functional>
#include <memory>
#include <vector>

#include "board/hardware.h"
#include "firmware/runtime/bus_worker.h"
#include "hal/core/clock.h"

namespace caphub::firmware {

class SteppedCapture {
public:
    using SampleFn = std::function<void(const SensorSample&)>;
    using EventFn = std::function<void(const RuntimeEvent&)>;

    // The longest a bus waits for data-ready edges before the next bus takes its turn.
    static constexpr Duration kMaxStep = std::chrono::milliseconds(1);

    // The clock must be a stepped SimulatedClock driving the suit's simulated buses.
    SteppedCapture(board::SuitHardware& suit, SimulatedClock& clock,
                   const BusWorker::Options& options = {});

    // Runs every bus in turn until the clock reaches `end`, handing each sample and event on as
    // it is read. Each sensor's samples come in order; buses interleave within one sample period.
    void runUntil(Timestamp end, const SampleFn& onSample, const EventFn& onEvent = {});

    const std::vector<std::unique_ptr<BusWorker>>& workers() const { return workers_; }

private:
    SimulatedClock& clock_;
    std::vector<std::unique_ptr<BusWorker>> workers_;
};

}  // namespace caphub::firmware
