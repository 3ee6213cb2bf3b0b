// The capture pipeline: one worker thread per bus, and one pipeline thread that takes every
// sample and event from the workers' rings and hands them to the stages (recorder, fusion, body,
// preview), so that a slow stage never stalls sampling. Stops cleanly on request (SIGINT,
// SIGTERM, or the configured duration): workers first, then the rings are drained, then the
// stages finish (the recording is flushed and valid).
#pragma once

#include <atomic>
#include <functional>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

#include "board/board.h"
#include "board/hardware.h"
#include "firmware/runtime/bus_worker.h"
#include "firmware/runtime/latency_window.h"
#include "firmware/runtime/pipeline.h"
#include "firmware/runtime/wake_signal.h"

namespace caphub::firmware {

struct CaptureStats {
    std::uint64_t samples = 0;
    std::uint64_t events = 0;
    std::uint64_t dropped = 0;  // samples lost because a ring was full
    std::uint64_t lost = 0;     // sensors that went offline
    // Samples still in the rings at the end that the stages could not take within 0.2 s
    // (a pipeline hopelessly behind its workers: a virtual suit paced beyond the machine).
    std::uint64_t abandoned = 0;
    Duration elapsed{};      // on the capture's clock
    Duration realElapsed{};  // in real time (a paced virtual suit runs faster or slower)
    // Latency from each sample's data-ready time to the pipeline taking it (on the capture
    // clock): percentiles over the run.
    Duration latencyP50{};
    Duration latencyP99{};
    Duration latencyMax{};
    // CPU time (user and system) of the threaded capture's own threads: the pipeline (every
    // stage on it) and the bus workers together (on the virtual suit they also run the motion,
    // the IMU model and the chips' models). Zero in stepped mode.
    Duration pipelineCpu{};
    Duration busWorkersCpu{};
};

class Capture {
public:
    // Threaded: a worker thread per bus and a pipeline thread (start(), wait()). Stepped: the
    // virtual suit on a stepped SimulatedClock, every bus and the pipeline in turn on the calling
    // thread (runStepped()): the same workers and stages, deterministic, as fast as the machine
    // allows.
    enum class Mode { Threaded, Stepped };

    Capture(board::SuitHardware& suit, Clock& clock, BusWorker::Options options = {},
            Mode mode = Mode::Threaded);
    ~Capture();

    void addStage(PipelineStage& stage) { pipeline_.add(stage); }
    // Scheduling of the capture threads (before start()): the bus workers get the policy, the
    // pipeline one priority level below.
    void setThreadPolicy(const ThreadPolicy& policy) { threadPolicy_ = policy; }

    // Starts the workers and the pipeline thread; runs until requestStop() or `duration` of
    // capture-clock time has passed (zero: until requested).
    void start(Duration duration = Duration{0});
    // Safe from a signal handler (the pipeline sees it within its tick, 5 ms).
    void requestStop() { stopRequested_.store(true, std::memory_order_relaxed); }
    bool stopRequested() const { return stopRequested_.load(std::memory_order_relaxed); }
    // Blocks until the capture has stopped and every stage has finished.
    CaptureStats wait();
    // Stepped mode: runs until `duration` of the clock has passed (or requestStop()), then the
    // stages finish.
    CaptureStats runStepped(Duration duration);
    // Stepped mode, in pieces: moves the capture on until the clock reaches `end` (or
    // requestStop()) without finishing it; finishStepped() ends it. runStepped() is the two.
    void stepUntil(Timestamp end);
    CaptureStats finishStepped();
    Mode mode() const { return mode_; }
    Pipeline& pipeline() { return pipeline_; }

    const std::vector<std::unique_ptr<BusWorker>>& workers() const { return workers_; }
    // Runs fn on the pipeline thread between two batches of samples (Pipeline::post), and wakes
    // it. Work posted before start() runs first; work posted after the capture has ended is
    // refused (false); what is still queued when it ends runs before the stages finish.
    bool post(std::function<void(Timestamp)> fn);

    // What wakes the pipeline thread: the workers after they fill the rings; others may use it
    // to hand the pipeline work (commands).
    WakeSignal& wake() { return wake_; }

private:
    void pipelineLoop(Timestamp endAt);
    // After the last sample: the workers stop, the rings are drained, the stages finish.
    void end(Timestamp now);
    // Hands at most kMaxBatch samples per worker (and its events) to the stages.
    int drain(Timestamp now, Timestamp realDeadline);
    bool ringsEmpty() const;
    static constexpr int kMaxBatch = 256;

    board::SuitHardware& suit_;
    Mode mode_;
    Clock& clock_;
    MonotonicClock realClock_;
    std::vector<std::unique_ptr<BusWorker>> workers_;
    Pipeline pipeline_;
    ThreadPolicy threadPolicy_;
    WakeSignal wake_;
    std::atomic<bool> stopRequested_{false};
    std::thread thread_;
    Timestamp started_{};
    Timestamp realStarted_{};
    Timestamp nextTick_{};
    bool stepping_ = false;
    CaptureStats stats_;
    LatencyWindow latency_;  // the most recent samples' data-ready -> pipeline latencies
};

}  // namespace caphub::firmware
