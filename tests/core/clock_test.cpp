#include "hal/core/clock.h"

#include <thread>

#include <gtest/gtest.h>

namespace caphub {
namespace {

using std::chrono::milliseconds;

TEST(MonotonicClock, NeverGoesBackwards) {
    MonotonicClock clock;
    Timestamp last = clock.now();
    for (int i = 0; i < 10000; ++i) {
        const Timestamp t = clock.now();
        ASSERT_GE(t, last);
        last = t;
    }
}

TEST(MonotonicClock, SleepUntilDoesNotReturnEarly) {
    MonotonicClock clock;
    const Timestamp target = clock.now() + milliseconds(5);
    clock.sleepUntil(target);
    EXPECT_GE(clock.now(), target);
}

TEST(MonotonicClock, SleepUntilThePastReturns) {
    MonotonicClock clock;
    clock.sleepUntil(clock.now() - milliseconds(100));
    SUCCEED();
}

TEST(SimulatedClock, SteppedTimeMovesOnlyWhenTold) {
    SimulatedClock clock(timestampFromNs(1000));
    EXPECT_EQ(clock.mode(), SimulatedClock::Mode::Stepped);
    EXPECT_EQ(toNs(clock.now()), 1000);
    std::this_thread::sleep_for(milliseconds(2));
    EXPECT_EQ(toNs(clock.now()), 1000);
    clock.advanceBy(milliseconds(20));
    EXPECT_EQ(toNs(clock.now()), 1000 + 20'000'000);
}

TEST(SimulatedClock, SteppedSleepJumpsToTheTarget) {
    SimulatedClock clock;
    clock.sleepUntil(timestampFromNs(3'600'000'000'000));  // an hour, instantly
    EXPECT_EQ(toNs(clock.now()), 3'600'000'000'000);
}

TEST(SimulatedClock, SteppedTimeNeverGoesBackwards) {
    SimulatedClock clock(timestampFromNs(500));
    clock.advanceTo(timestampFromNs(100));
    EXPECT_EQ(toNs(clock.now()), 500);
    clock.sleepUntil(timestampFromNs(200));
    EXPECT_EQ(toNs(clock.now()), 500);
}

TEST(SimulatedClock, SteppedAdvanceIsSafeFromSeveralThreads) {
    SimulatedClock clock;
    std::vector<std::thread> threads;
    for (int t = 0; t < 4; ++t) {
        threads.emplace_back([&clock, t] {
            for (int i = 1; i <= 1000; ++i) {
                clock.advanceTo(timestampFromNs(i * 4 + t));
            }
        });
    }
    for (auto& th : threads) {
        th.join();
    }
    EXPECT_EQ(toNs(clock.now()), 4003);  // the largest target any thread asked for
}

TEST(SimulatedClock, PacedClockRunsAtItsRate) {
    SimulatedClock clock(timestampFromNs(0), 10.0);
    EXPECT_EQ(clock.mode(), SimulatedClock::Mode::Paced);
    const Timestamp target = timestampFromNs(50'000'000);  // 50 ms simulated = 5 ms real
    MonotonicClock real;
    const Timestamp realStart = real.now();
    clock.sleepUntil(target);
    EXPECT_GE(clock.now(), target);
    // Behaviour, not speed: it must not have slept the full simulated 50 ms of real time.
    EXPECT_LT(real.now() - realStart, milliseconds(50));
}

}  // namespace
}  // namespace caphub
