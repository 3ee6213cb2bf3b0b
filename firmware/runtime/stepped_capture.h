// The raw samples of a virtual suit on a stepped clock, in pieces: a Capture in stepped mode
// (the same bus workers, drivers and chip models as `caphub run`; deterministic, as fast as the
// machine allows) whose only stage hands each sample to a callback. For tests and benchmarks
// that step the suit and look at the samples between steps; commands use the Hub.
#pragma once

#include "board/hardware.h"
#include "firmware/runtime/capture.h"
#include "hal/core/clock.h"

namespace caphub::firmware {

class SteppedCapture {
public:
    using SampleFn = CallbackStage::SampleFn;
    using EventFn = CallbackStage::EventFn;

    // The clock must be a stepped SimulatedClock driving the suit's simulated buses.
    SteppedCapture(board::SuitHardware& suit, SimulatedClock& clock,
                   const BusWorker::Options& options = {});

    // Runs every bus in turn until the clock reaches `end`, handing each sample and event on as
    // it is read. Each sensor's samples come in order; buses interleave within one sample period.
    void runUntil(Timestamp end, const SampleFn& onSample, const EventFn& onEvent = {});

    const std::vector<std::unique_ptr<BusWorker>>& workers() const { return capture_.workers(); }

private:
    Capture capture_;
    CallbackStage stage_;
};

}  // namespace caphub::firmware
