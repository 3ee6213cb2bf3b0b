// LSM6DSOX accelerometer/gyroscope with a LIS3MDL magnetometer on the same bus, driven as one
// 9-axis sensor. Accel, gyro and temperature come in one burst per sample; the magnetometer is
// read in a burst of its own (status + data), polled at twice its rate or at every sample. Both
// dies are assumed to be mounted with the same axes (as on the common LSM6DSOX+LIS3MDL breakouts).
#pragma once

#include <memory>
#include <optional>

#include "hal/drivers/imu_driver.h"
#include "hal/drivers/register_io.h"

namespace caphub::hal {

class Lsm6dsoxLis3mdl final : public ImuDriver {
public:
    static constexpr std::uint8_t kImuSpace = 0;
    static constexpr std::uint8_t kMagSpace = 1;

    Lsm6dsoxLis3mdl(std::unique_ptr<RegisterIo> imu, std::unique_ptr<RegisterIo> mag,
                    std::string name, const ImuConfig& config);

    int probe() override;
    int readSample(Timestamp t, ImuSample& out) override;
    int dataReady(bool& ready) override;

    // Register codes for a configuration (exposed for tests): -1 when not supported.
    static int odrCode(double hz);
    static int accelFsCode(double g);
    static int gyroFsCode(double dps);

protected:
    int softReset() override;
    Duration resetDelay() const override { return std::chrono::milliseconds(10); }
    int buildSettings(SettingTable& table) override;
    int readRegister(std::uint8_t space, std::uint8_t reg, std::uint8_t& value) override;
    int writeRegister(std::uint8_t space, std::uint8_t reg, std::uint8_t value) override;
    void onReset() override { lastMagRead_.reset(); }

private:
    int readMag(ImuSample& out);

    std::unique_ptr<RegisterIo> imu_;
    std::unique_ptr<RegisterIo> mag_;
    double accelMps2PerLsb_ = 0;
    double gyroRadpsPerLsb_ = 0;
    double magUtPerLsb_ = 0;
    Duration magPeriod_{};
    std::optional<Timestamp> lastMagRead_;
};

}  // namespace caphub::hal
