// How producers wake a consumer thread that has nothing to do: an eventfd that the consumer
// waits on with a timeout, written only when the consumer says it is about to sleep, so a busy
// pipeline costs its producers no system call per sample. Any number of producers, one waiter.
#pragma once

#include <atomic>

#include "hal/core/time.h"
#include "hal/linux/unique_fd.h"

namespace caphub::firmware {

class WakeSignal {
public:
    WakeSignal();

    // Producer side, after making work visible (a ring push, a queued command): wakes the waiter
    // if it is asleep or about to sleep. Cheap when it is awake (one atomic load).
    void notify();

    // Waiter side. The protocol: prepare(), then check for work once more, then wait() only if
    // there is none; work made visible after prepare() is never slept through.
    void prepare() { sleeping_.store(true, std::memory_order_seq_cst); }
    // Sleeps until notify() or the timeout (real time); returns true when notified.
    bool wait(Duration timeout);
    // The waiter found work after prepare(): it does not sleep after all.
    void cancel() { sleeping_.store(false, std::memory_order_relaxed); }

    // Wake-ups that were delivered through the eventfd (a test and status figure).
    std::uint64_t wakeups() const { return wakeups_.load(std::memory_order_relaxed); }

private:
    hal::UniqueFd fd_;
    std::atomic<bool> sleeping_{false};
    std::atomic<std::uint64_t> wakeups_{0};
};

}  // namespace caphub::firmware
