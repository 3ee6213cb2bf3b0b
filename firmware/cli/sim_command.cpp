// caphub sim: the virtual suit played through a motion clip, the whole path of `caphub run`
// (IMU model, chip models, simulated buses, drivers, bus workers) on a stepped clock, written
// per sensor in the layout of the BROAD data set with each sensor's ground truth, so that the
// tools that read real recordings read simulated ones too.
#include <chrono>
#include <cmath>
#include <filesystem>

#include <fmt/format.h>
#include <unistd.h>
#include <zlib.h>

#include "board/loader.h"
#include "board/sim/virtual_suit.h"
#include "firmware/calibration_file.h"
#include "firmware/cli/app.h"
#include "firmware/cli/commands.h"
#include "firmware/cli/data_dir.h"
#include "firmware/cli/number_checks.h"
#include "firmware/cli/suit_options.h"
#include "firmware/export/output_file.h"
#include "firmware/export/partial_output.h"
#include "firmware/io/broad_csv.h"
#include "firmware/runtime/hub.h"
#include "hal/core/output_fd.h"

namespace caphub::firmware {

namespace {

namespace fs = std::filesystem;
namespace bs = board::sim;

struct SimOptions {
    std::string bvh;
    SuitCliOptions suit;
    std::string sensor;
    bool all = false;
    std::string out;
    std::string calibration;
};

// A sample is "movement" (the BROAD column) when the sensor truly turns faster than this or
// its mounting point accelerates more than this; BROAD marks its rest phases the same way, by
// the motion of the rigid body.
constexpr double kMovingRadS = 5.0 * hal::kPi / 180.0;
constexpr double kMovingMps2 = 0.5;

// Everything written for one sensor, and how far its readings are from the truth.
struct SensorStream {
    int sensor = -1;
    bs::SensorPlacement placement;
    BroadTrial trial;
    Vec3d lastMagUt = Vec3d::Zero();
    bool haveMag = false;
    double gyroErr2 = 0;  // sums of squared error norms
    double accelErr2 = 0;
    double magErr2 = 0;
    std::size_t magCount = 0;
    std::size_t saturated = 0;  // samples with an accel or gyro axis at full scale
};

double rms(double sum2, std::size_t n) {
    return n > 0 ? std::sqrt(sum2 / static_cast<double>(n)) : 0.0;
}

// The ground-truth skeleton of the clip: each segment's orientation (segment -> world) and
// origin (its proximal joint), skeleton world frame (docs/frames.md), metres.
Result<void> writeSkeleton(const fs::path& path, const bs::Motion& motion, double rateHz) {
    auto fd = createOutputFd(path);
    if (!fd) {
        return fd.error();
    }
    gzFile f = gzdopen(*fd, path.extension() == ".gz" ? "wb6" : "wT");
    if (f == nullptr) {
        ::close(*fd);
        return Error{EIO, fmt::format("create '{}': failed", path.string())};
    }
    std::string out = fmt::format(
        "# caphub-sim ground truth skeleton; world frame: Y up, Z the subject's reference "
        "heading (docs/frames.md); q segment -> world (w x y z); p the segment's proximal joint "
        "in m; sampling_rate_hz={:.6f}\nt",
        rateHz);
    for (const auto& seg : board::kSegments) {
        if (!motion.mapped(seg.id)) {
            continue;
        }
        for (const char* c : {"qw", "qx", "qy", "qz", "px", "py", "pz"}) {
            out += fmt::format(",{}_{}", seg.name, c);
        }
    }
    out += '\n';
    bs::SuitState state;
    const auto periodNs = static_cast<std::int64_t>(std::llround(1e9 / rateHz));
    bool ok = true;
    for (std::int64_t t = 0; t <= motion.durationNs() && ok; t += periodNs) {
        motion.evaluateAll(t, state);
        out += fmt::format("{:.6f}", static_cast<double>(t) * 1e-9);
        for (const auto& seg : board::kSegments) {
            if (!motion.mapped(seg.id)) {
                continue;
            }
            const auto& s = state[static_cast<std::size_t>(seg.id)];
            out +=
                fmt::format(",{:.9g},{:.9g},{:.9g},{:.9g},{:.6f},{:.6f},{:.6f}",
                            s.qWorldSegment.w(), s.qWorldSegment.x(), s.qWorldSegment.y(),
                            s.qWorldSegment.z(), s.positionM.x(), s.positionM.y(), s.positionM.z());
        }
        out += '\n';
        if (out.size() > (1 << 16)) {
            ok = gzwrite(f, out.data(), static_cast<unsigned>(out.size())) ==
                 static_cast<int>(out.size());
            out.clear();
        }
    }
    ok = ok && (out.empty() || gzwrite(f, out.data(), static_cast<unsigned>(out.size())) ==
                                   static_cast<int>(out.size()));
    ok = gzclose(f) == Z_OK && ok;
    if (!ok) {
        return Error{EIO, fmt::format("write '{}': failed", path.string())};
    }
    return {};
}

// One sensor's stream, written as a whole: into FILE.part, renamed over FILE when complete.
Result<void> writeStream(const fs::path& file, const BroadTrial& trial) {
    PartialOutput part(file.string() + ".part");
    // The part keeps the target's extension after ".part": written compressed as the target is.
    if (auto w = writeBroadCsv(part.path(), trial, file.extension() == ".gz"); !w) {
        return w;
    }
    std::error_code ec;
    fs::rename(part.path(), file, ec);
    if (ec) {
        return Error{ec.value(), fmt::format("rename '{}' to '{}': {}", part.path(), file.string(),
                                             ec.message())};
    }
    part.published();
    return {};
}

int sim(const SimOptions& o) {
    if (o.all == !o.sensor.empty()) {
        fmt::print(stderr, "caphub sim: give either --sensor SEGMENT or --all\n");
        return kExitUsage;
    }
    const auto loaded = loadVirtualSuitBoard(o.suit.board, "caphub sim", "the simulation");
    if (!loaded) {
        return kExitUsage;
    }
    const board::Board& b = *loaded;
    std::vector<int> wanted;
    for (std::size_t i = 0; i < b.sensors.size(); ++i) {
        const auto& s = b.sensors[i];
        if (o.all || s.name == o.sensor || board::segmentName(s.segment) == o.sensor) {
            wanted.push_back(static_cast<int>(i));
        }
    }
    if (wanted.empty()) {
        std::string names;
        for (const auto& s : b.sensors) {
            names += fmt::format("{}{} ({})", names.empty() ? "" : ", ",
                                 board::segmentName(s.segment), s.name);
        }
        fmt::print(stderr, "caphub sim: board '{}' has no sensor on '{}'; it has: {}\n", b.name,
                   o.sensor, names);
        return kExitUsage;
    }
    const auto profile = suitProfile(o.suit, "caphub sim");
    if (!profile) {
        return kExitUsage;
    }

    // The capture clock starts at a round second; clip time 0 is that instant.
    SimulatedClock clock(Timestamp{std::chrono::seconds(1)});
    const Timestamp start = clock.now();
    bs::ClipOptions clipOptions;
    clipOptions.bvh = o.bvh.empty() ? defaultMotionClip() : fs::path(o.bvh);
    clipOptions.map = o.suit.map;
    clipOptions.profile = *profile;
    clipOptions.seed = o.suit.seed;
    clipOptions.strapErrorDeg = o.suit.strapDeg;
    clipOptions.chipDelayS = o.suit.chipDelayMs * 1e-3;
    if (clipOptions.bvh.empty()) {
        fmt::print(stderr, "caphub sim: no motion: give --bvh FILE\n");
        return kExitUsage;
    }
    auto clip = bs::clipSources(clipOptions, start);
    if (!clip) {
        fmt::print(stderr, "caphub sim: {}\n", clip.error().message);
        return kExitUsage;
    }
    // A capture of no duration runs until it is stopped: a clip of one frame of motion (two
    // frames, the first the T-pose its map skips) simulated for ever.
    if (clip->motion->durationNs() <= 0) {
        fmt::print(stderr,
                   "caphub sim: '{}': its motion is a single frame (frame {} of the file): "
                   "nothing to simulate\n",
                   clipOptions.bvh.string(), clip->motion->firstFrame());
        return kExitUsage;
    }
    auto suit = bs::buildVirtualSuit(b, clock, clip->sources);
    if (!suit) {
        fmt::print(stderr, "caphub sim: {}\n", suit.error().message);
        return kExitRuntime;
    }

    std::vector<std::optional<fusion::SensorCalibration>> calibrations(b.sensors.size());
    if (!o.calibration.empty()) {
        auto set = readCalibrationFile(o.calibration);
        if (!set) {
            fmt::print(stderr, "caphub sim: {}\n", set.error().message);
            return kExitUsage;
        }
        calibrations = calibrationsFor(b, *set, nullptr);
    }

    // Where the streams go, settled before the simulation: each file regular or new, none of
    // the files the simulation reads.
    const fs::path out =
        o.out.empty() ? fs::path(o.all ? "sim-out" : "sim.csv.gz") : fs::path(o.out);
    std::error_code ec;
    if (o.all || out.has_parent_path()) {
        const fs::path folder = o.all ? out : out.parent_path();
        fs::create_directories(folder, ec);
        if (ec || !fs::is_directory(folder)) {
            fmt::print(stderr, "caphub sim: cannot create the folder '{}': {}\n", folder.string(),
                       ec ? ec.message() : "a file has the name");
            return kExitUsage;
        }
    }
    const std::vector<std::string> inputs{clipOptions.bvh.string(), o.suit.map, o.suit.board,
                                          o.calibration};
    std::vector<fs::path> files;
    for (int i : wanted) {
        const std::string name =
            o.all ? (out / (b.sensors[static_cast<std::size_t>(i)].name + ".csv.gz")).string()
                  : out.string();
        auto target = exporter::claimOutputTarget(name, "-o", inputs);
        if (!target) {
            fmt::print(stderr, "caphub sim: {}\n", target.error().message);
            return kExitUsage;
        }
        files.push_back(*target);
    }
    const fs::path skeletonFile = out / "skeleton.csv.gz";
    if (o.all) {
        if (auto target = exporter::claimOutputTarget(skeletonFile.string(), "-o", inputs);
            !target) {
            fmt::print(stderr, "caphub sim: {}\n", target.error().message);
            return kExitUsage;
        }
    }

    std::vector<int> streamOf(b.sensors.size(), -1);
    std::vector<SensorStream> streams;
    for (int i : wanted) {
        const auto& sc = b.sensors[static_cast<std::size_t>(i)];
        SensorStream st;
        st.sensor = i;
        st.placement = clip->placement(sc, i);
        st.trial.name =
            fmt::format("caphub-sim {} sensor {} on {} (board {}, profile {}, seed {})",
                        clipOptions.bvh.stem().string(), sc.name, board::segmentName(sc.segment),
                        b.name, o.suit.profile, o.suit.seed);
        st.trial.rateHz = sc.achievedOdrHz;
        streamOf[static_cast<std::size_t>(i)] = static_cast<int>(streams.size());
        streams.push_back(std::move(st));
    }

    const bs::Motion& motion = *clip->motion;
    const bs::Environment& env = clip->environment;
    const Quatd qEnuWorld = bs::qEnuWorld();
    const Vec3d gravityWorld(0, -env.gravityMps2, 0);
    std::uint64_t events = 0;
    std::uint64_t samples = 0;
    bs::SegmentState seg;
    const auto onSample = [&](const SensorSample& s) {
        ++samples;
        const int k = streamOf[static_cast<std::size_t>(s.sensor)];
        const Duration sinceStart = s.sample.t - start;
        if (k < 0 || sinceStart.count() < 0 || toNs(sinceStart) > motion.durationNs()) {
            return;
        }
        SensorStream& st = streams[static_cast<std::size_t>(k)];
        const std::int64_t tNs = toNs(sinceStart);
        motion.evaluate(st.placement.segment, tNs, seg);
        const bs::ImuSignals truth = bs::idealSignals(seg, st.placement, env);
        const Quatd qWorldSensor = seg.qWorldSegment * st.placement.mounting;

        fusion::ImuSample row;
        row.tS = static_cast<double>(tNs) * 1e-9;
        row.gyrRadS = s.sample.gyrRadps.cast<double>();
        row.accMps2 = s.sample.accMps2.cast<double>();
        row.magUt = s.sample.magUt.cast<double>();
        if (const auto& cal = calibrations[static_cast<std::size_t>(s.sensor)]) {
            row = cal->apply(row);
        }
        if ((s.sample.flags & hal::ImuSample::kMagFresh) != 0) {
            st.lastMagUt = row.magUt;
            st.haveMag = true;
            st.magErr2 += (st.lastMagUt - truth.magUt).squaredNorm();
            ++st.magCount;
        }
        // Between magnetometer readings a row repeats the last one (BROAD rows all carry a
        // field); rows before the first reading carry zeros.
        row.magUt = st.haveMag ? st.lastMagUt : Vec3d::Zero();
        st.trial.samples.push_back(row);
        st.trial.truth.push_back(qEnuWorld * qWorldSensor);
        const Vec3d accelWorld = qWorldSensor * truth.accelMps2 + gravityWorld;
        st.trial.movement.push_back(truth.gyroRadS.norm() > kMovingRadS ||
                                    accelWorld.norm() > kMovingMps2);
        if ((s.sample.flags & (hal::ImuSample::kAccSaturated | hal::ImuSample::kGyrSaturated)) !=
            0) {
            ++st.saturated;
        }
        st.gyroErr2 += (row.gyrRadS - truth.gyroRadS).squaredNorm();
        st.accelErr2 += (row.accMps2 - truth.accelMps2).squaredNorm();
    };

    CallbackStage collect(onSample, [&events](const RuntimeEvent&) { ++events; });
    const auto wallStart = std::chrono::steady_clock::now();
    (void)captureSamples(b, clock, *suit, Capture::Mode::Stepped,
                         start + Duration{motion.durationNs()} - clock.now(), collect);
    const double wallS =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - wallStart).count();
    const double simS = static_cast<double>(motion.durationNs()) * 1e-9;

