// Finding where a sensor was held still in a stream: the stream is cut into short windows, a
// window whose rates and specific forces barely spread is still, and runs of still windows form
// the intervals the accelerometer and gyroscope calibrations are measured from.
#pragma once

#include <cstddef>
#include <span>
#include <vector>

#include "hal/core/error.h"
#include "hal/core/quaternion.h"

namespace caphub::fusion {

struct StillPositionParams {
    double windowS = 0.5;         // s, length of the windows the stream is cut into
    double maxGyroStdDps = 0.5;   // deg/s, per-axis standard deviation of a still window
    double maxAccStdMps2 = 0.15;  // m/s^2, per-axis standard deviation of a still window
    double minStillS = 1.0;       // s, least still time needed in each position
};

// Samples [begin, end) of a stream, with their means.
struct StillInterval {
    std::size_t begin = 0;
    std::size_t end = 0;
    Vec3d meanAccMps2 = Vec3d::Zero();
    Vec3d meanGyrRadS = Vec3d::Zero();
    std::size_t size() const { return end - begin; }
};

// Every run of consecutive still windows, however short, in stream order. Refused when the two
// streams differ in length or the rate is not positive.
Result<std::vector<StillInterval>> findStillIntervals(std::span<const Vec3d> accMps2,
                                                      std::span<const Vec3d> gyrRadS, double rateHz,
                                                      const StillPositionParams& params = {});

// The positions a sensor was held in: the runs of at least minStillS, each with its first and
// last window left out when it has four or more (where the hold meets a turn, the sensor may
// already move a little), and its means taken over what remains.
Result<std::vector<StillInterval>> findHeldPositions(std::span<const Vec3d> accMps2,
                                                     std::span<const Vec3d> gyrRadS, double rateHz,
                                                     const StillPositionParams& params = {});

}  // namespace caphub::fusion
