// The Linux backends on this machine's kernel: their error paths (no such device), and the
// timerfd data-ready fallback with the epoll waiter. The i2c-dev path against a real adapter is
// the kernel-level test (tests/kernel), which boots a kernel with i2c-stub.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "hal/linux/gpiod_line.h"
#include "hal/linux/linux_i2c_bus.h"
#include "hal/linux/linux_spi_bus.h"

namespace caphub::hal {
namespace {

using ::testing::HasSubstr;

TEST(LinuxI2cBus, OpeningAMissingAdapterNamesTheDeviceAndTheError) {
    const auto r = LinuxI2cBus::open("/dev/i2c-250");
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().code, ENOENT);
    EXPECT_THAT(r.error().message, HasSubstr("'/dev/i2c-250'"));
    EXPECT_THAT(r.error().message, HasSubstr("No such file or directory"));
}

TEST(LinuxI2cBus, OpeningSomethingThatIsNotAnAdapterFailsAtI2cFuncs) {
    const auto r = LinuxI2cBus::open("/dev/null");
    ASSERT_FALSE(r.ok());
    EXPECT_THAT(r.error().message, HasSubstr("I2C_FUNCS"));
}

TEST(LinuxI2cBus, DescribesFunctionBits) {
    EXPECT_EQ(LinuxI2cBus::describeFunctions(LinuxI2cBus::defaultRequiredFunctions()),
              "SMBus receive byte, SMBus send byte, SMBus read byte data, SMBus write byte data, "
              "SMBus I2C block read, SMBus I2C block write");
}

TEST(LinuxSpiBus, OpeningAMissingDeviceNamesIt) {
    const auto r = LinuxSpiBus::open("/dev/spidev9.9", {});
    ASSERT_FALSE(r.ok());
    EXPECT_THAT(r.error().message, HasSubstr("'/dev/spidev9.9'"));
    EXPECT_THAT(r.error().message, HasSubstr("No such file or directory"));
}

TEST(GpiodDataReadyLine, AMissingChipIsNamed) {
    const auto r = GpiodDataReadyLine::open(250, 17, "caphub-test");
    ASSERT_FALSE(r.ok());
    EXPECT_THAT(r.error().message, HasSubstr("gpiochip250:17"));
    EXPECT_THAT(r.error().message, HasSubstr("/dev/gpiochip250"));
}

TEST(TimerDataReadyLine, TicksFollowTheScheduleWithoutJitter) {
    auto r = TimerDataReadyLine::open(std::chrono::milliseconds(2), "pelvis");
    ASSERT_TRUE(r.ok()) << r.error().message;
    auto& line = **r;
    EXPECT_TRUE(line.isTimer());
    Timestamp first{};
    ASSERT_EQ(line.waitEdge(std::chrono::seconds(1), first), 0);
    for (int i = 1; i <= 5; ++i) {
        Timestamp t{};
        ASSERT_EQ(line.waitEdge(std::chrono::seconds(1), t), 0);
        EXPECT_EQ(t - first, std::chrono::milliseconds(2) * i);  // exact: from the schedule
    }
}

TEST(TimerDataReadyLine, RejectsANonPositivePeriod) {
    EXPECT_FALSE(TimerDataReadyLine::open(Duration{0}, "x").ok());
}

TEST(EpollDataReadyWaiter, WaitsOnSeveralTimersTogether) {
    auto waiter = EpollDataReadyWaiter::create();
    ASSERT_TRUE(waiter.ok());
    auto fast = TimerDataReadyLine::open(std::chrono::milliseconds(1), "fast");
    auto slow = TimerDataReadyLine::open(std::chrono::milliseconds(4), "slow");
    ASSERT_TRUE(fast.ok() && slow.ok());
    ASSERT_EQ((*waiter)->add(**fast), 0);
    ASSERT_EQ((*waiter)->add(**slow), 1);
    int fastTicks = 0;
    int slowTicks = 0;
    while (slowTicks < 10) {
        std::array<int, 4> ready{};
        const int n = (*waiter)->wait(std::chrono::seconds(1), ready);
        ASSERT_GT(n, 0);
        for (int i = 0; i < n; ++i) {
            Timestamp t{};
            if (ready[static_cast<std::size_t>(i)] == 0) {
                while ((*fast)->readEdge(t) == 0) {
                    ++fastTicks;
                }
            } else {
                while ((*slow)->readEdge(t) == 0) {
                    ++slowTicks;
                }
            }
        }
    }
    // Behaviour, not timing: the 1 ms timer ticked about four times as often as the 4 ms one.
    EXPECT_GE(fastTicks, 30);
}

}  // namespace
}  // namespace caphub::hal
