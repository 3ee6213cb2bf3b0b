// A lock-free single-producer single-consumer ring of fixed capacity: how a bus worker hands
// samples to the pipeline without locks or allocation. A full ring refuses the push (the
// producer counts the drop) rather than blocking the bus.
#pragma once

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <optional>

namespace caphub::firmware {

template <typename T, std::size_t Capacity>
class SpscRing {
    static_assert(Capacity >= 2 && (Capacity & (Capacity - 1)) == 0,
                  "capacity must be a power of two");

public:
    // Producer side.
    bool push(const T& value) {
        const std::size_t head = head_.load(std::memory_order_relaxed);
        if (head - tail_.load(std::memory_order_acquire) == Capacity) {
            return false;
        }
        slots_[head & (Capacity - 1)] = value;
        head_.store(head + 1, std::memory_order_release);
        return true;
    }

    // Consumer side.
    bool pop(T& out) {
        const std::size_t tail = tail_.load(std::memory_order_relaxed);
        if (tail == head_.load(std::memory_order_acquire)) {
            return false;
        }
        out = slots_[tail & (Capacity - 1)];
        tail_.store(tail + 1, std::memory_order_release);
        return true;
    }

    std::size_t size() const {
        return head_.load(std::memory_order_acquire) - tail_.load(std::memory_order_acquire);
    }
    static constexpr std::size_t capacity() { return Capacity; }

private:
    std::array<T, Capacity> slots_{};
    alignas(64) std::atomic<std::size_t> head_{0};
    alignas(64) std::atomic<std::size_t> tail_{0};
};

// The latest value of something produced on one thread and read on others (the pose for the
// preview): a seqlock, so a slow reader never stalls the writer and never sees a torn value.
template <typename T>
class LatestValue {
public:
    void publish(const T& value) {
        const std::uint64_t s = seq_.load(std::memory_order_relaxed);
        seq_.store(s + 1, std::memory_order_relaxed);
        std::atomic_thread_fence(std::memory_order_release);
        value_ = value;
        seq_.store(s + 2, std::memory_order_release);
    }

    // The latest value and its version (0: nothing published yet).
    std::uint64_t read(T& out) const {
        for (;;) {
            const std::uint64_t before = seq_.load(std::memory_order_acquire);
            if (before & 1) {
                continue;  // a write is in progress
            }
            out = value_;
            std::atomic_thread_fence(std::memory_order_acquire);
            if (seq_.load(std::memory_order_relaxed) == before) {
                return before / 2;
            }
        }
    }

private:
    std::atomic<std::uint64_t> seq_{0};
    T value_{};
};

}  // namespace caphub::firmware
