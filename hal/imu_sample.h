// One sample of a 9-axis IMU in SI units, in the sensor's (accelerometer's) frame, stamped with
// the time of its data-ready edge.
#pragma once

#include <cstdint>

#include <Eigen/Core>

#include "hal/core/angles.h"
#include "hal/core/time.h"

namespace caphub::hal {

struct ImuSample {
    Timestamp t{};
    Eigen::Vector3f accMps2 = Eigen::Vector3f::Zero();
    Eigen::Vector3f gyrRadps = Eigen::Vector3f::Zero();
    Eigen::Vector3f magUt = Eigen::Vector3f::Zero();  // valid when flags has kMagFresh
    float temperatureC = 0;
    std::uint8_t flags = 0;

    static constexpr std::uint8_t kMagFresh = 1u << 0;      // a new magnetometer reading
    static constexpr std::uint8_t kAccSaturated = 1u << 1;  // an axis at full scale
    static constexpr std::uint8_t kGyrSaturated = 1u << 2;
    static constexpr std::uint8_t kMagOverflow = 1u << 3;
};

inline constexpr double kStandardGravity = 9.80665;  // m/s^2 per g (the datasheets' g)

}  // namespace caphub::hal
