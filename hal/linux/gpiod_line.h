// Data-ready lines on Linux: a GPIO line's rising edges through libgpiod v1, stamped by the
// kernel on CLOCK_MONOTONIC (kernels >= 5.7), and a timerfd at the sensor's rate standing in for
// a line that is not wired. An epoll waiter sleeps on the lines of one bus worker together.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "hal/core/error.h"
#include "hal/data_ready.h"
#include "hal/linux/unique_fd.h"

struct gpiod_chip;
struct gpiod_line;

namespace caphub::hal {

class GpiodDataReadyLine final : public DataReadyLine {
public:
    // Requests rising-edge events on gpiochipN line offset. Errors name the chip and line and
    // say why (no such chip, no such line, line busy: another consumer holds it).
    static Result<std::unique_ptr<GpiodDataReadyLine>> open(int chip, int offset,
                                                            const std::string& consumer);
    ~GpiodDataReadyLine() override;

    int waitEdge(Duration timeout, Timestamp& edgeTime) override;
    int readEdge(Timestamp& edgeTime) override;
    bool isTimer() const override { return false; }
    std::string name() const override { return name_; }
    int pollFd() const;

private:
    GpiodDataReadyLine(std::string name, gpiod_chip* chip, gpiod_line* line);

    std::string name_;
    gpiod_chip* chip_;
    gpiod_line* line_;
};

// A periodic timer (timerfd, CLOCK_MONOTONIC) in place of a data-ready line. Its "edges" are
// the ticks of the schedule, start + n * period, so their times do not jitter with wake-ups.
class TimerDataReadyLine final : public DataReadyLine {
public:
    static Result<std::unique_ptr<TimerDataReadyLine>> open(Duration period, std::string name);

    int waitEdge(Duration timeout, Timestamp& edgeTime) override;
    int readEdge(Timestamp& edgeTime) override;
    bool isTimer() const override { return true; }
    std::string name() const override { return name_; }
    int pollFd() const { return fd_.get(); }

    // Ticks that fired but were not taken yet (a worker that fell behind reads them one by one).
    std::uint64_t pendingTicks() const { return pending_; }

private:
    TimerDataReadyLine(UniqueFd fd, Timestamp start, Duration period, std::string name);

    UniqueFd fd_;
    Timestamp start_;
    Duration period_;
    std::string name_;
    std::uint64_t ticks_ = 0;    // ticks handed out so far
    std::uint64_t pending_ = 0;  // expirations read from the fd, not yet handed out
};

// Waits on the lines of one bus worker with epoll. Takes GpiodDataReadyLine and
// TimerDataReadyLine (anything with a poll fd).
class EpollDataReadyWaiter final : public DataReadyWaiter {
public:
    static Result<std::unique_ptr<EpollDataReadyWaiter>> create();

    int add(DataReadyLine& line) override;
    int wait(Duration timeout, std::span<int> ready) override;

private:
    explicit EpollDataReadyWaiter(UniqueFd fd) : fd_(std::move(fd)) {}

    UniqueFd fd_;
    int count_ = 0;
    // Timer lines whose expirations are already buffered are ready without a new fd event.
    std::vector<TimerDataReadyLine*> timers_;
    std::vector<int> timerIndex_;
};

}  // namespace caphub::hal
