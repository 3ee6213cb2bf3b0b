#include "board/sim/virtual_suit.h"

#include <algorithm>
#include <cmath>
#include <random>

#include <fmt/format.h>

#include "board/sim/bvh.h"
#include "board/sim/joint_map.h"
#include "board/sim/lead_in.h"
#include "board/sim/scripted_motion.h"
#include "hal/imu_sample.h"
#include "hal/sim/sim_bus.h"

namespace caphub::board::sim {

namespace {

namespace hs = hal::sim;

// Everything the simulated hardware owns, kept alive by SuitHardware::keepAlive.
struct World {
    std::vector<std::unique_ptr<hs::PhysicalSource>> sources;
    std::vector<std::unique_ptr<hs::ChipModel>> chips;
    std::vector<std::unique_ptr<hs::Tca9548aModel>> muxes;
};

}  // namespace

Result<SuitHardware> buildVirtualSuit(const Board& board, Clock& clock,
                                      const SourceFactory& sourceFor, VirtualChips* chipsOut) {
    auto world = std::make_shared<World>();
    SuitHardware suit;
    suit.clock = &clock;
    if (chipsOut != nullptr) {
        chipsOut->imu.assign(board.sensors.size(), nullptr);
        chipsOut->mag.assign(board.sensors.size(), nullptr);
    }
    for (std::size_t b = 0; b < board.buses.size(); ++b) {
        const BusConfig& bc = board.buses[b];
        if (bc.type != BusType::Sim) {
            return Error{EINVAL, "bus '" + bc.name + "' is a real " +
                                     std::string(hal::toString(bc.protocol)) +
                                     " bus: the virtual suit runs only sim buses"};
        }
        BusHardware hw;
        hw.bus = static_cast<int>(b);
        hw.waiter = std::make_unique<hs::SimDataReadyWaiter>(clock);
        hs::SimI2cBus* i2c = nullptr;
        std::vector<std::pair<std::string, hs::Tca9548aModel*>> muxModels;
        if (bc.protocol == hal::BusProtocol::I2c) {
            auto bus = std::make_unique<hs::SimI2cBus>(bc.name, clock);
            i2c = bus.get();
            hw.i2c = std::move(bus);
            for (const MuxConfig& m : board.muxes) {
                if (m.bus != hw.bus) {
                    continue;
                }
                world->muxes.push_back(std::make_unique<hs::Tca9548aModel>());
                i2c->attach(*world->muxes.back(), m.address);
                muxModels.emplace_back(m.name, world->muxes.back().get());
            }
            addMuxes(hw, board);
        }
        for (std::size_t s = 0; s < board.sensors.size(); ++s) {
            const SensorConfig& sc = board.sensors[s];
            if (sc.bus != hw.bus) {
                continue;
            }
            auto source = sourceFor ? sourceFor(sc, static_cast<int>(s)) : nullptr;
            if (!source) {
                source = std::make_unique<hs::ConstantSource>();
            }
            world->sources.push_back(std::move(source));
            hs::PhysicalSource* src = world->sources.back().get();

            hs::ChipModel* imuChip = nullptr;
            hs::ChipModel* magChip = nullptr;
            if (sc.chip->name == "icm20948") {
                auto chip = std::make_unique<hs::Icm20948Model>();
                chip->setPhysicalSource(src);
                imuChip = chip.get();
                world->chips.push_back(std::move(chip));
            } else {
                auto imu = std::make_unique<hs::Lsm6dsoxModel>();
                auto mag = std::make_unique<hs::Lis3mdlModel>();
                imu->setSource(src);
                mag->setSource(src);
                imuChip = imu.get();
                magChip = mag.get();
                world->chips.push_back(std::move(imu));
                world->chips.push_back(std::move(mag));
            }
            if (chipsOut != nullptr) {
                chipsOut->imu[s] = imuChip;
                chipsOut->mag[s] = magChip;
            }

            std::unique_ptr<hal::RegisterIo> imuRegs;
            std::unique_ptr<hal::RegisterIo> magRegs;
            if (i2c != nullptr) {
                const hs::Tca9548aModel* muxModel = nullptr;
                hal::I2cBus* bus = &sensorBus(hw, board, sc);
                if (sc.mux >= 0) {
                    const std::string& name = board.muxes[static_cast<std::size_t>(sc.mux)].name;
                    for (auto& [n, model] : muxModels) {
                        if (n == name) {
                            muxModel = model;
                        }
                    }
                }
                i2c->attach(*imuChip, sc.address, muxModel, sc.channel);
                imuRegs = i2cRegisters(sc, *bus, false);
                if (magChip != nullptr) {
                    i2c->attach(*magChip, *sc.magAddress, muxModel, sc.channel);
                    magRegs = i2cRegisters(sc, *bus, true);
                }
            } else {
                hw.spi.push_back(std::make_unique<hs::SimSpiBus>(
                    fmt::format("{}.{}", bc.name, sc.chipSelect), clock, *imuChip));
                imuRegs = spiRegisters(sc, *hw.spi.back(), false);
                if (magChip != nullptr) {
                    hw.spi.push_back(std::make_unique<hs::SimSpiBus>(
                        fmt::format("{}.{}", bc.name, sc.magChipSelect), clock, *magChip));
                    magRegs = spiRegisters(sc, *hw.spi.back(), true);
                }
            }
            auto driver = makeDriver(sc, bc.protocol, std::move(imuRegs), std::move(magRegs));
            if (!driver) {
                return driver.error();
            }
            SensorHardware sh;
            sh.sensor = static_cast<int>(s);
            sh.driver = std::move(*driver);
            // Sensors without a wired line are polled on their rate; in the simulation the chip's
            // sample instants stand in for the timer ticks, and the driver checks the status bit.
            sh.line = std::make_unique<hs::SimDataReadyLine>(
                sc.dataReady ? sc.dataReady->text() : "timer:" + sc.name, clock, *imuChip);
            if (int r = hw.waiter->add(*sh.line); r < 0) {
                return Error{-r, "sensor '" + sc.name + "': cannot wait on its line"};
            }
            hw.sensors.push_back(std::move(sh));
        }
        suit.buses.push_back(std::move(hw));
    }
    suit.keepAlive = world;
    return suit;
}

namespace {

// One sensor of the virtual suit: the IMU model's reading in the chip's frame, of a trajectory
// whose time 0 is `start` on the capture clock.
class TrajectoryImuSource final : public hs::PhysicalSource {
public:
    TrajectoryImuSource(std::shared_ptr<const SegmentTrajectory> trajectory, const Environment& env,
                        const SensorPlacement& placement, const ImuErrorSpec& spec,
                        std::uint64_t seed, const SensorConfig& sensor, Timestamp start,
                        Duration delay = Duration::zero())
        : trajectory_(std::move(trajectory)),
          imu_(*trajectory_, env, placement, spec, seed, sensor.achievedOdrHz,
               sensor.magOdrHz > 0 ? sensor.magOdrHz : sensor.achievedOdrHz),
          start_(start + delay) {}

