#include "hal/core/time.h"

#include <gtest/gtest.h>

namespace caphub {
namespace {

TEST(Time, DurationsAreInt64Nanoseconds) {
    static_assert(std::is_same_v<Duration::rep, std::int64_t>);
    static_assert(std::is_same_v<Duration::period, std::nano>);
    EXPECT_EQ(toNs(std::chrono::milliseconds(23)), 23'000'000);
}

TEST(Time, PeriodOfARateRoundsToTheNearestNanosecond) {
    EXPECT_EQ(toNs(periodFromHz(50)), 20'000'000);
    EXPECT_EQ(toNs(periodFromHz(1100.0 / 11.0)), 10'000'000);
    // BROAD's rate: 1/285.714 s = 3,500,003.500004 ns, which rounds up.
    EXPECT_EQ(toNs(periodFromHz(285.714)), 3'500'004);
}

TEST(Time, TimestampsRoundTripThroughNanoseconds) {
    const Timestamp t = timestampFromNs(1'234'567'890'123);
    EXPECT_EQ(toNs(t), 1'234'567'890'123);
    EXPECT_EQ(toNs(t + periodFromHz(100)), 1'234'577'890'123);
}

TEST(Time, HundredYearsFitInOneTimestamp) {
    // int64 ns covers +-292 years: enough for any capture clock.
    const Duration century = std::chrono::hours(24 * 365 * 100);
    EXPECT_GT(toNs(century), 0);
}

}  // namespace
}  // namespace caphub
