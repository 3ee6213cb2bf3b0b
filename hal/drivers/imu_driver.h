// The common part of caphub's IMU drivers (PX4-style): a non-blocking start-up state machine
// (Reset -> WaitReset -> Configure -> Running), configuration as a table of {register, set bits,
// clear bits} applied and read back, a periodic re-check of one table entry while running that
// detects a chip that reset itself, and failure counters instead of logs.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <span>
#include <string>

#include "hal/core/time.h"
#include "hal/imu_sample.h"

namespace caphub::hal {

struct ImuConfig {
    double odrHz = 100;       // accelerometer and gyroscope
    double magOdrHz = 100;    // magnetometer
    double accelRangeG = 16;  // full scale
    double gyroRangeDps = 2000;
    bool dataReadyInterrupt = true;  // raise the data-ready line on new data
};

// One configuration register: bits to set and bits to clear. `space` tells the driver where the
// register lives (the ICM-20948's user bank; the LSM6DSOX or the LIS3MDL die).
struct RegisterSetting {
    std::uint8_t space = 0;
    std::uint8_t reg = 0;
    std::uint8_t set = 0;
    std::uint8_t clear = 0;

    bool matches(std::uint8_t value) const { return (value & set) == set && (value & clear) == 0; }
    std::uint8_t apply(std::uint8_t value) const {
        return static_cast<std::uint8_t>((value & ~clear) | set);
    }
};

struct DriverCounters {
    std::atomic<std::uint64_t> samples{0};
    std::atomic<std::uint64_t> readErrors{0};
    std::atomic<std::uint64_t> probeFailures{0};
    std::atomic<std::uint64_t> configErrors{0};    // a setting that did not read back
    std::atomic<std::uint64_t> resetsDetected{0};  // settings found at reset values while running
    std::atomic<std::uint64_t> starts{0};          // times the start-up sequence completed

    void bump(std::atomic<std::uint64_t>& c) { c.fetch_add(1, std::memory_order_relaxed); }
};

class ImuDriver {
public:
    enum class State { Reset, WaitReset, Configure, Running };

    ImuDriver(std::string name, const ImuConfig& config)
        : name_(std::move(name)), config_(config) {}
    virtual ~ImuDriver() = default;
    ImuDriver(const ImuDriver&) = delete;
    ImuDriver& operator=(const ImuDriver&) = delete;

    // Advances the start-up sequence. Returns 0 once Running; -EAGAIN while starting (call again
    // at or after nextServiceTime()); -errno when a step failed (counted; the sequence restarts
    // from Reset after a pause).
    [[nodiscard]] int service(Timestamp now);

    State state() const { return state_; }
    Timestamp nextServiceTime() const { return next_; }

    // Checks the identity register: 0, -ENODEV for another chip, or the bus's -errno.
    [[nodiscard]] virtual int probe() = 0;

    // Running: reads one sample (accel + gyro in one bus transaction), stamped t.
    [[nodiscard]] virtual int readSample(Timestamp t, ImuSample& out) = 0;

    // The chip's data-ready status bit, for sensors polled on a timer.
    [[nodiscard]] virtual int dataReady(bool& ready) = 0;

    // Running: re-reads the next table entry. A mismatch means the chip lost its configuration
    // (it reset itself): counted, and the start-up sequence restarts. Returns 0, 1 when it
    // restarted, or the bus's -errno.
    [[nodiscard]] int checkNextSetting(Timestamp now);

    // Takes effect at the next start-up (call restart() to apply now).
    void setConfig(const ImuConfig& config) { config_ = config; }
    const ImuConfig& config() const { return config_; }
    void restart(Timestamp now);

    const DriverCounters& counters() const { return counters_; }
    const std::string& name() const { return name_; }

    // The active configuration table (valid after Configure).
    std::span<const RegisterSetting> settings() const {
        return std::span(settings_.data(), settingCount_);
    }

protected:
    static constexpr std::size_t kMaxSettings = 24;
    using SettingTable = std::array<RegisterSetting, kMaxSettings>;

    virtual int softReset() = 0;
    virtual Duration resetDelay() const = 0;
    // Fills the table for config(); returns the number of entries or -EINVAL.
    virtual int buildSettings(SettingTable& table) = 0;
    virtual int readRegister(std::uint8_t space, std::uint8_t reg, std::uint8_t& value) = 0;
    virtual int writeRegister(std::uint8_t space, std::uint8_t reg, std::uint8_t value) = 0;
    // After the table: set-up that is a sequence rather than register state (the ICM-20948's
    // magnetometer behind its auxiliary I2C master).
    virtual int afterConfigure() { return 0; }
    // Called when the chip state is unknown again (after a reset): forget cached state.
    virtual void onReset() {}

    DriverCounters counters_;

private:
    int configure();

    std::string name_;
    ImuConfig config_;
    State state_ = State::Reset;
    Timestamp next_{};
    SettingTable settings_{};
    std::size_t settingCount_ = 0;
    std::size_t checkIndex_ = 0;
};

// Big- and little-endian 16-bit register pairs.
constexpr std::int16_t be16(const std::uint8_t* p) {
    return static_cast<std::int16_t>(static_cast<std::uint16_t>((p[0] << 8) | p[1]));
}
constexpr std::int16_t le16(const std::uint8_t* p) {
    return static_cast<std::int16_t>(static_cast<std::uint16_t>((p[1] << 8) | p[0]));
}
constexpr bool atFullScale(std::int16_t v) {
    return v == INT16_MAX || v == INT16_MIN;
}

// Fills a sample's accelerometer and gyroscope from raw counts and their scales (SI units per
// count), flagging a triad with an axis at full scale.
inline void setAccelGyro(ImuSample& out, const std::array<std::int16_t, 3>& acc,
                         const std::array<std::int16_t, 3>& gyr, double accPerLsb,
                         double gyrPerLsb) {
    for (std::size_t k = 0; k < 3; ++k) {
        const auto i = static_cast<Eigen::Index>(k);
        out.accMps2[i] = static_cast<float>(acc[k] * accPerLsb);
        out.gyrRadps[i] = static_cast<float>(gyr[k] * gyrPerLsb);
        if (atFullScale(acc[k])) {
            out.flags |= ImuSample::kAccSaturated;
        }
        if (atFullScale(gyr[k])) {
            out.flags |= ImuSample::kGyrSaturated;
        }
    }
}

}  // namespace caphub::hal
