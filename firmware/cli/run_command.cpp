// caphub run: capture from a suit - the hub's real buses, or the virtual suit when the board's
// buses are simulated - recording every sample and event, until Ctrl-C or a duration.
#include <cstdlib>
#include <ctime>
#include <filesystem>

#include <fmt/format.h>
#include <sys/resource.h>

#include "board/loader.h"
#include "board/sim/virtual_suit.h"
#include "board/stream_spec.h"
#include "firmware/cli/app.h"
#include "firmware/cli/capture_setup.h"
#include "firmware/cli/commands.h"
#include "firmware/cli/data_dir.h"
#include "firmware/cli/info.h"
#include "firmware/cli/number_checks.h"
#include "firmware/cli/preview_sinks.h"
#include "firmware/evaluation.h"
#include "firmware/export/output_file.h"
#include "firmware/runtime/hub.h"
#include "hal/core/input_file.h"
#include "hal/core/log.h"
#include "render/sinks.h"

namespace caphub::firmware {

namespace {

namespace fs = std::filesystem;

struct RunOptions {
    std::string board = "sim-suit";
    double durationS = 0;
    std::string out;
    std::string record;  // the recording's path; empty: a timestamped name in `out`
    int realtime = -1;   // SCHED_FIFO priority of the capture threads; -1: the board's
    int syncMs = 200;    // the recording's durability interval
    bool noRecord = false;
    // The virtual suit (its motion, sensor errors, pace); the rest of it is filled in at the
    // start.
    CaptureSetupOptions suit;
    std::string calibration;
    std::string bodyCalibration = "none";  // tpose, npose, none
    double poseRateHz = 60;
    std::vector<std::string> previews;  // png:DIR, fb:/dev/fbN, http:PORT
    double previewFps = 10;
    bool noPreview = false;
    std::string statusFile;            // empty: defaultStatusPath()
    std::string magState;              // empty: the magnetometer estimates are not kept
    std::vector<std::string> streams;  // KIND:HOST:PORT[@RATE]; none: the board's outputs
    bool noStream = false;
};

// The preview sinks of --preview, or without it the board's outputs.
render::SinkSet previewSinks(const RunOptions& o, const board::Board& b) {
    std::vector<std::string> specs = o.previews;
    if (o.noPreview) {
        specs.clear();
    } else if (specs.empty()) {
        if (!b.outputs.previewPng.empty()) {
            specs.push_back("png:" + b.outputs.previewPng);
        }
        if (!b.outputs.mjpeg.empty()) {
            specs.push_back("http:" + b.outputs.mjpeg);
        }
    }
    return openPreviewSinks(specs);
}

std::string timestampName() {
    const std::time_t now = std::time(nullptr);
    char buf[32];
    std::strftime(buf, sizeof buf, "%Y%m%d-%H%M%S", std::localtime(&now));
    return buf;
}

// The body's figures: the calibration and, on the virtual suit, how far its mountings are from
// the sensors' true (strapped) ones; the poses and their latency.
// Where the CPU went: the capture's own threads over the capture's real time (a paced
// virtual suit's capture clock runs faster or slower), and the whole process over its life
// (the preview's rendering, the recorder's disk writes, the streams, and the setup before).
void printCpu(const CaptureStats& stats, Timestamp processStart) {
    const double seconds = toSeconds(stats.realElapsed);
    const double lifeS = toSeconds(MonotonicClock().now() - processStart);
    rusage usage{};
    if (seconds <= 0 || lifeS <= 0 || stats.pipelineCpu.count() == 0 ||
        ::getrusage(RUSAGE_SELF, &usage) != 0) {
        return;  // stepped, or nothing measured
    }
    const auto cpuS = [](const timeval& tv) {
        return static_cast<double>(tv.tv_sec) + static_cast<double>(tv.tv_usec) * 1e-6;
    };
    const double pipeline = toSeconds(stats.pipelineCpu);
    const double workers = toSeconds(stats.busWorkersCpu);
    const double process = cpuS(usage.ru_utime) + cpuS(usage.ru_stime);
    fmt::print(
        "cpu over the capture's {:.2f} s of real time: pipeline {:.2f} s ({:.1f} % of one core), "
        "bus workers {:.2f} s ({:.1f} %); whole process {:.2f} s in {:.2f} s ({:.1f} %)\n",
        seconds, pipeline, 100 * pipeline / seconds, workers, 100 * workers / seconds, process,
        lifeS, 100 * process / lifeS);
}

void printBody(const BodyStage& body, const board::Board& b,
               const std::function<board::sim::SensorPlacement(const board::SensorConfig&, int)>&
                   placementOf) {
    const auto& cal = body.calibration();
    if (!body.calibrationError().empty()) {
        fmt::print("\nbody calibration failed: {}", body.calibrationError());
    } else if (!body.calibrated()) {
        fmt::print("\nbody: not calibrated (the capture ended first)");
    } else {
        fmt::print("\nbody calibration: {}", cal.method == body::CalibrationMethod::None
                                                 ? std::string("nominal mountings")
                                                 : std::string(body::toString(cal.method)));
        if (placementOf && cal.method != body::CalibrationMethod::None) {
            const MountingErrors m = mountingErrors(cal, b, placementOf);
            fmt::print(
                "; mountings off the true (strapped) ones by {:.2f} deg mean, {:.2f} deg max "
                "(the board's nominal ones: {:.2f} deg mean)",
                m.meanDeg, m.maxDeg, m.nominalMeanDeg);
        }
    }
    fmt::print("\n{} poses; latency data-ready -> pose written p50 {:.3f} ms, p99 {:.3f} ms",
               body.poses(), toSeconds(body.latencyPercentile(0.5)) * 1e3,
               toSeconds(body.latencyPercentile(0.99)) * 1e3);
}

int run(const RunOptions& o) {
    const Timestamp processStart = MonotonicClock().now();
    const auto loaded = loadCommandBoard(o.board);
    if (!loaded) {
        return kExitUsage;
    }
    const board::Board& b = *loaded;
    BodyStage::Options bodyOptions;
    bodyOptions.rateHz = o.poseRateHz;
    if (o.bodyCalibration == "tpose") {
        bodyOptions.calibrate = body::ReferencePoseKind::T;
    } else if (o.bodyCalibration == "npose") {
        bodyOptions.calibrate = body::ReferencePoseKind::N;
    } else if (o.bodyCalibration != "none") {
        fmt::print(stderr, "caphub run: --calibrate: expected tpose, npose or none, got '{}'\n",
                   o.bodyCalibration);
        return kExitUsage;
    }
    for (const auto& spec : o.previews) {
        if (auto p = parsePreviewSpec(spec); !p) {
            fmt::print(stderr, "caphub run: --{}\n", p.error().message);
            return kExitUsage;
        }
    }
    if (std::error_code ec; !o.magState.empty() && fs::exists(fs::symlink_status(o.magState, ec))) {
        // A file to read and replace: what is there must be one (a missing one is a first run).
        if (auto ok = checkInputFile(o.magState); !ok) {
            fmt::print(stderr, "caphub run: --mag-state: {}\n", ok.error().message);
            return kExitUsage;
        }
        // A file that is not a state file at all (a mistyped path) is refused: it would be
        // replaced by the first save. A damaged state file is learnt afresh.
        if (auto ok = checkMagStateFile(o.magState); !ok) {
            fmt::print(stderr, "caphub run: --mag-state: {}\n", ok.error().message);
            return kExitUsage;
        }
    }
    // A recording is a new file: what is at --record is said for what it is (a directory, a
    // device and a FIFO were all "File exists").
    if (!o.record.empty()) {
        std::error_code ec;
        auto target = exporter::regularOutputTarget(o.record);
        if (!target) {
            fmt::print(stderr, "caphub run: --record: {}\n", target.error().message);
            return kExitUsage;
        }
        if (fs::exists(fs::symlink_status(o.record, ec))) {
            fmt::print(stderr,
                       "caphub run: --record: '{}' exists: a recording never replaces a file\n",
                       o.record);
            return kExitUsage;
        }
    }
    // The files the capture writes: none of them another's, nor a file it reads, nor a device
    // or a FIFO (the status file used to replace /dev/null, or the recording itself).
    const fs::path statusPath = o.statusFile.empty() ? defaultStatusPath() : fs::path(o.statusFile);
    if (auto ok = exporter::claimOutputTarget(statusPath.string(), "--status-file",
                                              {o.record, o.magState, o.calibration, o.suit.bvh});
        !ok) {
        fmt::print(stderr, "caphub run: {}\n", ok.error().message);
        return kExitUsage;
    }
    if (!o.magState.empty()) {
        if (auto ok = exporter::claimOutputTarget(o.magState, "--mag-state",
                                                  {o.record, o.calibration, o.suit.bvh});
            !ok) {
            fmt::print(stderr, "caphub run: {}\n", ok.error().message);
            return kExitUsage;
        }
    }
    // The pose is held from the start until the orientations have been averaged, plus a margin.
    const double holdS = toSeconds(bodyOptions.settle + bodyOptions.average) + 0.5;
    CaptureSetupOptions so = o.suit;
    so.leadInPose = bodyOptions.calibrate;
    so.holdS = holdS;
    so.calibration = o.calibration;
    auto setup = buildCaptureSetup(b, so);
    if (!setup) {
        fmt::print(stderr, "caphub run: {}\n", setup.error().message);
        return setup.error().code == EINVAL ? kExitUsage : kExitRuntime;
    }
    if (const std::string problem = recordingProblem(b, o.calibration, setup->calibrationText);
        !problem.empty()) {
        fmt::print(stderr, "caphub run: {}: {}\n", b.path.string(), problem);
        return kExitUsage;
    }
    // The live streams: --stream, or without it the board's outputs.
    std::vector<board::StreamConfig> streams;
    if (o.streams.empty()) {
        if (!o.noStream) {
            streams = b.outputs.streams;
        }
    } else {
        for (const std::string& spec : o.streams) {
            auto s = board::parseStreamSpec(spec);
            if (!s) {
                fmt::print(stderr, "caphub run: --stream: {}\n", s.error().message);
                return kExitUsage;
            }
            streams.push_back(*s);
        }
    }
    const bool sim = setup->sim;
    // From the moment the recording is created, a signal stops the capture cleanly.
    StopSignals signals;
    HubOptions ho;
    ho.calibrations = setup->calibrations;
    ho.body = bodyOptions;
    ho.threads = ThreadPolicy::fromBoard(b.runtime);
    if (o.realtime >= 0) {
        ho.threads.realtimePriority = o.realtime;
    }
    ho.streams = streams;
    ho.statusPath = statusPath;
    ho.magStatePath = o.magState;
    fs::path recordingPath;
    if (!o.noRecord) {
        const fs::path dir =
            !o.record.empty() ? fs::path(o.record).parent_path()
                              : (o.out.empty() ? fs::path(b.outputs.recordings) : fs::path(o.out));
        std::error_code ec;
        if (!o.record.empty()) {
            // A file named: its folder must be there, as for every other command's output (a
            // mistyped folder would otherwise be made, and the take looked for elsewhere).
            if (!dir.empty() && !fs::exists(dir, ec)) {
                fmt::print(stderr, "caphub run: --record {}: the folder '{}' does not exist\n",
                           o.record, dir.string());
                return kExitUsage;
            }
        } else if (!dir.empty()) {
            fs::create_directories(dir, ec);
        }
        if (ec) {
            fmt::print(stderr, "caphub run: cannot create '{}': {}\n", dir.string(), ec.message());
            return exitCodeForCreate(ec.value());
        }
        recordingPath = !o.record.empty() ? fs::path(o.record)
                                          : dir / fmt::format("{}-{}.cap", timestampName(), b.name);
        ho.writer.syncInterval = std::chrono::milliseconds(o.syncMs);
        auto writer =
            RecordingWriter::create(recordingPath.string(),
                                    recordingMetadata(b, setup->boardText, versionLine(),
                                                      o.calibration, setup->calibrationText),
                                    ho.writer);
        if (!writer) {
            fmt::print(stderr, "caphub run: {}\n", writer.error().message);
            return exitCodeForCreate(writer.error().code);
        }
        ho.recordFromStart = std::move(*writer);
    }
    attachPreview(ho, previewSinks(o, b), o.previewFps, "caphub run");
    Hub hub(b, *setup->clock, *setup->suit, std::move(ho));
    if (bodyOptions.calibrate && !sim) {
        fmt::print("stand still in the {} for the first {:.0f} s\n",
                   bodyOptions.calibrate == body::ReferencePoseKind::T ? "T-pose" : "N-pose",
                   holdS);
    }

    fmt::print("caphub run: {} sensors on {} buses of '{}' ({}){}\n", b.sensors.size(),
               b.buses.size(), b.name,
               sim ? "virtual suit, motion " + setup->motionText : "hub buses",
               o.durationS > 0 ? fmt::format(", {:g} s", o.durationS) : ", Ctrl-C to stop");
    signals.arm(hub.capture());
    hub.start(durationFromSeconds(o.durationS));
    const CaptureStats stats = hub.wait();

    const double seconds = toSeconds(stats.elapsed);
    fmt::print("\n{:<12} {:>9} {:>9} {:>7} {:>7}\n", "sensor", "samples", "rate Hz", "lost",
               "errors");
    for (const auto& w : hub.capture().workers()) {
        for (std::size_t i = 0; i < w->sensorCount(); ++i) {
            const auto& c = w->counters(i);
            const auto& sensor =
                b.sensors[static_cast<std::size_t>(w->hardware().sensors[i].sensor)];
            fmt::print("{:<12} {:>9} {:>9.1f} {:>7} {:>7}\n", sensor.name, c.samples.load(),
                       seconds > 0 ? static_cast<double>(c.samples.load()) / seconds : 0.0,
                       c.lost.load(), c.readErrors.load());
        }
    }
    fmt::print("\n{} orientation updates", hub.fusion().updates());
    printBody(hub.body(), b, setup->placementOf);
    if (const PreviewStage* preview = hub.preview()) {
        const std::string err = preview->error();
        fmt::print("\npreview: {} frames rendered, {} skipped{}", preview->framesRendered(),
                   preview->framesSkipped(), err.empty() ? "" : " - " + err);
    }
    for (const auto& stream : hub.streams()) {
        const std::string err = stream->lastError();
        // Latencies only of frames that went: none sent, none measured (it printed 0.000 ms).
        const std::string latency =
            stream->sent() == 0
                ? std::string("; no latency measured")
                : fmt::format(
                      "; latency data-ready -> sent p50 {:.3f} ms, p99 {:.3f} ms, max "
                      "{:.3f} ms",
                      toSeconds(stream->latencyPercentile(0.5)) * 1e3,
                      toSeconds(stream->latencyPercentile(0.99)) * 1e3,
                      toSeconds(stream->latencyMax()) * 1e3);
        fmt::print("\nstream {}: {} frames sent ({} datagrams), {} failed{}{}",
                   board::toString(stream->config()), stream->sent(), stream->datagrams(),
                   stream->errors(), err.empty() ? "" : " (last: " + err + ")", latency);
    }
    fmt::print(
        "\n{} samples in {:.2f} s, {} dropped{}, {} sensor losses; latency data-ready -> "
        "pipeline p50 {:.3f} ms, p99 {:.3f} ms, max {:.3f} ms\n",
        stats.samples, seconds, stats.dropped,
        stats.abandoned > 0
            ? fmt::format(" ({} more left unprocessed at the end: the pipeline was too far behind)",
                          stats.abandoned)
            : std::string(),
        stats.lost, toSeconds(stats.latencyP50) * 1e3, toSeconds(stats.latencyP99) * 1e3,
        toSeconds(stats.latencyMax) * 1e3);
    printCpu(stats, processStart);
    if (const RecordingWriter* w = hub.recorder().current(); w != nullptr) {
        std::error_code ec;
        const auto size = fs::file_size(recordingPath, ec);
        fmt::print("recording: {} ({} records, {} bytes){}\n", recordingPath.string(),
                   w->stats().records, ec ? 0 : size,
                   w->error() != 0 ? " - stopped early: " + errnoText(w->error()) : "");
        if (w->error() != 0) {
            return kExitRuntime;
        }
    }
    return kExitOk;
}

}  // namespace

void addRunCommand(CLI::App& app, int& exitCode) {
    auto o = std::make_shared<RunOptions>();
    CLI::App* cmd = app.add_subcommand(
        "run",
        "Capture: sample the suit, record every sample and event (virtual suit for sim boards)");
    cmd->add_option("-b,--board", o->board, "Board file, or the name of a shipped board")
        ->check(nonEmptyPath())
        ->capture_default_str();
    cmd->add_option("-d,--duration", o->durationS, "Seconds to capture (0: until Ctrl-C)")
        ->check(zeroOrRange(kMinDurationS, kMaxDurationS))
        ->capture_default_str();
    cmd->add_option("-o,--out", o->out,
                    "Folder for a timestamped recording (default: the board's outputs)")
        ->check(nonEmptyPath());
    auto* record = cmd->add_option("-r,--record", o->record,
                                   "The recording's file (.cap); an existing file is not replaced")
                       ->check(nonEmptyPath());
    cmd->add_option("--sync-ms", o->syncMs,
                    "The most a power cut may lose of the recording: fdatasync interval, ms")
        ->check(finiteRange(10, 10000))
        ->capture_default_str();
    cmd->add_option("--realtime", o->realtime,
                    "SCHED_FIFO priority of the capture threads, 1-99 (0: normal scheduling; "
                    "default: the board's [runtime])")
        ->check(finiteRange(0, 99));
    addVirtualSuitOptions(*cmd, o->suit);
    cmd->add_flag("--no-record", o->noRecord, "Do not write a recording")->excludes(record);
    cmd->add_option("--calibrate", o->bodyCalibration,
                    "Body calibration at the start: tpose, npose (the subject holds the pose "
                    "for the first seconds) or none (the board's nominal mountings)")
        ->capture_default_str();
    cmd->add_option("--pose-rate", o->poseRateHz, "Poses per second of the body solver")
        ->check(finiteRange(1.0, 1000.0))
        ->capture_default_str();
    cmd->add_option("--preview", o->previews,
                    "Preview frames to png:DIR, fb:/dev/fbN or http:[HOST:]PORT (repeatable; "
                    "default: the board's outputs)");
    cmd->add_option("--status-file", o->statusFile,
                    "Where to keep the live status for `caphub status` (default: $CAPHUB_STATUS, "
                    "/run/caphub/status.json, or the temporary folder)")
        ->check(nonEmptyPath());
    cmd->add_option("--mag-state", o->magState,
                    "Keep what the magnetometers that the calibration file does not correct learn "
                    "of their hard and soft iron in this file: read at the start, saved every "
                    "minute and at the end (docs/fusion.md)")
        ->check(nonEmptyPath());
    cmd->add_option("--stream", o->streams,
                    "Stream the poses live to KIND:HOST:PORT[@RATE], KIND vmc, vrchat or caphub "
                    "(repeatable; e.g. vmc:127.0.0.1:39539@60; default: the board's outputs)");
    cmd->add_flag("--no-stream", o->noStream, "No stream, whatever the board's outputs say");
    cmd->add_flag("--no-preview", o->noPreview, "No preview, whatever the board's outputs say");
    cmd->add_option("--preview-fps", o->previewFps, "Preview frames per second")
        ->check(finitePositive())
        ->capture_default_str();
    cmd->add_option("--calibration", o->calibration,
                    "Calibration file (caphub calibrate) applied before the filter and recorded")
        ->check(nonEmptyPath());
    cmd->callback([&exitCode, o] { exitCode = run(*o); });
}

}  // namespace caphub::firmware
