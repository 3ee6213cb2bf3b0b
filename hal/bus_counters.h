// Per-bus accounting: transactions, bytes and errors, counted on the bus worker's thread and read
// from any other (the status command), so every counter is a relaxed atomic.
#pragma once

#include <atomic>
#include <cstdint>

namespace caphub::hal {

struct BusCounters {
    std::atomic<std::uint64_t> transactions{0};
    std::atomic<std::uint64_t> bytes{0};  // on the wire: address, register and data bytes
    std::atomic<std::uint64_t> errors{0};

    void count(std::uint64_t wireBytes, bool ok) {
        transactions.fetch_add(1, std::memory_order_relaxed);
        bytes.fetch_add(wireBytes, std::memory_order_relaxed);
        if (!ok) {
            errors.fetch_add(1, std::memory_order_relaxed);
        }
    }
};

// A copy of the counters at one instant, for rates (difference of two snapshots over time).
struct BusCounterSnapshot {
    std::uint64_t transactions = 0;
    std::uint64_t bytes = 0;
    std::uint64_t errors = 0;
};

inline BusCounterSnapshot snapshot(const BusCounters& c) {
    return {c.transactions.load(std::memory_order_relaxed), c.bytes.load(std::memory_order_relaxed),
            c.errors.load(std::memory_order_relaxed)};
}

}  // namespace caphub::hal
