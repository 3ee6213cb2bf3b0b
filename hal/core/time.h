// Time in caphub: int64 nanoseconds, on CLOCK_MONOTONIC on hardware or on the simulation clock.
// Samples carry their own Timestamp end to end; nothing assumes a sample arrived "now".
#pragma once

#include <chrono>
#include <cmath>
#include <cstdint>

namespace caphub {

using Duration = std::chrono::duration<std::int64_t, std::nano>;

// The clock every Timestamp is on: the monotonic clock of the hub, or the simulated one.
struct CaptureClock {
    using rep = std::int64_t;
    using period = std::nano;
    using duration = Duration;
    using time_point = std::chrono::time_point<CaptureClock, Duration>;
    static constexpr bool is_steady = true;
};

using Timestamp = CaptureClock::time_point;

constexpr std::int64_t toNs(Duration d) {
    return d.count();
}
constexpr std::int64_t toNs(Timestamp t) {
    return t.time_since_epoch().count();
}
constexpr Timestamp timestampFromNs(std::int64_t ns) {
    return Timestamp{Duration{ns}};
}
constexpr double toSeconds(Duration d) {
    return static_cast<double>(d.count()) * 1e-9;
}

// A duration from seconds, rounded to the nearest nanosecond.
inline Duration durationFromSeconds(double s) {
    return Duration{static_cast<std::int64_t>(std::llround(s * 1e9))};
}

// The sample period of a rate in Hz, rounded to the nearest nanosecond (50 Hz -> 20 ms).
inline Duration periodFromHz(double hz) {
    return durationFromSeconds(1.0 / hz);
}

}  // namespace caphub
