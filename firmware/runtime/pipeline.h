// The pipeline: the stages in their order, and what the capture hands them - samples, events,
// ticks, the commands posted to it - whoever drives it: the threaded Capture (bus worker threads
// and a pipeline thread) or its stepped mode (one thread, a stepped clock: deterministic).
#pragma once

#include <atomic>
#include <functional>
#include <mutex>
#include <vector>

#include "firmware/runtime/bus_worker.h"
#include "hal/core/time.h"

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

// A stage made of callbacks: for a command that only wants the samples (and events) of a
// capture - calibrate, selftest, sim - and for tests.
class CallbackStage final : public PipelineStage {
public:
    using SampleFn = std::function<void(const SensorSample&)>;
    using EventFn = std::function<void(const RuntimeEvent&)>;

    explicit CallbackStage(SampleFn onSample = {}, EventFn onEvent = {})
        : onSample_(std::move(onSample)), onEvent_(std::move(onEvent)) {}
    void onSample(const SensorSample& s) override {
        if (onSample_) {
            onSample_(s);
        }
    }
    void onEvent(const RuntimeEvent& e) override {
        if (onEvent_) {
            onEvent_(e);
        }
    }
    void set(SampleFn onSample, EventFn onEvent) {
        onSample_ = std::move(onSample);
        onEvent_ = std::move(onEvent);
    }

private:
    SampleFn onSample_;
    EventFn onEvent_;
};

class Pipeline {
public:
    // The stages get everything in the order they were added.
    void add(PipelineStage& stage) { stages_.push_back(&stage); }

    void sample(const SensorSample& s) {
        for (auto* stage : stages_) {
            stage->onSample(s);
        }
    }
    void event(const RuntimeEvent& e) {
        for (auto* stage : stages_) {
            stage->onEvent(e);
        }
    }
    void tick(Timestamp now) {
        for (auto* stage : stages_) {
            stage->onTick(now);
        }
    }
    // Runs what is still posted, refuses what comes later, and lets the stages finish.
    void finish(Timestamp now);

    // Work for the pipeline's thread, run between two batches of samples with the capture
    // clock's time (how commands reach the stages of a running capture without locks in them).
    // False once the pipeline has finished. Thread-safe.
    bool post(std::function<void(Timestamp)> fn);
    // On the pipeline's thread: runs the posted work; returns how many ran.
    int runPosted(Timestamp now);
    bool hasPosted() const { return postedPending_.load(std::memory_order_acquire); }

private:
    std::vector<PipelineStage*> stages_;
    std::mutex postedMutex_;
    std::vector<std::function<void(Timestamp)>> posted_;
    std::atomic<bool> postedPending_{false};
    bool finished_ = false;  // guarded by postedMutex_
};

}  // namespace caphub::firmware
