// The capture threads' scheduling from the board's [runtime]: CPU affinity and SCHED_FIFO are
// applied to the calling thread, and a refusal (no CAP_SYS_NICE) leaves it as it was.
#include "firmware/runtime/thread_policy.h"

#include <cerrno>
#include <cstring>
#include <thread>

#include <gtest/gtest.h>
#include <pthread.h>
#include <sched.h>

namespace caphub::firmware {
namespace {

TEST(ThreadPolicy, AffinityKeepsTheThreadOnTheListedCpusAndNamesIt) {
    int result = 1;
    int cpusAllowed = 0;
    bool cpu0 = false;
    char name[16] = {};
    std::thread t([&] {
        result = applyToThisThread(ThreadPolicy{0, {0}}, "caphub-test");
        cpu_set_t set;
        CPU_ZERO(&set);
        if (::sched_getaffinity(0, sizeof set, &set) == 0) {
            cpusAllowed = CPU_COUNT(&set);
            cpu0 = CPU_ISSET(0, &set);
        }
        ::pthread_getname_np(::pthread_self(), name, sizeof name);
    });
    t.join();
    EXPECT_EQ(result, 0);
    EXPECT_EQ(cpusAllowed, 1);
    EXPECT_TRUE(cpu0);
    EXPECT_STREQ(name, "caphub-test");
}

TEST(ThreadPolicy, RealtimePriorityIsAppliedOrRefusedWithoutChange) {
    int result = 1;
    int policy = -1;
    sched_param param{};
    std::thread t([&] {
        result = applyToThisThread(ThreadPolicy{10, {}}, "caphub-test");
        ::pthread_getschedparam(::pthread_self(), &policy, &param);
    });
    t.join();
    if (result == 0) {
        EXPECT_EQ(policy, SCHED_FIFO);
        EXPECT_EQ(param.sched_priority, 10);
    } else {
        // Without CAP_SYS_NICE: reported, and the thread keeps the normal scheduler.
        EXPECT_EQ(result, -EPERM) << std::strerror(-result);
        EXPECT_EQ(policy, SCHED_OTHER);
    }
}

TEST(ThreadPolicy, ThePipelineRunsOneLevelBelowTheWorkersButStaysRealtime) {
    EXPECT_EQ((ThreadPolicy{50, {}}.lowered(1).realtimePriority), 49);
    EXPECT_EQ((ThreadPolicy{1, {}}.lowered(1).realtimePriority), 1);
    EXPECT_EQ((ThreadPolicy{0, {}}.lowered(1).realtimePriority), 0);
    EXPECT_EQ((ThreadPolicy{50, {2, 3}}.lowered(1).cpus), (std::vector<int>{2, 3}));
}

}  // namespace
}  // namespace caphub::firmware