    hs::PhysicalInput at(Timestamp t) override {
        const std::int64_t tNs = std::max<std::int64_t>(0, toNs(t - start_));
        const ImuSignals s = imu_.read(tNs);
        hs::PhysicalInput in;
        in.accMps2 = s.accelMps2;
        in.gyrRadps = s.gyroRadS;
        in.magUt = s.magUt;
        return in;
    }

private:
    std::shared_ptr<const SegmentTrajectory> trajectory_;  // what VirtualImu reads
    VirtualImu imu_;
    Timestamp start_;
};

}  // namespace

std::uint64_t partSeed(std::uint64_t suitSeed, int index) {
    return suitSeed * 1000003u + static_cast<std::uint64_t>(index);
}

Quatd strappedMounting(const Quatd& nominal, double strapErrorDeg, std::uint64_t seed, int index) {
    if (strapErrorDeg <= 0) {
        return nominal;
    }
    // Raw 64-bit draws of a fully specified engine, turned into numbers here, so that every
    // platform and standard library draws the same mountings.
    std::mt19937_64 rng(seed * 0x9E3779B97F4A7C15ull + 0x5157u + static_cast<std::uint64_t>(index));
    const auto uniform = [&rng] {
        return (static_cast<double>(rng() >> 11) + 0.5) * 0x1.0p-53;  // in (0, 1)
    };
    // A random axis, uniform on the sphere.
    const double z = 2 * uniform() - 1;
    const double phi = 2 * hal::kPi * uniform();
    const double r = std::sqrt(std::max(0.0, 1 - z * z));
    const Vec3d axis(r * std::cos(phi), r * std::sin(phi), z);
    // A half-normal angle (Box-Muller), capped at three scales so that no draw is absurd.
    const double g = std::sqrt(-2 * std::log(uniform())) * std::cos(2 * hal::kPi * uniform());
    const double angleDeg = std::min(std::abs(g), 3.0) * strapErrorDeg;
    // The strap turns the sensor about the segment's axes: q_segment_sensor' = q_err * q_nominal.
    return (Quatd(Eigen::AngleAxisd(angleDeg * hal::kPi / 180, axis)) * nominal).normalized();
}

Result<ClipSuit> clipSources(const ClipOptions& options, Timestamp start) {
    auto clip = loadBvh(options.bvh);
    if (!clip) {
        return clip.error();
    }
    JointMap map;
    if (!options.map.empty()) {
        auto loaded = loadJointMap(options.map);
        if (!loaded) {
            return loaded.error();
        }
        map = std::move(*loaded);
    } else if (const JointMap* detected = detectJointMap(*clip)) {
        map = *detected;
    } else {
        return Error{EINVAL, fmt::format("'{}': no built-in joint map fits its joint names; give "
                                         "one with --map (docs/virtual-suit.md)",
                                         options.bvh.string())};
    }
    auto motion = Motion::fromClip(*clip, map);
    if (!motion) {
        // Said of the clip: its line or frame is in the message.
        return Error{motion.error().code,
                     fmt::format("'{}': {}", options.bvh.string(), motion.error().message)};
    }
    ClipSuit suit;
    for (ImplausibleTurns& t : implausibleTurns(*clip)) {
        const bool ofASegment = std::any_of(
            map.joints.begin(), map.joints.end(), [&](const std::vector<std::string>& names) {
                return std::find(names.begin(), names.end(), t.joint) != names.end();
            });
        if (ofASegment) {
            suit.truthTurns.push_back(std::move(t));
        }
    }
    suit.motion = std::make_shared<const Motion>(std::move(*motion));
    SegmentState pelvis;
    suit.motion->evaluate(board::Segment::Pelvis, 0, pelvis);
    suit.environment = environmentFor(options.profile, pelvis.positionM);
    suit.trajectory = suit.motion;
    if (options.tposeHoldS > 0) {
        auto leadIn =
            options.leadInPose
                ? std::make_shared<const LeadInMotion>(suit.motion, options.tposeHoldS,
                                                       options.tposeBlendS, *options.leadInPose)
                : std::make_shared<const LeadInMotion>(suit.motion, options.tposeHoldS,
                                                       options.tposeBlendS);
        suit.leadInNs = leadIn->leadInNs();
        suit.trajectory = leadIn;
    }
    const auto motionPtr = suit.trajectory;
    const Environment env = suit.environment;
    const ErrorProfile profile = options.profile;
    const std::uint64_t seed = options.seed;
    const double strapDeg = options.strapErrorDeg;
    const Duration delay = durationFromSeconds(options.chipDelayS);
    suit.placement = [seed, strapDeg](const SensorConfig& sensor, int index) {
        SensorPlacement placement;
        placement.segment = sensor.segment;
        placement.mounting = strappedMounting(sensor.mounting, strapDeg, seed, index);
        placement.leverArmM = sensor.positionM;
        return placement;
    };
    suit.sources = [motionPtr, env, profile, seed, start, delay, placementOf = suit.placement](
                       const SensorConfig& sensor,
                       int index) -> std::unique_ptr<hs::PhysicalSource> {
        auto spec = errorSpec(sensor.chip->name, profile);
        if (!spec) {
            return nullptr;
        }
        const SensorPlacement placement = placementOf(sensor, index);
        return std::make_unique<TrajectoryImuSource>(motionPtr, env, placement, *spec,
                                                     partSeed(seed, index), sensor, start, delay);
    };
    return suit;
}

ScriptedSuit scriptedSources(const ScriptOptions& options, Timestamp start) {
    ScriptedSuit suit;
    auto motion = std::make_shared<const ScriptedMotion>(options.script, options.timing);
    suit.motion = motion;
    suit.environment = environmentFor(options.profile, Vec3d(0.0, 1.0, 0.0));
    const Environment env = suit.environment;
    const ErrorProfile profile = options.profile;
    const std::uint64_t seed = options.seed;
    suit.placement = [](const SensorConfig& sensor, int) {
        SensorPlacement placement;  // off the body: the script moves the sensor itself
        placement.segment = sensor.segment;
        return placement;
    };
    suit.sources = [motion, env, profile, seed, start, placementOf = suit.placement](
                       const SensorConfig& sensor,
                       int index) -> std::unique_ptr<hs::PhysicalSource> {
        auto spec = errorSpec(sensor.chip->name, profile);
        if (!spec) {
            return nullptr;
        }
        return std::make_unique<TrajectoryImuSource>(motion, env, placementOf(sensor, index), *spec,
                                                     partSeed(seed, index), sensor, start);
    };
    return suit;
}

}  // namespace caphub::board::sim
