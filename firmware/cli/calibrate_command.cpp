// caphub calibrate gyro|accel|mag: the sensor calibrations of a board, measured on the suit and
// merged into a calibration file (firmware/calibration_file.h) that `caphub run` applies before
// the filter and writes into its recordings. On a virtual suit the sensors are taken off the
// body and moved by a script (board/sim/scripted_motion.h); the table then also shows the
// simulated parts' true errors beside the estimates. On a hub the person is told what to do.
#include <chrono>
#include <cmath>
#include <filesystem>
#include <optional>

#include <Eigen/SVD>
#include <fmt/format.h>

#include "board/loader.h"
#include "board/sim/virtual_suit.h"
#include "firmware/calibration_file.h"
#include "firmware/cli/app.h"
#include "firmware/cli/commands.h"
#include "firmware/cli/data_dir.h"
#include "firmware/cli/number_checks.h"
#include "firmware/export/output_file.h"
#include "firmware/runtime/hub.h"
#include "firmware/sensor_calibration_steps.h"
#include "fusion/calibration/accel_six_position.h"
#include "fusion/calibration/ellipsoid_fit.h"
#include "fusion/calibration/gyro_bias.h"
#include "fusion/calibration/imu_axes.h"
#include "hal/core/angles.h"

namespace caphub::firmware {

namespace {

namespace fs = std::filesystem;
namespace bs = board::sim;

using hal::kRadToDeg;

enum class Kind { Gyro, Accel, Mag };

struct CalibrateOptions {
    std::string board = "sim-suit";
    std::string file = "calibration.toml";
    double durationS = 0;  // 0: the kind's default
    std::string profile = "typical";
    std::uint64_t seed = 1;
};

// What each board sensor delivered during the calibration; on a virtual suit also each simulated
// part's true errors.
struct Streams : CalibrationSamples {
    bool virtualSuit = false;
    std::vector<bs::ImuConstants> truth;
    using CalibrationSamples::CalibrationSamples;
};

double defaultDurationS(Kind k, const bs::ScriptTiming& timing) {
    switch (k) {
        case Kind::Gyro:
            return 5.0;
        case Kind::Accel:  // the script's own length
            return static_cast<double>(
                       bs::ScriptedMotion(bs::Script::FourteenPositions, timing).durationNs()) *
                   1e-9;
        case Kind::Mag:
            return timing.tumbleS;
    }
    return 0;
}

// The virtual suit, its sensors moved by the kind's script, on a stepped clock.
Result<Streams> collectVirtual(const board::Board& b, Kind kind, double durationS,
                               bs::ErrorProfile profile, std::uint64_t seed) {
    bs::ScriptOptions so;
    so.script = kind == Kind::Gyro    ? bs::Script::Rest
                : kind == Kind::Accel ? bs::Script::FourteenPositions
                                      : bs::Script::Tumble;
    so.profile = profile;
    so.seed = seed;
    so.timing.tumbleS = durationS;
    // The sensors start (reset, configuration) in the first half second; the script then runs.
    SimulatedClock clock(Timestamp{std::chrono::seconds(1)});
    const Timestamp scriptStart = clock.now() + std::chrono::milliseconds(500);
    bs::ScriptedSuit scripted = bs::scriptedSources(so, scriptStart);
    auto suit = bs::buildVirtualSuit(b, clock, scripted.sources);
    if (!suit) {
        return suit.error();
    }
    Streams out(b);
    out.virtualSuit = true;
    for (std::size_t i = 0; i < b.sensors.size(); ++i) {
        const auto& sc = b.sensors[i];
        auto spec = bs::errorSpec(sc.chip->name, profile);
        if (!spec) {
            return spec.error();
        }
        const bs::VirtualImu part(*scripted.motion, scripted.environment,
                                  scripted.placement(sc, static_cast<int>(i)), *spec,
                                  bs::partSeed(seed, static_cast<int>(i)), sc.achievedOdrHz,
                                  sc.magOdrHz > 0 ? sc.magOdrHz : sc.achievedOdrHz);
        out.truth.push_back(part.constants());
    }
    CallbackStage collect([&out, scriptStart](const SensorSample& s) {
        if (s.sample.t >= scriptStart) {
            out.add(s);
        }
    });
    (void)captureSamples(b, clock, *suit, Capture::Mode::Stepped,
                         scriptStart + durationFromSeconds(durationS) - clock.now(), collect);
    return out;
}

Result<Streams> collectHub(const board::Board& b, double durationS) {
    MonotonicClock clock;
    auto suit = board::openLinuxSuit(b, clock);
    if (!suit) {
        return suit.error();
    }
    Streams out(b);
    // Every sample, collected on the pipeline thread; read once the capture has stopped.
    CallbackStage collect(
        [&out](const SensorSample& s) { out.add(s); },
        [](const RuntimeEvent& e) {
            if (e.kind == RuntimeEvent::Kind::SensorLost) {
                fmt::print(stderr, "caphub calibrate: sensor {} stopped answering\n", e.sensor);
            }
        });
    (void)captureSamples(b, clock, *suit, Capture::Mode::Threaded, durationFromSeconds(durationS),
                         collect);
    return out;
}

std::string vec(const Vec3d& v, double scale, int decimals) {
    return fmt::format("[{:.{}f} {:.{}f} {:.{}f}]", v.x() * scale, decimals, v.y() * scale,
                       decimals, v.z() * scale, decimals);
}

// The rotation nearest a matrix (the orthogonal factor of its polar decomposition).
Eigen::Matrix3d rotationOf(const Eigen::Matrix3d& m) {
    const Eigen::JacobiSVD<Eigen::Matrix3d> svd(m, Eigen::ComputeFullU | Eigen::ComputeFullV);
    return svd.matrixU() * svd.matrixV().transpose();
}

// The accelerometer and gyroscope axes of one sensor (sensor_calibration_steps.h). Prints the
// sensor's row; returns why it failed, or nothing.
std::string printAxes(const std::string& name, const Streams& st, std::size_t i,
                      fusion::SensorCalibration& cal) {
    const auto r = calibrateAxes(st, i, cal);
    if (!r) {
        return r.error().message;
    }
    const fusion::AccelAxesResult& acc = r->acc;
    const std::optional<fusion::GyroAxesResult>& gyro = r->gyro;
    fmt::print(
        "{:<11} {:>4} {:>29} {:>7.3f} {:>9.4f} {:>7} {:>13}", name, r->heldPositions,
        vec(acc.offsetMps2, 1.0, 4), 100.0 * fusion::axisDeparture(acc.matrix), acc.residualMps2,
        gyro ? fmt::format("{:.3f}", 100.0 * fusion::axisDeparture(gyro->matrix)) : "-",
        gyro ? fmt::format("{:.2f} -> {:.2f}", gyro->uncalibratedDeg, gyro->residualDeg) : "-");
    if (st.virtualSuit) {
        // The part reads raw = M f + b. Calibrated, P = A M must be a rotation (the frame the
        // accelerometer now defines); the gyroscope's G Mg must be that same rotation.
        const bs::ImuConstants& t = st.truth[i];
        const Eigen::Matrix3d p = acc.matrix * t.accelMatrix;
        const Eigen::Matrix3d frame = rotationOf(p);
        const double accAxes =
            (frame.transpose() * p - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
        const double gyroAxes = (cal.gyroMatrix * t.gyroMatrix - frame).cwiseAbs().maxCoeff();
        fmt::print(" {:>9.4f} {:>11.3f} {:>11.3f}", (acc.offsetMps2 - t.accelBiasMps2).norm(),
                   100.0 * accAxes, 100.0 * gyroAxes);
    }
    return {};
}

// The magnetometer's hard and soft iron and its alignment (sensor_calibration_steps.h). Prints
// the row.
std::string printMag(const std::string& name, const Streams& st, std::size_t i,
                     fusion::SensorCalibration& cal) {
    const auto result = calibrateMagnetometer(st, i, cal);
    if (!result) {
        return result.error().message;
    }
    const fusion::EllipsoidFitResult* r = &result->fit;
    const std::optional<fusion::MagAlignResult>& align = result->align;
    fmt::print(
        "{:<11} {:>8} {:>26} {:>9.2f} {:>8.2f} {:>9.2f} {:>9} {:>14}", name, st.mag[i].size(),
        vec(r->hardIronUt, 1.0, 2), r->fieldNormUt, r->qualityPct, r->coverage,
        align ? fmt::format("{:.2f}", align->angleDeg) : "-",
        align ? fmt::format("{:.2f} -> {:.2f}", align->unalignedDeg, align->residualDeg) : "-");
    if (st.virtualSuit) {
        // The part reads raw = Mm B + h. Calibrated, softIron Mm must turn the field into the
        // accelerometer's frame: the rotation of A Ma (the frame it defines).
        const bs::ImuConstants& t = st.truth[i];
        const Eigen::Matrix3d frame = rotationOf(cal.accMatrix * t.accelMatrix);
        const Eigen::Matrix3d m = cal.magSoftIron * t.magMatrix;
        const double err =
            align ? Eigen::AngleAxisd(Eigen::Matrix3d(rotationOf(m) * frame.transpose())).angle() *
                        kRadToDeg
                  : 0.0;
        fmt::print(" {:>26} {:>9.3f} {:>9}", vec(t.magOffsetUt, 1.0, 2),
                   (r->hardIronUt - t.magOffsetUt).norm(),
                   align ? fmt::format("{:.3f}", err) : "-");
    }
    return {};
}

// Runs one kind of calibration on every sensor; returns the number of sensors calibrated.
int calibrateAll(Kind kind, const board::Board& b, const Streams& st, CalibrationSet& set) {
    int done = 0;
    const bool truth = st.virtualSuit;
    switch (kind) {
        case Kind::Gyro:
            fmt::print("{:<11} {:>8} {:>26} {:>9}{}\n", "sensor", "samples", "bias deg/s",
                       "std dps", truth ? fmt::format(" {:>26} {:>9}", "true bias", "error") : "");
            break;
        case Kind::Accel:
            // Axes: the accelerometer's scale and cross-axis terms and the gyroscope's (against
            // the accelerometer's frame), each as its matrix's largest departure from the identity.
            fmt::print(
                "{:<11} {:>4} {:>29} {:>7} {:>9} {:>7} {:>13}{}\n", "sensor", "pos", "offset m/s^2",
                "axes %", "resid", "gyro %", "turns deg",
                truth ? fmt::format(" {:>9} {:>11} {:>11}", "off err", "acc axes %", "gyro axes %")
                      : "");
            break;
        case Kind::Mag:
            fmt::print(
                "{:<11} {:>8} {:>26} {:>9} {:>8} {:>9} {:>9} {:>14}{}\n", "sensor", "readings",
                "hard iron uT", "norm uT", "quality%", "coverage", "align deg", "dip spread deg",
                truth ? fmt::format(" {:>26} {:>9} {:>9}", "true hard iron", "error", "align err")
                      : "");
            break;
    }
    for (std::size_t i = 0; i < b.sensors.size(); ++i) {
        const std::string& name = b.sensors[i].name;
        fusion::SensorCalibration& cal = set[name];
        std::string failure;
        switch (kind) {
            case Kind::Gyro: {
                const auto r = calibrateGyroBias(st, i, cal);
                if (!r) {
                    failure = r.error().message;
                    break;
                }
                fmt::print("{:<11} {:>8} {:>26} {:>9.3f}", name, r->samples,
                           vec(r->biasRadS, kRadToDeg, 3), r->stdRadS.maxCoeff() * kRadToDeg);
                if (truth) {
                    const Vec3d& t = st.truth[i].gyroBiasRadS;
                    fmt::print(" {:>26} {:>9.3f}", vec(t, kRadToDeg, 3),
                               (r->biasRadS - t).norm() * kRadToDeg);
                }
                break;
            }
            case Kind::Accel:
                failure = printAxes(name, st, i, cal);
                break;
            case Kind::Mag:
                failure = printMag(name, st, i, cal);
                break;
        }
        if (!failure.empty()) {
            fmt::print("{:<11} not calibrated: {}", name, failure);
        } else {
            ++done;
        }
        fmt::print("\n");
    }
    return done;
}

int calibrate(Kind kind, const CalibrateOptions& o) {
    const auto loaded = loadCommandBoard(o.board);
    if (!loaded) {
        return kExitUsage;
    }
    const board::Board& b = *loaded;
    const auto profile = bs::parseErrorProfile(o.profile);
    if (!profile) {
        fmt::print(stderr, "caphub calibrate: unknown profile '{}' (ideal, typical or harsh)\n",
                   o.profile);
        return kExitUsage;
    }
    // Where the result goes is settled before the sensors are moved through their poses: a
    // regular file or a new one in a folder that exists, not the board file.
    const auto target = exporter::claimOutputTarget(o.file, "--file", {o.board});
    if (!target) {
        fmt::print(stderr, "caphub calibrate: {}\n", target.error().message);
        return kExitUsage;
    }
    // An existing file is updated: the other kinds and other sensors' entries stay.
    CalibrationSet set;
    std::error_code ec;
    if (fs::exists(o.file, ec)) {
        auto existing = readCalibrationFile(o.file);
        if (!existing) {
            fmt::print(stderr, "caphub calibrate: {}\n", existing.error().message);
            return kExitUsage;
        }
        set = std::move(*existing);
    }

    const double durationS = o.durationS > 0 ? o.durationS : defaultDurationS(kind, {});
    const bool sim = board::allBusesSimulated(b);
    static constexpr const char* kWhat[] = {
        "gyroscope bias", "accelerometer offset and axes, gyroscope axes",
        "magnetometer hard and soft iron (and its alignment to a calibrated accelerometer)"};
    static constexpr const char* kTodo[] = {
        "lay every sensor still (on a table, off the body)",
        "turn each sensor so that each of its six faces and eight corners points up in turn "
        "(fourteen positions), holding each still for 2-3 s and turning it smoothly between",
        "turn each sensor slowly through every direction, away from metal and magnets"};
    const int k = static_cast<int>(kind);
    fmt::print("caphub calibrate: {} of {} sensors of '{}', {:g} s\n", kWhat[k], b.sensors.size(),
               b.name, durationS);
    if (sim) {
        fmt::print("virtual suit ({} profile, seed {}): the sensors are scripted to {}\n\n",
                   o.profile, o.seed, kTodo[k]);
    } else {
        fmt::print("now {}.\n\n", kTodo[k]);
    }
    auto streams =
        sim ? collectVirtual(b, kind, durationS, *profile, o.seed) : collectHub(b, durationS);
    if (!streams) {
        fmt::print(stderr, "caphub calibrate: {}\n", streams.error().message);
        return kExitRuntime;
    }
    const int done = calibrateAll(kind, b, *streams, set);
    if (done == 0) {
        fmt::print(stderr, "caphub calibrate: no sensor was calibrated; '{}' is unchanged\n",
                   o.file);
        return kExitRuntime;
    }
    if (auto w = writeCalibrationFile(*target, set); !w) {
        fmt::print(stderr, "caphub calibrate: {}\n", w.error().message);
        return kExitRuntime;
    }
    fmt::print("\n{} of {} sensors calibrated; written to {}\n", done, b.sensors.size(), o.file);
    return done == static_cast<int>(b.sensors.size()) ? kExitOk : kExitRuntime;
}

}  // namespace

void addCalibrateCommand(CLI::App& app, int& exitCode) {
    CLI::App* cmd = app.add_subcommand(
        "calibrate", "Calibrate the sensors: gyroscope bias, accelerometer, magnetometer");
    cmd->require_subcommand(1);
    struct Sub {
        const char* name;
        Kind kind;
        const char* help;
    };
    static constexpr Sub kSubs[] = {
        {"gyro", Kind::Gyro, "Gyroscope bias: every sensor lying still (default 5 s)"},
        {"accel", Kind::Accel,
         "Accelerometer offset and axes, gyroscope axes: each sensor held in fourteen positions "
         "(each face and corner up) and turned between them (default 61.5 s; six positions give "
         "the accelerometer's per-axis scale only)"},
        {"mag", Kind::Mag,
         "Magnetometer hard and soft iron: each sensor turned through every direction (default "
         "60 s)"},
    };
    for (const Sub& s : kSubs) {
        auto o = std::make_shared<CalibrateOptions>();
        CLI::App* sub = cmd->add_subcommand(s.name, s.help);
        sub->add_option("-b,--board", o->board, "Board file, or the name of a shipped board")
            ->check(nonEmptyPath())
            ->capture_default_str();
        sub->add_option("-f,--file", o->file, "Calibration file to update (created when missing)")
            ->capture_default_str();
        // Every sample is held until the fit: ten minutes of a 17-sensor suit is 100k samples
        // a sensor, and no calibration needs more (the defaults are 5-62 s).
        sub->add_option("-d,--duration", o->durationS, "Seconds to measure (0: the default)")
            ->check(zeroOrRange(1.0, 600.0));
        sub->add_option("--profile", o->profile,
                        "Virtual suit: sensor errors: ideal, typical, harsh")
            ->capture_default_str();
        sub->add_option("--seed", o->seed,
                        "Virtual suit: seed of the sensor errors (the same parts as run/sim)")
            ->check(seedNumber())
            ->capture_default_str();
        sub->callback([&exitCode, o, kind = s.kind] { exitCode = calibrate(kind, *o); });
    }
}

}  // namespace caphub::firmware
