#include "firmware/runtime/thread_policy.h"

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstring>

#include <pthread.h>
#include <sched.h>
#include <time.h>

#include "hal/core/log.h"

namespace caphub::firmware {

namespace {

void reportOnce(int error, const char* what) {
    static std::atomic<bool> reported{false};
    if (!reported.exchange(true)) {
        log::logger(log::Category::Firmware)
            .warn("capture threads: cannot set {} ({}); running with normal scheduling", what,
                  std::strerror(-error));
    }
}

}  // namespace

ThreadPolicy ThreadPolicy::lowered(int below) const {
    ThreadPolicy p = *this;
    if (p.realtimePriority > 0) {
        p.realtimePriority = std::max(1, p.realtimePriority - below);
    }
    return p;
}

int applyToThisThread(const ThreadPolicy& policy, const char* name) {
    ::pthread_setname_np(::pthread_self(), name);
    int result = 0;
    if (!policy.cpus.empty()) {
        cpu_set_t set;
        CPU_ZERO(&set);
        for (int cpu : policy.cpus) {
            if (cpu >= 0 && cpu < CPU_SETSIZE) {
                CPU_SET(static_cast<std::size_t>(cpu), &set);
            }
        }
        // pthread_* return the error number instead of setting errno.
        if (int e = ::pthread_setaffinity_np(::pthread_self(), sizeof set, &set); e != 0) {
            result = -e;
            reportOnce(result, "the CPU affinity of [runtime] cpus");
        }
    }
    if (policy.realtimePriority > 0) {
        sched_param param{};
        param.sched_priority = policy.realtimePriority;
        if (int e = ::pthread_setschedparam(::pthread_self(), SCHED_FIFO, &param); e != 0) {
            if (result == 0) {
                result = -e;
            }
            reportOnce(-e, "SCHED_FIFO priority of [runtime] realtime_priority");
        }
    }
    return result;
}

Duration thisThreadCpuTime() {
    timespec ts{};
    if (::clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts) != 0) {
        return Duration{0};
    }
    return std::chrono::seconds(ts.tv_sec) + std::chrono::nanoseconds(ts.tv_nsec);
}

}  // namespace caphub::firmware
