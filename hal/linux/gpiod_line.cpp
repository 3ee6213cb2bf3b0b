#include "hal/linux/gpiod_line.h"

#include <array>
#include <cerrno>
#include <ctime>

#include <gpiod.h>
#include <poll.h>
#include <sys/epoll.h>
#include <sys/timerfd.h>

#include "hal/core/clock.h"

namespace caphub::hal {

namespace {

timespec toTimespec(Duration d) {
    const std::int64_t ns = toNs(d) < 0 ? 0 : toNs(d);
    return {static_cast<time_t>(ns / 1'000'000'000), static_cast<long>(ns % 1'000'000'000)};
}

int timeoutMs(Duration d) {
    const std::int64_t ns = toNs(d);
    if (ns <= 0) {
        return 0;
    }
    return static_cast<int>((ns + 999'999) / 1'000'000);  // round up: never wake early
}

}  // namespace

// --- GpiodDataReadyLine ---

Result<std::unique_ptr<GpiodDataReadyLine>> GpiodDataReadyLine::open(int chip, int offset,
                                                                     const std::string& consumer) {
    const std::string chipName = "gpiochip" + std::to_string(chip);
    const std::string name = chipName + ":" + std::to_string(offset);
    gpiod_chip* c = gpiod_chip_open_by_name(chipName.c_str());
    if (c == nullptr) {
        return errnoError(errno, "data-ready line " + name + ": cannot open /dev/" + chipName);
    }
    if (offset < 0 || static_cast<unsigned>(offset) >= gpiod_chip_num_lines(c)) {
        const unsigned lines = gpiod_chip_num_lines(c);
        gpiod_chip_close(c);
        return Error{EINVAL, "data-ready line " + name + ": " + chipName + " has only " +
                                 std::to_string(lines) + " lines"};
    }
    gpiod_line* line = gpiod_chip_get_line(c, static_cast<unsigned>(offset));
    if (line == nullptr) {
        const int err = errno;
        gpiod_chip_close(c);
        return errnoError(err, "data-ready line " + name + ": cannot get the line");
    }
    if (gpiod_line_request_rising_edge_events(line, consumer.c_str()) < 0) {
        const int err = errno;
        gpiod_chip_close(c);
        return errnoError(err, "data-ready line " + name + ": cannot request rising edges" +
                                   (err == EBUSY ? " (another consumer holds the line)" : ""));
    }
    return std::unique_ptr<GpiodDataReadyLine>(new GpiodDataReadyLine(name, c, line));
}

GpiodDataReadyLine::GpiodDataReadyLine(std::string name, gpiod_chip* chip, gpiod_line* line)
    : name_(std::move(name)), chip_(chip), line_(line) {}

GpiodDataReadyLine::~GpiodDataReadyLine() {
    gpiod_line_release(line_);
    gpiod_chip_close(chip_);
}

int GpiodDataReadyLine::pollFd() const {
    return gpiod_line_event_get_fd(line_);
}

int GpiodDataReadyLine::waitEdge(Duration timeout, Timestamp& edgeTime) {
    const timespec ts = toTimespec(timeout);
    const int r = gpiod_line_event_wait(line_, &ts);
    if (r < 0) {
        return -errno;
    }
    if (r == 0) {
        return -ETIMEDOUT;
    }
    return readEdge(edgeTime);
}

int GpiodDataReadyLine::readEdge(Timestamp& edgeTime) {
    pollfd p{pollFd(), POLLIN, 0};
    const int ready = ::poll(&p, 1, 0);
    if (ready < 0) {
        return -errno;
    }
    if (ready == 0) {
        return -EAGAIN;
    }
    gpiod_line_event ev{};
    if (gpiod_line_event_read(line_, &ev) < 0) {
        return -errno;
    }
    edgeTime =
        timestampFromNs(static_cast<std::int64_t>(ev.ts.tv_sec) * 1'000'000'000 + ev.ts.tv_nsec);
    return 0;
}

// --- TimerDataReadyLine ---

Result<std::unique_ptr<TimerDataReadyLine>> TimerDataReadyLine::open(Duration period,
                                                                     std::string name) {
    if (toNs(period) <= 0) {
        return Error{EINVAL, "timer for " + name + ": the period must be positive"};
    }
    UniqueFd fd(::timerfd_create(CLOCK_MONOTONIC, TFD_NONBLOCK | TFD_CLOEXEC));
    if (!fd.isValid()) {
        return errnoError(errno, "timer for " + name + ": timerfd_create");
    }
    const Timestamp start = MonotonicClock().now() + period;
    itimerspec spec{};
    spec.it_value = toTimespec(start.time_since_epoch());
    spec.it_interval = toTimespec(period);
    if (::timerfd_settime(fd.get(), TFD_TIMER_ABSTIME, &spec, nullptr) < 0) {
        return errnoError(errno, "timer for " + name + ": timerfd_settime");
    }
    return std::unique_ptr<TimerDataReadyLine>(
        new TimerDataReadyLine(std::move(fd), start, period, std::move(name)));
}

TimerDataReadyLine::TimerDataReadyLine(UniqueFd fd, Timestamp start, Duration period,
                                       std::string name)
    : fd_(std::move(fd)), start_(start), period_(period), name_(std::move(name)) {}

int TimerDataReadyLine::readEdge(Timestamp& edgeTime) {
    if (pending_ == 0) {
        std::uint64_t expirations = 0;
        const ssize_t n = ::read(fd_.get(), &expirations, sizeof expirations);
        if (n < 0) {
            return -errno;  // EAGAIN: nothing fired yet
        }
        pending_ += expirations;
    }
    if (pending_ == 0) {
        return -EAGAIN;
    }
    --pending_;
    edgeTime = start_ + period_ * static_cast<std::int64_t>(ticks_);
    ++ticks_;
    return 0;
}

int TimerDataReadyLine::waitEdge(Duration timeout, Timestamp& edgeTime) {
    if (int r = readEdge(edgeTime); r != -EAGAIN) {
        return r;
    }
    pollfd p{fd_.get(), POLLIN, 0};
    const int ready = ::poll(&p, 1, timeoutMs(timeout));
    if (ready < 0) {
        return -errno;
    }
    if (ready == 0) {
        return -ETIMEDOUT;
    }
    return readEdge(edgeTime);
}

// --- EpollDataReadyWaiter ---

Result<std::unique_ptr<EpollDataReadyWaiter>> EpollDataReadyWaiter::create() {
    UniqueFd fd(::epoll_create1(EPOLL_CLOEXEC));
    if (!fd.isValid()) {
        return errnoError(errno, "epoll_create1");
    }
    return std::unique_ptr<EpollDataReadyWaiter>(new EpollDataReadyWaiter(std::move(fd)));
}

int EpollDataReadyWaiter::add(DataReadyLine& line) {
    int fd = -1;
    if (auto* g = dynamic_cast<GpiodDataReadyLine*>(&line)) {
        fd = g->pollFd();
    } else if (auto* t = dynamic_cast<TimerDataReadyLine*>(&line)) {
        fd = t->pollFd();
        timers_.push_back(t);
        timerIndex_.push_back(count_);
    } else {
        return -EINVAL;  // not a Linux line
    }
    epoll_event ev{};
    ev.events = EPOLLIN;
    ev.data.u32 = static_cast<std::uint32_t>(count_);
    if (::epoll_ctl(fd_.get(), EPOLL_CTL_ADD, fd, &ev) < 0) {
        return -errno;
    }
    return count_++;
}

int EpollDataReadyWaiter::wait(Duration timeout, std::span<int> ready) {
    if (ready.empty()) {
        return -EINVAL;
    }
    int n = 0;
    for (std::size_t i = 0; i < timers_.size() && static_cast<std::size_t>(n) < ready.size(); ++i) {
        if (timers_[i]->pendingTicks() > 0) {
            ready[static_cast<std::size_t>(n++)] = timerIndex_[i];
        }
    }
    std::array<epoll_event, 32> events{};
    const int capacity =
        static_cast<int>(std::min(events.size(), ready.size() - static_cast<std::size_t>(n)));
    if (capacity == 0) {
        return n;
    }
    const int got =
        ::epoll_wait(fd_.get(), events.data(), capacity, n > 0 ? 0 : timeoutMs(timeout));
    if (got < 0) {
        return errno == EINTR ? n : -errno;
    }
    for (int i = 0; i < got; ++i) {
        const int index = static_cast<int>(events[static_cast<std::size_t>(i)].data.u32);
        bool seen = false;
        for (int j = 0; j < n; ++j) {
            seen = seen || ready[static_cast<std::size_t>(j)] == index;
        }
        if (!seen) {
            ready[static_cast<std::size_t>(n++)] = index;
        }
    }
    return n;
}

}  // namespace caphub::hal
