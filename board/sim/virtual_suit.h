// The virtual suit's hardware: for a board whose buses are simulated, register-level chip models
// on simulated buses (with TCA9548A models), driven by physical inputs, and the same drivers,
// muxes and data-ready waiting the hub uses on real buses.
#pragma once

#include <array>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <vector>

#include "board/hardware.h"
#include "board/sim/bvh.h"
#include "board/sim/imu_model.h"
#include "board/sim/motion.h"
#include "board/sim/scripted_motion.h"
#include "hal/sim/device_model.h"
#include "hal/sim/imu_models.h"

namespace caphub::board::sim {

// The physical inputs of one sensor (in its chip's frame), e.g. from the virtual suit's motion
// and IMU model; nullptr leaves the sensor at rest, level, facing north.
using SourceFactory =
    std::function<std::unique_ptr<hal::sim::PhysicalSource>(const SensorConfig& sensor, int index)>;

// The chip models of a built suit, for fault injection and inspection.
struct VirtualChips {
    std::vector<hal::sim::ChipModel*> imu;  // per board sensor: the accel/gyro chip
    std::vector<hal::sim::ChipModel*> mag;  // per board sensor: a separate magnetometer, or null
};

// Builds the suit of a board whose buses are all sim buses. Errors name the offending bus.
Result<SuitHardware> buildVirtualSuit(const Board& board, Clock& clock,
                                      const SourceFactory& sources, VirtualChips* chips = nullptr);

// Physical inputs from motion capture: each sensor reads the clip's motion of its segment
// through the IMU model (its lever arm from the board, its mounting from the board turned by a
// strapping error, the error profile, a seed per sensor). Time 0 of the clip is `start` on the
// capture clock; after the clip the last pose is held.
struct ClipOptions {
    std::filesystem::path bvh;
    std::filesystem::path map;  // empty: detect a built-in preset from the clip's joint names
    ErrorProfile profile = ErrorProfile::Typical;
    std::uint64_t seed = 1;
    // How far a strapped-on sensor sits from the board file's nominal mounting: each sensor's
    // true mounting is the nominal one turned about a random axis by an angle drawn from a
    // half-normal distribution with this scale (degrees). Straps on soft tissue sit 5-15 degrees
    // off what the wearer intended (docs/virtual-suit.md); 0 puts every sensor exactly at its
    // nominal mounting. Independent of the error profile: it is the fit of the suit, not the chip.
    double strapErrorDeg = 10;
    // Each sensor reads the motion this long ago (s): the output delay of a chip's digital
    // low-pass, which the chip models do not have (0: none, as the register models; the
    // ICM-20948 at the driver's 23.9 Hz setting for 100 Hz delays by several milliseconds,
    // docs/virtual-suit.md). The same for gyroscope, accelerometer and magnetometer.
    double chipDelayS = 0;
    // Seconds the subject first stands in the T-pose (for a body calibration), before moving
    // into the clip over tposeBlendS (board/sim/lead_in.h); 0: the clip starts at once.
    double tposeHoldS = 0;
    double tposeBlendS = 1.5;
    // The pose held instead of the T-pose, as each segment's orientation in the skeleton world
    // (the N-pose for an N-pose calibration); none: the T-pose.
    std::optional<std::array<Quatd, board::kSegmentCount>> leadInPose;
};

struct ClipSuit {
    std::shared_ptr<const Motion> motion;
    // What the sensors follow: the motion, after the T-pose lead-in when there is one; the
    // clip's time 0 is leadInNs into it.
    std::shared_ptr<const SegmentTrajectory> trajectory;
    std::int64_t leadInNs = 0;
    Environment environment;
    SourceFactory sources;
    // The clip's joints that make up a segment and turn faster than a body can
    // (implausibleTurns): where the truth itself is a motion-capture artefact.
    std::vector<ImplausibleTurns> truthTurns;
    // Where a board sensor truly sits on its segment (the mounting the calibration must find).
    std::function<SensorPlacement(const SensorConfig& sensor, int index)> placement;
};

// The seed of the simulated part of board sensor `index` in a suit seeded with `suitSeed`: the
// same chip (the same constant errors) whatever moves it, a clip or a calibration script.
std::uint64_t partSeed(std::uint64_t suitSeed, int index);

// The true mounting of sensor `index`: the nominal one turned by the strapping error of
// ClipOptions::strapErrorDeg, drawn from the seed and the index.
Quatd strappedMounting(const Quatd& nominal, double strapErrorDeg, std::uint64_t seed, int index);

Result<ClipSuit> clipSources(const ClipOptions& options, Timestamp start);

// Physical inputs for calibrating on the virtual suit: every sensor off the body, moved by the
// same script, each the same simulated part (partSeed) as in a clip-driven suit of that seed.
struct ScriptOptions {
    Script script = Script::Rest;
    ScriptTiming timing;
    ErrorProfile profile = ErrorProfile::Typical;
    std::uint64_t seed = 1;
};

struct ScriptedSuit {
    std::shared_ptr<const ScriptedMotion> motion;
    Environment environment;
    SourceFactory sources;
    std::function<SensorPlacement(const SensorConfig& sensor, int index)> placement;
};

ScriptedSuit scriptedSources(const ScriptOptions& options, Timestamp start);

}  // namespace caphub::board::sim
