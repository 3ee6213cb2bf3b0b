#include "firmware/runtime/capture.h"

#include <algorithm>

namespace caphub::firmware {

namespace {
// Latency samples kept for the percentiles (the most recent ones: ~50 s of 17 x 200 Hz).
constexpr std::size_t kLatencyWindow = 1 << 18;
// The stages' tick, and the longest the pipeline sleeps when no data arrives.
constexpr Duration kTick = std::chrono::milliseconds(5);
// The most real time one batch of samples may take before the pipeline looks at the rest.
constexpr Duration kBatchTime = std::chrono::milliseconds(5);
// The most real time the stages get for the samples left in the rings at the end.
constexpr Duration kFinalDrainTime = std::chrono::milliseconds(200);
}  // namespace

Capture::Capture(board::SuitHardware& suit, Clock& clock, BusWorker::Options options, Mode mode)
    : suit_(suit), mode_(mode), clock_(clock), latency_(kLatencyWindow) {
    if (mode_ == Mode::Stepped) {
        // A bus that waits moves the clock of every bus: its waits stay far below any sample
        // period, so that no other bus falls a whole period behind (and reads a sample twice).
        options.maxWait = std::min(options.maxWait, Duration{std::chrono::milliseconds(1)});
    }
    for (auto& bus : suit_.buses) {
        workers_.push_back(std::make_unique<BusWorker>(bus, clock_, options));
        workers_.back()->setWake(&wake_);
    }
}

Capture::~Capture() {
    requestStop();
    if (thread_.joinable()) {
        thread_.join();
    }
}

void Capture::start(Duration duration) {
    started_ = clock_.now();
    realStarted_ = realClock_.now();
    const Timestamp endAt = duration.count() > 0 ? started_ + duration : Timestamp::max();
    for (auto& w : workers_) {
        w->start(threadPolicy_);
    }
    thread_ = std::thread([this, endAt] {
        (void)applyToThisThread(threadPolicy_.lowered(1), "caphub-pipeline");
        pipelineLoop(endAt);
        stats_.pipelineCpu = thisThreadCpuTime();
    });
}

int Capture::drain(Timestamp now, Timestamp realDeadline) {
    int n = 0;
    for (auto& w : workers_) {
        SensorSample s;
        // A bounded batch per worker, and a bounded time: a pipeline slower than the workers
        // still comes back to check the end of the capture, its commands and its ticks (the
        // rings absorb the rest or drop).
        for (int k = 0; k < kMaxBatch; ++k) {
            if (k % 16 == 15 && realClock_.now() > realDeadline) {
                return n;
            }
            if (!w->samples().pop(s)) {
                break;
            }
            pipeline_.sample(s);
            latency_.add(now - s.sample.t);
            ++stats_.samples;
            ++n;
        }
        RuntimeEvent e;
        while (w->events().pop(e)) {
            pipeline_.event(e);
            ++stats_.events;
            ++n;
        }
    }
    return n;
}

bool Capture::post(std::function<void(Timestamp)> fn) {
    if (!pipeline_.post(std::move(fn))) {
        return false;
    }
    wake_.notify();
    return true;
}

bool Capture::ringsEmpty() const {
    return std::all_of(workers_.begin(), workers_.end(), [](const auto& w) {
        return w->samples().size() == 0 && w->events().size() == 0;
    });
}

void Capture::pipelineLoop(Timestamp endAt) {
    Timestamp nextTick{};
    while (!stopRequested() && clock_.now() < endAt) {
        const Timestamp now = clock_.now();
        const int n = drain(now, realClock_.now() + kBatchTime) + pipeline_.runPosted(now);
        if (now >= nextTick) {
            pipeline_.tick(now);
            nextTick = now + kTick;
        }
        if (n == 0) {
            // Asleep until a worker has data (an eventfd), or the next tick. The check after
            // prepare() closes the race with a worker that pushed just before it.
            wake_.prepare();
            if (ringsEmpty() && !pipeline_.hasPosted() && !stopRequested()) {
                (void)wake_.wait(kTick);
            } else {
                wake_.cancel();
            }
        }
    }
    end(clock_.now());
}

void Capture::end(Timestamp now) {
    // Every worker told first, then the clock interrupted (they may sleep on a simulated clock
    // paced far below real time), then each joined: a worker whose sleeps the interrupt ends
    // must not be left spinning through them while another is joined (with SCHED_FIFO workers
    // and fewer cores than spinners, the joined one would never run again).
    for (auto& w : workers_) {
        w->requestStop();
    }
    clock_.interrupt();
    for (auto& w : workers_) {
        w->stop();
    }
    // What the workers produced before they stopped; a pipeline hopelessly behind (a virtual
    // suit paced far beyond the machine) leaves what it cannot take within kFinalDrainTime.
    const Timestamp deadline = realClock_.now() + kFinalDrainTime;
    while (drain(now, deadline) > 0 && realClock_.now() < deadline) {
    }
    for (auto& w : workers_) {
        SensorSample s;
        while (w->samples().pop(s)) {
            ++stats_.abandoned;
        }
    }
    pipeline_.finish(now);
    stats_.elapsed = now - started_;
    stats_.realElapsed = realClock_.now() - realStarted_;
    for (auto& w : workers_) {
        for (std::size_t i = 0; i < w->sensorCount(); ++i) {
            stats_.dropped += w->counters(i).dropped.load();
            stats_.lost += w->counters(i).lost.load();
        }
        stats_.busWorkersCpu += w->cpuTime();
    }
    stats_.latencyP50 = latency_.percentile(0.5);
    stats_.latencyP99 = latency_.percentile(0.99);
    stats_.latencyMax = latency_.max();
}

CaptureStats Capture::runStepped(Duration duration) {
    const Timestamp from = clock_.now();
    stepUntil(duration.count() > 0 ? from + duration : Timestamp::max());
    return finishStepped();
}

void Capture::stepUntil(Timestamp end) {
    if (!stepping_) {
        stepping_ = true;
        started_ = clock_.now();
        realStarted_ = realClock_.now();
        nextTick_ = started_;
    }
    while (!stopRequested() && clock_.now() < end) {
        for (auto& w : workers_) {
            w->runOnce();
            (void)drain(clock_.now(), Timestamp::max());
        }
        const Timestamp now = clock_.now();
        (void)pipeline_.runPosted(now);
        if (now >= nextTick_) {
            pipeline_.tick(now);
            nextTick_ = now + kTick;
        }
    }
}

CaptureStats Capture::finishStepped() {
    if (!stepping_) {
        started_ = clock_.now();
    }
    end(clock_.now());
    return stats_;
}

CaptureStats Capture::wait() {
    if (thread_.joinable()) {
        thread_.join();
    }
    return stats_;
}

}  // namespace caphub::firmware
