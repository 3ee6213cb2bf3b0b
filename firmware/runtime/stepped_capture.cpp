#include "firmware/runtime/stepped_capture.h"

namespace caphub::firmware {

SteppedCapture::SteppedCapture(board::SuitHardware& suit, SimulatedClock& clock,
                               const BusWorker::Options& options)
    : capture_(suit, clock, options, Capture::Mode::Stepped) {
    capture_.addStage(stage_);
}

void SteppedCapture::runUntil(Timestamp end, const SampleFn& onSample, const EventFn& onEvent) {
    stage_.set(onSample, onEvent);
    capture_.stepUntil(end);
}

}  // namespace caphub::firmware
