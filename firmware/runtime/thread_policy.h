// Real-time scheduling and CPU affinity for the capture threads (bus workers and the pipeline),
// from the board file's [runtime] table, so that other work on the hub (the preview, an export,
// the recorder's disk writes) cannot delay a sample or a pose.
#pragma once

#include <vector>

#include "board/board.h"
#include "hal/core/time.h"

namespace caphub::firmware {

struct ThreadPolicy {
    int realtimePriority = 0;  // SCHED_FIFO priority 1-99; 0: the normal scheduler
    std::vector<int> cpus;     // empty: any CPU

    static ThreadPolicy fromBoard(const board::RuntimeConfig& r) {
        return ThreadPolicy{r.realtimePriority, r.cpus};
    }
    // The same CPUs, `below` priority levels lower (never under 1; 0 stays 0).
    ThreadPolicy lowered(int below) const;
};

// Names the calling thread (up to 15 characters) and applies the policy to it. Returns 0, or the
// -errno of the first setting the kernel refused (-EPERM without CAP_SYS_NICE); the thread then
// keeps its normal scheduling. The first refusal in the process is logged, once.
int applyToThisThread(const ThreadPolicy& policy, const char* name);

// The CPU time the calling thread has used so far (user and system).
Duration thisThreadCpuTime();

}  // namespace caphub::firmware
