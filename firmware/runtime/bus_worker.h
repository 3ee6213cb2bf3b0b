// One worker per physical bus (PX4-style): it sleeps on the data-ready lines of its sensors,
// reads each sample in one bus transaction, and hands it on through a lock-free ring. Devices on
// a bus take turns; workers share no locks. A sensor that stops answering is reported, retried
// by its driver's start-up sequence, and reported again when it is back; the others go on.
#pragma once

#include <atomic>
#include <memory>
#include <thread>
#include <vector>

#include "board/hardware.h"
#include "firmware/runtime/spsc_ring.h"
#include "firmware/runtime/thread_policy.h"
#include "firmware/runtime/wake_signal.h"
#include "hal/imu_sample.h"

namespace caphub::firmware {

struct SensorSample {
    int sensor = -1;  // index into Board::sensors
    hal::ImuSample sample;
};

struct RuntimeEvent {
    enum class Kind : std::uint8_t { SensorOnline, SensorLost, SensorReset, LineSilent };
    Kind kind = Kind::SensorOnline;
    int sensor = -1;
    Timestamp t{};
    int error = 0;  // -errno, when there is one
};

// Per-sensor counters, written by the worker, read by anyone.
struct SensorCounters {
    std::atomic<std::uint64_t> samples{0};
    std::atomic<std::uint64_t> readErrors{0};
    std::atomic<std::uint64_t> dropped{0};  // ring full: the pipeline fell behind
    std::atomic<std::uint64_t> lost{0};     // times the sensor went offline
    std::atomic<bool> online{false};
};

class BusWorker {
public:
    static constexpr std::size_t kRingSize = 4096;  // > 1 s of 17 sensors at 200 Hz
    using SampleRing = SpscRing<SensorSample, kRingSize>;
    using EventRing = SpscRing<RuntimeEvent, 256>;

    struct Options {
        int lostAfterErrors = 3;      // consecutive failed reads
        int silentAfterPeriods = 20;  // no edge for this many sample periods
        Duration checkInterval = std::chrono::milliseconds(100);  // one setting re-check
        Duration maxWait = std::chrono::milliseconds(50);
    };

    BusWorker(board::BusHardware& hardware, Clock& clock, const Options& options);
    BusWorker(board::BusHardware& hardware, Clock& clock) : BusWorker(hardware, clock, Options{}) {}
    ~BusWorker();

    // One pass: start-up of sensors not yet running, one wait for data-ready edges, the reads
    // those edges call for. Runs on the worker thread, or directly from a test.
    void runOnce();

    // Woken after each pass that put samples or events into the rings (before start()).
    void setWake(WakeSignal* wake) { wake_ = wake; }

    // The most edges of one line taken in one pass: a worker behind its chips (a simulated suit
    // paced faster than the machine can read it) still comes back to its other sensors and to
    // stop(), instead of chasing edges that arrive faster than it reads them.
    static constexpr int kMaxEdgesPerPass = 64;
    // The most stale edges dropped when a sensor comes online (a kernel line queue holds 16; a
    // simulated line 100 ms of them).
    static constexpr int kMaxStaleEdges = 1024;

    // A thread that runs runOnce() until stop(), with the given scheduling.
    void start(const ThreadPolicy& policy = {});
    void stop();
    // Asks the thread to stop after its current pass without waiting for it (stop() then joins
    // it): a capture asks every worker before it interrupts the clock, so that no worker spins on
    // an interrupted clock's sleeps while another is being joined - with SCHED_FIFO workers on
    // a two-core board, two such spinners would keep the joined one from ever running.
    void requestStop() { running_.store(false, std::memory_order_relaxed); }
    // The CPU time its thread used, once stopped (0 before, or when run by a stepped capture).
    Duration cpuTime() const { return Duration{cpuNs_.load(std::memory_order_relaxed)}; }

    SampleRing& samples() { return samples_; }
    EventRing& events() { return events_; }
    const SensorCounters& counters(std::size_t localIndex) const { return *counters_[localIndex]; }
    std::size_t sensorCount() const { return hw_.sensors.size(); }
    const board::BusHardware& hardware() const { return hw_; }

private:
    struct SensorState {
        int consecutiveErrors = 0;
        bool wasOnline = false;
        Timestamp lastEdge{};
        Timestamp nextCheck{};
        Duration period{};
    };

    void emit(RuntimeEvent::Kind kind, std::size_t i, Timestamp t, int error);
    void goOffline(std::size_t i, Timestamp now, int error, RuntimeEvent::Kind kind);
    void handleEdge(std::size_t i, Timestamp edge);

    board::BusHardware& hw_;
    Clock& clock_;
    Options options_;
    std::vector<SensorState> state_;
    std::vector<std::unique_ptr<SensorCounters>> counters_;
    SampleRing samples_;
    EventRing events_;
    WakeSignal* wake_ = nullptr;
    bool produced_ = false;  // this pass pushed a sample or an event
    std::atomic<bool> running_{false};
    std::atomic<std::int64_t> cpuNs_{0};
    std::thread thread_;
};

}  // namespace caphub::firmware
