#include "hal/drivers/imu_driver.h"

#include <cerrno>

namespace caphub::hal {

namespace {
// Pause before retrying a start-up that failed (a sensor that NACKs is retried, not given up).
constexpr Duration kRetryPause = std::chrono::milliseconds(100);
}  // namespace

int ImuDriver::service(Timestamp now) {
    if (state_ == State::Running) {
        return 0;
    }
    if (now < next_) {
        return -EAGAIN;
    }
    switch (state_) {
        case State::Reset: {
            onReset();
            const int r = softReset();
            if (r < 0) {
                counters_.bump(counters_.readErrors);
                next_ = now + kRetryPause;
                return r;
            }
            state_ = State::WaitReset;
            next_ = now + resetDelay();
            return -EAGAIN;
        }
        case State::WaitReset: {
            onReset();
            const int r = probe();
            if (r < 0) {
                counters_.bump(counters_.probeFailures);
                state_ = State::Reset;
                next_ = now + kRetryPause;
                return r;
            }
            state_ = State::Configure;
            [[fallthrough]];
        }
        case State::Configure: {
            const int r = configure();
            if (r < 0) {
                state_ = State::Reset;
                next_ = now + kRetryPause;
                return r;
            }
            state_ = State::Running;
            checkIndex_ = 0;
            counters_.bump(counters_.starts);
            return 0;
        }
        case State::Running:
            break;
    }
    return 0;
}

int ImuDriver::configure() {
    const int n = buildSettings(settings_);
    if (n < 0) {
        counters_.bump(counters_.configErrors);
        return n;
    }
    settingCount_ = static_cast<std::size_t>(n);
    for (std::size_t i = 0; i < settingCount_; ++i) {
        const RegisterSetting& s = settings_[i];
        std::uint8_t value = 0;
        if (int r = readRegister(s.space, s.reg, value); r < 0) {
            counters_.bump(counters_.readErrors);
            return r;
        }
        if (int r = writeRegister(s.space, s.reg, s.apply(value)); r < 0) {
            counters_.bump(counters_.readErrors);
            return r;
        }
        std::uint8_t back = 0;
        if (int r = readRegister(s.space, s.reg, back); r < 0) {
            counters_.bump(counters_.readErrors);
            return r;
        }
        if (!s.matches(back)) {
            counters_.bump(counters_.configErrors);
            return -EIO;
        }
    }
    if (int r = afterConfigure(); r < 0) {
        counters_.bump(counters_.configErrors);
        return r;
    }
    return 0;
}

int ImuDriver::checkNextSetting(Timestamp now) {
    if (state_ != State::Running || settingCount_ == 0) {
        return 0;
    }
    const RegisterSetting& s = settings_[checkIndex_];
    checkIndex_ = (checkIndex_ + 1) % settingCount_;
    std::uint8_t value = 0;
    if (int r = readRegister(s.space, s.reg, value); r < 0) {
        counters_.bump(counters_.readErrors);
        return r;
    }
    if (s.matches(value)) {
        return 0;
    }
    counters_.bump(counters_.resetsDetected);
    restart(now);
    return 1;
}

void ImuDriver::restart(Timestamp now) {
    state_ = State::Reset;
    next_ = now;
}

}  // namespace caphub::hal
