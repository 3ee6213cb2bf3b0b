// A tap of the raw samples of a running Hub, for consumers off the pipeline thread (the guided
// sensor calibration): a pipeline stage that, only while it is opened, pushes every sample into
// a bounded lock-free ring and never waits: a full ring drops the sample and counts it. The
// consumer drains the ring on its own thread.
#pragma once

#include <atomic>
#include <cstdint>

#include "firmware/runtime/pipeline.h"
#include "firmware/runtime/spsc_ring.h"

namespace caphub::firmware::serve {

class SampleTap final : public PipelineStage {
public:
    static constexpr std::size_t kCapacity = 16384;  // ~4 s of a 17-sensor suit at 240 Hz

    // Pipeline thread.
    void onSample(const SensorSample& s) override {
        if (!open_.load(std::memory_order_acquire)) {
            return;
        }
        if (!ring_.push(s)) {
            dropped_.fetch_add(1, std::memory_order_relaxed);
        }
    }
    void onEvent(const RuntimeEvent&) override {}

    // Consumer side (one thread at a time): open() starts passing samples (what the ring held
    // from an earlier opening is discarded), close() stops it.
    void open() {
        SensorSample s;
        while (ring_.pop(s)) {
        }
        dropped_.store(0, std::memory_order_relaxed);
        open_.store(true, std::memory_order_release);
    }
    void close() { open_.store(false, std::memory_order_release); }
    bool pop(SensorSample& out) { return ring_.pop(out); }
    // Samples dropped since open() because the consumer fell behind.
    std::uint64_t dropped() const { return dropped_.load(std::memory_order_relaxed); }

private:
    std::atomic<bool> open_{false};
    std::atomic<std::uint64_t> dropped_{0};
    SpscRing<SensorSample, kCapacity> ring_;
};

}  // namespace caphub::firmware::serve
