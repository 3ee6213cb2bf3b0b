// The physical IMU model of the virtual suit: what a 9-axis sensor strapped to a moving segment
// measures (gyro, specific force, magnetic field, in SI units and the sensor frame), and the
// errors of a real chip on top (noise, bias, scale, cross-axis, hard and soft iron), drawn from
// a seed so that every run is reproducible. Quantisation and saturation belong to the chip models.
#pragma once

#include <cstdint>
#include <optional>
#include <string_view>
#include <vector>

#include "board/segment.h"
#include "board/sim/motion.h"
#include "hal/core/error.h"
#include "hal/core/quaternion.h"

namespace caphub::board::sim {

// A magnet or a piece of magnetised steel, as a point dipole in the skeleton world frame.
struct MagneticDipole {
    Vec3d positionM = Vec3d::Zero();
    Vec3d momentAm2 = Vec3d::Zero();
};

// Gravity and the magnetic field the suit moves in.
struct Environment {
    double gravityMps2 = 9.81;  // along -Y of the world frame (down)
    double fieldUt = 50;        // earth field intensity
    double dipDeg = 65;         // inclination below the horizontal (northern hemisphere: > 0)
    double declinationDeg = 0;  // magnetic north east of the world's north (+Z)
    std::vector<MagneticDipole> dipoles;

    // The earth field alone, in the world frame.
    Vec3d earthFieldWorldUt() const;
    // The earth field plus every dipole's field at a point of the world frame.
    Vec3d fieldWorldUt(const Vec3d& pointM) const;
};

// R_ENU_world of docs/frames.md: world X west, Y up, Z north.
Quatd qEnuWorld();

// A sensor on a segment: mounting q_segment_sensor and lever arm (the sensor's position in the
// segment frame, from the segment origin), as board/board.h SensorConfig::mounting, positionM.
struct SensorPlacement {
    board::Segment segment = board::Segment::Pelvis;
    Quatd mounting = Quatd::Identity();
    Vec3d leverArmM = Vec3d::Zero();
};

struct ImuSignals {
    Vec3d gyroRadS = Vec3d::Zero();
    Vec3d accelMps2 = Vec3d::Zero();  // specific force: acceleration minus gravity
    Vec3d magUt = Vec3d::Zero();
};

// The error-free signals of a sensor on a segment whose state is known.
ImuSignals idealSignals(const SegmentState& segment, const SensorPlacement& placement,
                        const Environment& env);

// The error figures of one sensor triad, in the triad's SI unit u (rad/s, m/s^2 or uT).
struct TriadErrors {
    double noiseDensity = 0;    // u/sqrt(Hz); per-sample sigma = density * sqrt(odr / 2)
    double noiseRms = 0;        // u per sample; used instead of the density when > 0
    double biasRandomWalk = 0;  // u/sqrt(s): the slow bias drift (bias instability)
    double turnOnBias = 0;      // u per axis
    double scaleError = 0;      // fraction per axis
    double crossAxis = 0;       // fraction per off-diagonal element
};

enum class ErrorProfile { Ideal, Typical, Harsh };

std::string_view toString(ErrorProfile p);
std::optional<ErrorProfile> parseErrorProfile(std::string_view name);

struct ImuErrorSpec {
    TriadErrors gyro;
    TriadErrors accel;
    TriadErrors mag;
    double hardIronUt = 0;  // per axis: magnetised parts of the board and strap
    double softIron = 0;    // fraction per element of the symmetric soft-iron distortion
    // false: each constant error is drawn from a zero-mean Gaussian with the figure as its
    // sigma; true: each sits at the figure itself with a random sign (a worst-case part).
    bool worstCase = false;
};

// The figures of a chip (hal/chip_info.h names: "icm20948", "lsm6dsox+lis3mdl") under a profile.
// Sources and the rules turning datasheet figures into profiles: docs/virtual-suit.md.
Result<ImuErrorSpec> errorSpec(std::string_view chipName, ErrorProfile profile);

// The environment of a profile: for harsh, magnetic disturbances placed around a point of the
// capture area (e.g. where the subject walks); otherwise the undisturbed earth field.
Environment environmentFor(ErrorProfile profile, const Vec3d& areaCentreM);

// The constant errors of one simulated part, drawn from the spec and the seed.
struct ImuConstants {
    Eigen::Matrix3d gyroMatrix = Eigen::Matrix3d::Identity();  // scale and cross-axis
    Eigen::Matrix3d accelMatrix = Eigen::Matrix3d::Identity();
    Eigen::Matrix3d magMatrix = Eigen::Matrix3d::Identity();  // soft iron, scale, cross-axis
    Vec3d gyroBiasRadS = Vec3d::Zero();
    Vec3d accelBiasMps2 = Vec3d::Zero();
    Vec3d magOffsetUt = Vec3d::Zero();  // chip zero-field offset plus hard iron
};

// One simulated sensor: reads the trajectory at any instant and returns what the chip's
// sensing elements deliver before quantisation. Noise at an instant depends only on the seed and
// the instant, so reading an instant twice gives the same value. The bias random walks advance
// with time: read each stream (gyro/accel, mag) at non-decreasing instants; an earlier instant
// reuses the current bias. No allocation per reading. The trajectory must outlive the sensor.
class VirtualImu {
public:
    VirtualImu(const SegmentTrajectory& trajectory, const Environment& env,
               const SensorPlacement& placement, const ImuErrorSpec& spec, std::uint64_t seed,
               double imuOdrHz, double magOdrHz);

    void readGyroAccel(std::int64_t tNs, Vec3d& gyroRadS, Vec3d& accelMps2);
    void readMag(std::int64_t tNs, Vec3d& magUt);
    // All three at one instant (for chip models that take one physical input per sample).
    ImuSignals read(std::int64_t tNs);

    // The error-free signals at an instant.
    ImuSignals ideal(std::int64_t tNs) const;

    const ImuConstants& constants() const { return constants_; }
    const SensorPlacement& placement() const { return placement_; }

private:
    struct Walk {
        Vec3d biasU = Vec3d::Zero();
        std::int64_t lastNs = 0;
        bool started = false;
    };

    // The chip's errors on the true signals at tNs, advancing that stream's bias walk.
    void addGyroAccelErrors(const ImuSignals& truth, std::int64_t tNs, Vec3d& gyroRadS,
                            Vec3d& accelMps2);
    void addMagErrors(const ImuSignals& truth, std::int64_t tNs, Vec3d& magUt);
    Vec3d gaussian3(std::uint64_t stream, std::int64_t tNs) const;
    void advance(Walk& w, std::uint64_t stream, double rateU, std::int64_t tNs) const;

    const SegmentTrajectory& trajectory_;
    Environment env_;
    SensorPlacement placement_;
    ImuErrorSpec spec_;
    std::uint64_t seed_;
    ImuConstants constants_;
    double gyroSigma_ = 0;
    double accelSigma_ = 0;
    double magSigma_ = 0;
    Walk gyroWalk_;
    Walk accelWalk_;
    Walk magWalk_;
};

}  // namespace caphub::board::sim
