#include "firmware/runtime/capture.h"

#include <algorithm>

namespace caphub::firmware {

namespace {
// Latency samples kept for the percentiles (the most recent ones: ~50 s of 17 x 200 Hz).
constexpr std::size_t kLatencyWindow = 1 << 18;
constexpr Duration kIdlePause = std::chrono::microseconds(200);
}  // namespace

Capture::Capture(board::SuitHardware& suit, Clock& clock, BusWorker::Options options)
    : suit_(suit), clock_(clock), latency_(kLatencyWindow) {
    for (auto& bus : suit_.buses) {
        workers_.push_back(std::make_unique<BusWorker>(bus, clock_, options));
    }
}

Capture::~Capture() {
    requestStop();
    if (pipeline_.joinable()) {
        pipeline_.join();
    }
}

void Capture::start(Duration duration) {
    started_ = clock_.now();
    const Timestamp end = duration.count() > 0 ? started_ + duration : Timestamp::max();
    for (auto& w : workers_) {
        w->start(threadPolicy_);
    }
    pipeline_ = std::thread([this, end] {
        (void)applyToThisThread(threadPolicy_.lowered(1), "caphub-pipeline");
        pipelineLoop(end);
    });
}

int Capture::drain(Timestamp now) {
    int n = 0;
    for (auto& w : workers_) {
        SensorSample s;
        // A bounded batch per worker: a pipeline slower than the workers still comes back to
        // check the end of the capture and its ticks (the rings absorb the rest or drop).
        for (int k = 0; k < kMaxBatch && w->samples().pop(s); ++k) {
            for (auto* stage : stages_) {
                stage->onSample(s);
            }
            latency_.add(now - s.sample.t);
            ++stats_.samples;
            ++n;
        }
        RuntimeEvent e;
        while (w->events().pop(e)) {
            for (auto* stage : stages_) {
                stage->onEvent(e);
            }
            ++stats_.events;
            ++n;
        }
    }
    return n;
}

void Capture::pipelineLoop(Timestamp end) {
    MonotonicClock real;
    Timestamp nextTick{};
    while (!stopRequested() && clock_.now() < end) {
        const Timestamp now = clock_.now();
        const int n = drain(now);
        if (now >= nextTick) {
            for (auto* stage : stages_) {
                stage->onTick(now);
            }
            nextTick = now + std::chrono::milliseconds(5);
        }
        if (n == 0) {
            real.sleepUntil(real.now() + kIdlePause);
        }
    }
    for (auto& w : workers_) {
        w->stop();
    }
    const Timestamp now = clock_.now();
    while (drain(now) > 0) {  // what the workers produced before they stopped
    }
    for (auto* stage : stages_) {
        stage->finish(now);
    }
    stats_.elapsed = now - started_;
    for (auto& w : workers_) {
        for (std::size_t i = 0; i < w->sensorCount(); ++i) {
            stats_.dropped += w->counters(i).dropped.load();
            stats_.lost += w->counters(i).lost.load();
        }
    }
    stats_.latencyP50 = latency_.percentile(0.5);
    stats_.latencyP99 = latency_.percentile(0.99);
    stats_.latencyMax = latency_.max();
}

CaptureStats Capture::wait() {
    if (pipeline_.joinable()) {
        pipeline_.join();
    }
    return stats_;
}

}  // namespace caphub::firmware
