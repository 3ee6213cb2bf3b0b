#include "firmware/runtime/stepped_capture.h"

#include <algorithm>

namespace caphub::firmware {

SteppedCapture::SteppedCapture(board::SuitHardware& suit, SimulatedClock& clock,
                               const BusWorker::Options& options)
    : clock_(clock) {
    // A bus that waits moves the clock of every bus: its waits stay far below any sample period,
    // so that no other bus falls a whole period behind (and reads a sample twice).
    BusWorker::Options o = options;
    o.maxWait = std::min(o.maxWait, kMaxStep);
    for (auto& bus : suit.buses) {
        workers_.push_back(std::make_unique<BusWorker>(bus, clock, o));
    }
}

void SteppedCapture::runUntil(Timestamp end, const SampleFn& onSample, const EventFn& onEvent) {
    SensorSample s;
    RuntimeEvent e;
    while (clock_.now() < end) {
        // Each pass moves the clock to the bus's next data-ready edge (or its wait limit); the
        // buses whose edges are then in the past catch up on their next pass, as the chips keep
        // their samples latched until read.
        for (auto& w : workers_) {
            w->runOnce();
            while (w->samples().pop(s)) {
                if (onSample) {
                    onSample(s);
                }
            }
            while (w->events().pop(e)) {
                if (onEvent) {
                    onEvent(e);
                }
            }
        }
    }
}

}  // namespace caphub::firmware
