#include "firmware/runtime/wake_signal.h"

#include <algorithm>
#include <cerrno>
#include <cstdint>

#include <poll.h>
#include <sys/eventfd.h>
#include <time.h>
#include <unistd.h>

namespace caphub::firmware {

WakeSignal::WakeSignal() : fd_(::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC)) {}

void WakeSignal::notify() {
    // Orders the producer's publication of work (a ring's release store) before this load:
    // with the waiter's seq_cst store in prepare(), one of the two sees the other.
    std::atomic_thread_fence(std::memory_order_seq_cst);
    if (!sleeping_.load(std::memory_order_relaxed)) {
        return;
    }
    if (sleeping_.exchange(false, std::memory_order_seq_cst)) {
        const std::uint64_t one = 1;
        // EAGAIN (the counter is full) still leaves the waiter woken; nothing else can fail on a
        // valid eventfd.
        (void)!::write(fd_.get(), &one, sizeof one);
    }
}

bool WakeSignal::wait(Duration timeout) {
    const std::int64_t ns = std::max<std::int64_t>(0, timeout.count());
    const timespec ts{static_cast<time_t>(ns / 1'000'000'000),
                      static_cast<long>(ns % 1'000'000'000)};
    // Without an eventfd (the process ran out of descriptors) a bounded sleep still works.
    pollfd p{fd_.get(), POLLIN, 0};
    const nfds_t count = fd_.isValid() ? 1 : 0;
    int r = 0;
    do {
        r = ::ppoll(count > 0 ? &p : nullptr, count, &ts, nullptr);
    } while (r < 0 && errno == EINTR);
    sleeping_.store(false, std::memory_order_relaxed);
    if (r > 0) {
        std::uint64_t signals = 0;
        (void)!::read(fd_.get(), &signals, sizeof signals);
        wakeups_.fetch_add(1, std::memory_order_relaxed);
        return true;
    }
    return false;
}

}  // namespace caphub::firmware
