#include "hal/core/clock.h"

#include <algorithm>
#include <cerrno>
#include <ctime>

namespace caphub {

namespace {

timespec toTimespec(Timestamp t) {
    const std::int64_t ns = toNs(t);
    return timespec{static_cast<time_t>(ns / 1'000'000'000), static_cast<long>(ns % 1'000'000'000)};
}

}  // namespace

Timestamp MonotonicClock::now() const {
    timespec ts{};
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return timestampFromNs(static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec);
}

void MonotonicClock::sleepUntil(Timestamp t) {
    const timespec target = toTimespec(t);
    // Absolute sleeps do not drift and restart cleanly after a signal.
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &target, nullptr) == EINTR) {
    }
}

SimulatedClock::SimulatedClock(Timestamp start) : mode_(Mode::Stepped), nowNs_(toNs(start)) {}

SimulatedClock::SimulatedClock(Timestamp start, double rate)
    : mode_(Mode::Paced),
      rate_(rate > 0.0 ? rate : 1.0),
      nowNs_(toNs(start)),
      start_(start),
      realStart_(real_.now()) {}

Timestamp SimulatedClock::now() const {
    if (mode_ == Mode::Stepped) {
        return timestampFromNs(nowNs_.load(std::memory_order_acquire));
    }
    const double realElapsed = toSeconds(real_.now() - realStart_);
    return start_ + durationFromSeconds(realElapsed * rate_);
}

void SimulatedClock::sleepUntil(Timestamp t) {
    if (mode_ == Mode::Stepped) {
        advanceTo(t);
        return;
    }
    // In real-time slices, so that interrupt() is seen promptly: at a slow rate one simulated
    // millisecond can be seconds of real time.
    const double simAhead = toSeconds(t - start_);
    const Timestamp realTarget = realStart_ + durationFromSeconds(simAhead / rate_);
    while (!interrupted_.load(std::memory_order_acquire)) {
        const Timestamp realNow = real_.now();
        if (realNow >= realTarget) {
            return;
        }
        real_.sleepUntil(std::min(realTarget, realNow + kInterruptLatency));
    }
}

void SimulatedClock::advanceTo(Timestamp t) {
    const std::int64_t target = toNs(t);
    std::int64_t cur = nowNs_.load(std::memory_order_acquire);
    while (cur < target && !nowNs_.compare_exchange_weak(cur, target, std::memory_order_acq_rel)) {
    }
}

void SimulatedClock::advanceBy(Duration d) {
    advanceTo(now() + d);
}

}  // namespace caphub