    fmt::print(
        "caphub sim: {} ({:.2f} s, {} frames) on board '{}', profile {}, seed {}, straps {:g} "
        "deg{}\n",
        clipOptions.bvh.filename().string(), simS, motion.frameCount(), b.name, o.suit.profile,
        o.suit.seed, o.suit.strapDeg,
        o.calibration.empty() ? "" : ", calibrated with " + o.calibration);
    fmt::print("simulated {} sensors, {} samples, {} events in {:.3f} s: {:.1f}x real time\n\n",
               b.sensors.size(), samples, events, wallS, wallS > 0 ? simS / wallS : 0.0);
    fmt::print("{:<11} {:<13} {:>7} {:>8} {:>10} {:>10} {:>9} {:>5}  {}\n", "sensor", "segment",
               "rows", "rate Hz", "gyro dps", "acc m/s2", "mag uT", "sat", "file");
    for (std::size_t k = 0; k < streams.size(); ++k) {
        SensorStream& st = streams[k];
        const auto& sc = b.sensors[static_cast<std::size_t>(st.sensor)];
        const fs::path& file = files[k];
        if (auto w = writeStream(file, st.trial); !w) {
            fmt::print(stderr, "caphub sim: {}\n", w.error().message);
            return kExitRuntime;
        }
        const std::size_t n = st.trial.samples.size();
        fmt::print("{:<11} {:<13} {:>7} {:>8.1f} {:>10.4f} {:>10.4f} {:>9.3f} {:>5}  {}\n", sc.name,
                   board::segmentName(sc.segment), n, st.trial.rateHz,
                   rms(st.gyroErr2, n) * 180.0 / hal::kPi, rms(st.accelErr2, n),
                   rms(st.magErr2, st.magCount), st.saturated, file.string());
    }
    fmt::print(
        "(gyro/acc/mag: RMS of the error vector's norm against the sensor's ground truth; sat: "
        "samples with an axis at full scale)\n");
    if (o.all) {
        double rateHz = 0;
        for (const auto& sc : b.sensors) {
            rateHz = std::max(rateHz, sc.achievedOdrHz);
        }
        const fs::path& skeleton = skeletonFile;
        if (auto w = writeSkeleton(skeleton, motion, rateHz); !w) {
            fmt::print(stderr, "caphub sim: {}\n", w.error().message);
            return kExitRuntime;
        }
        fmt::print("ground truth skeleton: {}\n", skeleton.string());
    }
    return kExitOk;
}

}  // namespace

void addSimCommand(CLI::App& app, int& exitCode) {
    auto o = std::make_shared<SimOptions>();
    CLI::App* cmd = app.add_subcommand(
        "sim", "Play a BVH clip on the virtual suit; write sensor streams in the BROAD layout");
    cmd->add_option("--bvh", o->bvh, "The motion (BVH); default: the shipped walking clip")
        ->check(nonEmptyPath());
    addSuitOptions(*cmd, o->suit);
    cmd->add_option("--sensor", o->sensor, "The sensor to write: its segment or its name");
    cmd->add_flag("--all", o->all, "Write every sensor, and the ground-truth skeleton");
    cmd->add_option("--calibration", o->calibration,
                    "Apply this calibration file (caphub calibrate) to the streams written")
        ->check(nonEmptyPath());
    cmd->add_option("-o,--out", o->out, "FILE.csv.gz for --sensor, a folder for --all");
    cmd->callback([&exitCode, o] { exitCode = sim(*o); });
}

}  // namespace caphub::firmware
