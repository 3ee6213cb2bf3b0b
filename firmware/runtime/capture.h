// The capture pipeline: one worker thread per bus, and one pipeline thread that takes every
// sample and event from the workers' rings and hands them to the stages (recorder, fusion, body,
// preview), so that a slow stage never stalls sampling. Stops cleanly on request (SIGINT,
// SIGTERM, or the configured duration): workers first, then the rings are drained, then the
// stages finish (the recording is flushed and valid).
#pragma once

#include <atomic>
#include <memory>
#include <thread>
#include <vector>

#include "board/board.h"
#include "board/hardware.h"
#include "firmware/runtime/bus_worker.h"
#include "firmware/runtime/latency_window.h"

namespace caphub::firmware {

// A consumer of the pipeline. Runs on the pipeline thread; must not block for long.
class PipelineStage {
public:
    virtual ~PipelineStage() = default;
    virtual void onSample(const SensorSample& s) = 0;
    virtual void onEvent(const RuntimeEvent& e) = 0;
    // Called at least every few milliseconds with the current time.
    virtual void onTick(Timestamp now) { (void)now; }
    // The capture is over: flush and close.
    virtual void finish(Timestamp now) { (void)now; }
};

struct CaptureStats {
    std::uint64_t samples = 0;
    std::uint64_t events = 0;
    std::uint64_t dropped = 0;  // samples lost because a ring was full
    std::uint64_t lost = 0;     // sensors that went offline
    Duration elapsed{};
    // Latency from each sample's data-ready time to the pipeline taking it (on the capture
    // clock): percentiles over the run.
    Duration latencyP50{};
    Duration latencyP99{};
    Duration latencyMax{};
};

class Capture {
public:
    Capture(board::SuitHardware& suit, Clock& clock, BusWorker::Options options = {});
    ~Capture();

    void addStage(PipelineStage& stage) { stages_.push_back(&stage); }
    // Scheduling of the capture threads (before start()): the bus workers get the policy, the
    // pipeline one priority level below.
    void setThreadPolicy(const ThreadPolicy& policy) { threadPolicy_ = policy; }

    // Starts the workers and the pipeline thread; runs until requestStop() or `duration` of
    // capture-clock time has passed (zero: until requested).
    void start(Duration duration = Duration{0});
    // Safe from a signal handler.
    void requestStop() { stopRequested_.store(true, std::memory_order_relaxed); }
    bool stopRequested() const { return stopRequested_.load(std::memory_order_relaxed); }
    // Blocks until the capture has stopped and every stage has finished.
    CaptureStats wait();

    const std::vector<std::unique_ptr<BusWorker>>& workers() const { return workers_; }

private:
    void pipelineLoop(Timestamp end);
    // Hands at most kMaxBatch samples per worker (and its events) to the stages.
    int drain(Timestamp now);
    static constexpr int kMaxBatch = 256;

    board::SuitHardware& suit_;
    Clock& clock_;
    std::vector<std::unique_ptr<BusWorker>> workers_;
    std::vector<PipelineStage*> stages_;
    ThreadPolicy threadPolicy_;
    std::atomic<bool> stopRequested_{false};
    std::thread pipeline_;
    Timestamp started_{};
    CaptureStats stats_;
    LatencyWindow latency_;  // the most recent samples' data-ready -> pipeline latencies
};

}  // namespace caphub::firmware
