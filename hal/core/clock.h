// The Clock seam: the monotonic clock of the hub, or a simulation clock for the virtual suit.
#pragma once

#include <atomic>

#include "hal/core/time.h"

namespace caphub {

class Clock {
public:
    virtual ~Clock() = default;

    virtual Timestamp now() const = 0;
    // Blocks until now() >= t (returns at once if t is past), or until interrupt().
    virtual void sleepUntil(Timestamp t) = 0;
    // The threads that sleep on this clock are stopping: every sleepUntil in progress returns
    // within kInterruptLatency of real time, and later ones at once, whatever their target (so
    // now() may still be before it). For clocks whose sleeps can be long in real time (a
    // simulated clock paced far below real time); a MonotonicClock's callers bound their own.
    virtual void interrupt() {}
    static constexpr Duration kInterruptLatency = std::chrono::milliseconds(20);
};

// CLOCK_MONOTONIC, the clock the kernel stamps GPIO edge events with.
class MonotonicClock final : public Clock {
public:
    Timestamp now() const override;
    void sleepUntil(Timestamp t) override;
};

// Simulated time. Stepped: time moves only when told (advanceTo/advanceBy, or sleepUntil, which
// jumps straight to its target): deterministic and as fast as the machine allows. Paced: time
// follows the monotonic clock scaled by a rate (1.0 = real time for the demo, 4.0 = 4x faster).
class SimulatedClock final : public Clock {
public:
    enum class Mode { Stepped, Paced };

    // A stepped clock starting at start.
    explicit SimulatedClock(Timestamp start = Timestamp{});
    // A paced clock starting at start and running rate times faster than real time (rate > 0).
    SimulatedClock(Timestamp start, double rate);

    Mode mode() const { return mode_; }
    double rate() const { return rate_; }

    Timestamp now() const override;
    void sleepUntil(Timestamp t) override;
    void interrupt() override { interrupted_.store(true, std::memory_order_release); }

    // Stepped mode only: moves time forward; a target in the past leaves it unchanged.
    void advanceTo(Timestamp t);
    void advanceBy(Duration d);

private:
    MonotonicClock real_;  // first: the paced constructor reads it
    Mode mode_;
    double rate_ = 1.0;
    std::atomic<std::int64_t> nowNs_;  // stepped mode
    Timestamp start_{};                // paced mode: simulated time at realStart_
    Timestamp realStart_{};
    std::atomic<bool> interrupted_{false};
};

}  // namespace caphub
