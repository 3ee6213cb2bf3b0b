// caphub serve: the hub running until SIGTERM/SIGINT - sensors, fusion, body, status, preview -
// operated from a phone or laptop through its web page and HTTP API (firmware/serve,
// docs/serve.md). `caphub serve --set-password` stores the password that listening beyond this
// machine needs.
#include <charconv>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <future>
#include <iostream>
#include <memory>
#include <thread>

#include <fmt/format.h>
#include <unistd.h>

#include "firmware/cli/app.h"
#include "firmware/cli/capture_setup.h"
#include "firmware/cli/commands.h"
#include "firmware/cli/data_dir.h"
#include "firmware/cli/info.h"
#include "firmware/cli/number_checks.h"
#include "firmware/cli/preview_sinks.h"
#include "firmware/export/output_file.h"
#include "firmware/runtime/hub.h"
#include "firmware/serve/auth.h"
#include "firmware/serve/calibration_motion.h"
#include "firmware/serve/sample_tap.h"
#include "firmware/serve/sensor_calibration_session.h"
#include "firmware/serve/web_server.h"
#include "render/sinks.h"

namespace caphub::firmware {

namespace {

namespace fs = std::filesystem;

struct ServeOptions {
    std::string board = "sim-suit";
    std::string listen = "127.0.0.1:8080";
    std::string recordings;  // empty: the board's outputs
    std::string stateDir;    // empty: defaultStateDir()
    std::string webRoot;     // empty: serve::defaultWebRoot()
    bool setPassword = false;
    double durationS = 0;
    int realtime = -1;
    int syncMs = 200;
    double poseRateHz = 60;
    // The virtual suit (its motion, sensor errors, pace); the rest of it is filled in at the
    // start.
    CaptureSetupOptions suit;
    std::string calibration;  // empty: STATE_DIR/calibration.toml when it exists
    std::vector<std::string> previews;
    double previewFps = 10;
    bool noPreview = false;
    std::string statusFile;
    int threads = 24;
    int maxStreams = 12;
    int maxDownloads = 6;
    // Virtual suit: the subject first holds this pose (tpose, npose) for leadInS seconds.
    std::string leadIn;
    double leadInS = 8;
};

// $CAPHUB_STATE_DIR; /var/lib/caphub when it is a folder this user may write (the service's);
// else $XDG_STATE_HOME/caphub or ~/.local/state/caphub.
fs::path defaultStateDir() {
    if (const char* env = std::getenv("CAPHUB_STATE_DIR"); env != nullptr && *env != '\0') {
        return env;
    }
    std::error_code ec;
    if (fs::is_directory("/var/lib/caphub", ec) && ::access("/var/lib/caphub", W_OK) == 0) {
        return "/var/lib/caphub";
    }
    if (const char* xdg = std::getenv("XDG_STATE_HOME"); xdg != nullptr && *xdg != '\0') {
        return fs::path(xdg) / "caphub";
    }
    const char* home = std::getenv("HOME");
    return fs::path(home != nullptr ? home : ".") / ".local" / "state" / "caphub";
}

// HOST:PORT, [V6]:PORT or PORT (on 127.0.0.1).
Result<std::pair<std::string, int>> parseListen(const std::string& text) {
    std::string host = "127.0.0.1";
    std::string port = text;
    if (const auto colon = text.rfind(':'); colon != std::string::npos) {
        host = text.substr(0, colon);
        port = text.substr(colon + 1);
        if (host.size() >= 2 && host.front() == '[' && host.back() == ']') {
            host = host.substr(1, host.size() - 2);
        }
    }
    int value = -1;
    const auto [end, ec] = std::from_chars(port.data(), port.data() + port.size(), value);
    if (host.empty() || port.empty() || ec != std::errc() || end != port.data() + port.size() ||
        value < 0 || value > 65535) {
        return Error{EINVAL,
                     fmt::format("--listen '{}': expected HOST:PORT with a port 0-65535", text)};
    }
    return std::pair{host, value};
}

int setPasswordFromStdin(const fs::path& stateDir) {
    if (isatty(STDIN_FILENO) == 1) {
        fmt::print(stderr, "password (8 characters at least), then Enter: ");
    }
    std::string password;
    std::getline(std::cin, password);
    if (!password.empty() && password.back() == '\r') {
        password.pop_back();
    }
    auto r = serve::setPassword(stateDir, password);
    if (!r) {
        fmt::print(stderr, "caphub serve: {}\n", r.error().message);
        return r.error().code == EINVAL ? kExitUsage : kExitRuntime;
    }
    fmt::print("caphub serve: password stored (hashed) in {}\n",
               serve::passwordFile(stateDir).string());
    return kExitOk;
}

// How long the web server's workers have to finish their requests once the hub has stopped.
constexpr std::chrono::milliseconds kWebStopGrace{2000};

int runServe(const ServeOptions& o) {
    const fs::path stateDir = o.stateDir.empty() ? defaultStateDir() : fs::path(o.stateDir);
    if (o.setPassword) {
        return setPasswordFromStdin(stateDir);
    }
    const auto listen = parseListen(o.listen);
    if (!listen) {
        fmt::print(stderr, "caphub serve: {}\n", listen.error().message);
        return kExitUsage;
    }
    const auto& [host, port] = *listen;
    if (!serve::isLoopbackHost(host) && !serve::hasPassword(stateDir)) {
        fmt::print(stderr,
                   "caphub serve: listening on {} (beyond this machine) needs a password; set one "
                   "first: caphub serve --set-password --state-dir {}\n",
                   host, stateDir.string());
        return kExitUsage;
    }
    // An extra MJPEG preview has no password: beyond this machine it would show the capture to
    // anyone on the network while the page says "this machine only".
    for (const std::string& spec : o.previews) {
        if (auto p = parsePreviewSpec(spec);
            p && p->kind == "http" && !serve::isLoopbackHost(p->host)) {
            fmt::print(stderr,
                       "caphub serve: --preview '{}': an MJPEG preview has no password, so serve "
                       "keeps it on this machine (127.0.0.1 or [::1]); beyond it, watch the "
                       "preview on the page\n",
                       spec);
            return kExitUsage;
        }
    }
    const fs::path webRoot = o.webRoot.empty() ? serve::defaultWebRoot() : fs::path(o.webRoot);
    if (webRoot.empty()) {
        fmt::print(stderr,
                   "caphub serve: the web page's files are not found (set "
                   "CAPHUB_WEB_DIR or --web-root); the API works without them\n");
    }
    const auto loaded = loadCommandBoard(o.board);
    if (!loaded) {
        return kExitUsage;
    }
    const board::Board& b = *loaded;
    CaptureSetupOptions so = o.suit;
    if (!o.leadIn.empty()) {
        if (o.leadIn != "tpose" && o.leadIn != "npose") {
            fmt::print(stderr, "caphub serve: --lead-in: expected tpose or npose, got '{}'\n",
                       o.leadIn);
            return kExitUsage;
        }
        so.leadInPose =
            o.leadIn == "tpose" ? body::ReferencePoseKind::T : body::ReferencePoseKind::N;
        so.holdS = o.leadInS;
    }
    so.calibration = o.calibration;
    if (so.calibration.empty()) {
        // The sensor calibration kept on the hub is applied at every start.
        std::error_code ec;
        if (const fs::path kept = stateDir / "calibration.toml"; fs::is_regular_file(kept, ec)) {
            so.calibration = kept.string();
        }
    }
    // The guided sensor calibration: on the virtual suit it plays the calibration motions.
    std::shared_ptr<serve::CalibrationMotion> motion;
    if (board::allBusesSimulated(b)) {
        if (const auto profile = board::sim::parseErrorProfile(so.profile)) {
            motion = std::make_shared<serve::CalibrationMotion>(b, *profile, so.seed);
            so.wrapSources = [motion](board::sim::SourceFactory inner) {
                return motion->wrap(std::move(inner));
            };
        }
    }
    auto setup = buildCaptureSetup(b, so);
    if (!setup) {
        fmt::print(stderr, "caphub serve: {}\n", setup.error().message);
        return setup.error().code == EINVAL ? kExitUsage : kExitRuntime;
    }
    // The folders and the status file, checked before the capture starts: a takes folder that is
    // a file (or a FIFO) used to start and fail every take; a status file that is a device was
    // replaced.
    const fs::path recordings =
        o.recordings.empty() ? fs::path(b.outputs.recordings) : fs::path(o.recordings);
    for (const auto& [option, folder] :
         {std::pair{"--recordings", recordings}, std::pair{"--state-dir", stateDir}}) {
        std::error_code ec;
        fs::create_directories(folder, ec);
        if (!fs::is_directory(folder, ec)) {
            fmt::print(stderr, "caphub serve: {} '{}' is not a folder{}\n", option, folder.string(),
                       ec ? ": " + ec.message() : "");
            return kExitUsage;
        }
    }
    const fs::path statusPath = o.statusFile.empty() ? defaultStatusPath() : fs::path(o.statusFile);
    if (auto ok = exporter::claimOutputTarget(statusPath.string(), "--status-file",
                                              {so.calibration, o.suit.bvh});
        !ok) {
        fmt::print(stderr, "caphub serve: {}\n", ok.error().message);
        return kExitUsage;
    }
    StopSignals signals;
    HubOptions ho;
    ho.calibrations = setup->calibrations;
    ho.body.rateHz = o.poseRateHz;
    ho.threads = ThreadPolicy::fromBoard(b.runtime);
    if (o.realtime >= 0) {
        ho.threads.realtimePriority = o.realtime;
    }
    ho.statusPath = statusPath;
    // What the magnetometers the calibration does not correct learn is kept on the hub: the
    // next start is magnetic from its first sample (docs/fusion.md, "Persistence").
    {
        std::error_code ec;
        fs::create_directories(stateDir, ec);
    }
    ho.magStatePath = stateDir / "mag-estimates.txt";
    ho.recordings = recordings;
    ho.boardText = setup->boardText;
    ho.softwareVersion = versionLine();
    ho.calibrationPath = so.calibration;
    ho.calibrationText = setup->calibrationText;
    ho.writer.syncInterval = std::chrono::milliseconds(o.syncMs);
    std::shared_ptr<render::JpegFrameSlot> preview;
    if (!o.noPreview) {
        render::SinkSet sinks = openPreviewSinks(o.previews);
        preview = std::make_shared<render::JpegFrameSlot>();
        sinks.add(render::makeJpegSlotSink(preview));
        attachPreview(ho, std::move(sinks), o.previewFps, "caphub serve");
        if (!ho.previewSkin) {
            preview.reset();
        }
    }
    serve::SampleTap tap;
    ho.stages.push_back(&tap);
    Hub hub(b, *setup->clock, *setup->suit, std::move(ho));
    serve::SensorCalibrationSession calibration(b, *setup->clock, tap, motion,
                                                stateDir / "calibration.toml", so.calibration);
    signals.arm(hub.capture());
    hub.start(durationFromSeconds(o.durationS));

    serve::WebOptions wo;
    wo.host = host;
    wo.port = port;
    wo.recordings = o.recordings.empty() ? fs::path(b.outputs.recordings) : fs::path(o.recordings);
    wo.stateDir = stateDir;
    wo.webRoot = webRoot;
    wo.version = versionLine();
    wo.sensorCalibration = so.calibration;
    wo.calibrationSession = &calibration;
    wo.preview = preview;
    wo.threads = o.threads;
    wo.maxStreams = o.maxStreams;
    wo.maxDownloads = o.maxDownloads;
    auto web = serve::WebServer::start(hub, b, wo);
    if (!web) {
        fmt::print(stderr, "caphub serve: {}\n", web.error().message);
        hub.requestStop();
        (void)hub.wait();
        return web.error().code == EADDRINUSE ? kExitRuntime : kExitUsage;
    }
    const std::string shownHost = host.find(':') != std::string::npos ? "[" + host + "]" : host;
    fmt::print(
        "caphub serve: http://{}:{}/ - {} sensors on '{}' ({}); takes in {}; state in {}{}\n",
        shownHost, (*web)->port(), b.sensors.size(), b.name,
        setup->sim ? "virtual suit, motion " + setup->motionText : "hub buses",
        wo.recordings.string(), stateDir.string(),
        serve::hasPassword(stateDir) ? "; password set" : "; no password (this machine only)");
    std::fflush(stdout);

    const CaptureStats stats = hub.wait();  // the take and the state files are closed here
    // The web server's workers end with their requests; a client that sends its request a byte
    // at a time would hold the process for as long as it likes (SIGTERM took 38 s). They get a
    // grace period, then the process ends without them: everything it wrote is closed.
    auto stopped = std::make_shared<std::promise<void>>();
    std::future<void> done = stopped->get_future();
    std::thread stopper([w = web->get(), stopped] {
        w->stop();
        stopped->set_value();
    });
    const bool clean = done.wait_for(kWebStopGrace) == std::future_status::ready;
    fmt::print(
        "caphub serve: stopped; {} samples in {:.2f} s, {} dropped, {} sensor losses; "
        "{} poses, latency data-ready -> pose written p50 {:.3f} ms, p99 {:.3f} ms\n",
        stats.samples, toSeconds(stats.elapsed), stats.dropped, stats.lost, hub.body().poses(),
        toSeconds(hub.body().latencyPercentile(0.5)) * 1e3,
        toSeconds(hub.body().latencyPercentile(0.99)) * 1e3);
    if (!clean) {
        fmt::print(stderr,
                   "caphub serve: web clients still connected {:g} s after the stop: ended "
                   "without them\n",
                   std::chrono::duration<double>(kWebStopGrace).count());
        std::fflush(stdout);
        std::fflush(stderr);
        std::_Exit(kExitOk);
    }
    stopper.join();
    return kExitOk;
}

}  // namespace

void addServeCommand(CLI::App& app, int& exitCode) {
    auto o = std::make_shared<ServeOptions>();
    CLI::App* cmd = app.add_subcommand(
        "serve",
        "Run the hub until stopped, operated from a web page and HTTP API (docs/serve.md)");
    cmd->add_option("-b,--board", o->board, "Board file, or the name of a shipped board")
        ->check(nonEmptyPath())
        ->capture_default_str();
    cmd->add_option("--listen", o->listen,
                    "HOST:PORT to serve on; beyond 127.0.0.1 a password must be set first")
        ->capture_default_str();
    cmd->add_option("--recordings", o->recordings,
                    "Folder of the takes (default: the board's outputs)")
        ->check(nonEmptyPath());
    cmd->add_option("--state-dir", o->stateDir,
                    "The hub's state: password hash, calibration.toml (default: "
                    "$CAPHUB_STATE_DIR, /var/lib/caphub, ~/.local/state/caphub)")
        ->check(nonEmptyPath());
    cmd->add_option("--web-root", o->webRoot, "The web page's files (default: the installed ones)")
        ->check(nonEmptyPath());
    cmd->add_flag("--set-password", o->setPassword,
                  "Read a password from stdin, store its hash in the state folder, and exit");
    cmd->add_option("-d,--duration", o->durationS, "Seconds to run (0: until SIGTERM or Ctrl-C)")
        ->check(zeroOrRange(kMinDurationS, kMaxDurationS))
        ->capture_default_str();
    cmd->add_option("--realtime", o->realtime, "SCHED_FIFO priority of the capture threads, 0-99")
        ->check(finiteRange(0, 99));
    cmd->add_option("--sync-ms", o->syncMs, "fdatasync interval of a take, ms")
        ->check(finiteRange(10, 10000))
        ->capture_default_str();
    cmd->add_option("--pose-rate", o->poseRateHz, "Poses per second of the body solver")
        ->check(finiteRange(1.0, 1000.0))
        ->capture_default_str();
    addVirtualSuitOptions(*cmd, o->suit);
    cmd->add_option("--lead-in", o->leadIn,
                    "Virtual suit: the subject first holds this pose (tpose, npose), for a body "
                    "calibration at the start");
    cmd->add_option("--lead-in-s", o->leadInS, "Virtual suit: how long the lead-in pose is held")
        ->check(finiteRange(1.0, 120.0))
        ->capture_default_str();
    cmd->add_option("--calibration", o->calibration,
                    "Sensor calibration file (default: calibration.toml in the state folder, "
                    "when there is one)")
        ->check(nonEmptyPath());
    cmd->add_option("--preview", o->previews,
                    "More preview outputs: png:DIR, fb:/dev/fbN, http:[HOST:]PORT (repeatable)");
    cmd->add_option("--preview-fps", o->previewFps, "Preview frames per second")
        ->check(finitePositive())
        ->capture_default_str();
    cmd->add_flag("--no-preview", o->noPreview, "No preview (the page's 3D view still works)");
    cmd->add_option("--status-file", o->statusFile, "Where to keep the live status")
        ->check(nonEmptyPath());
    cmd->add_option("--http-threads", o->threads, "HTTP worker threads")
        ->check(finiteRange(4, 256))
        ->capture_default_str();
    cmd->add_option("--max-streams", o->maxStreams,
                    "Live streams (events, poses, MJPEG) served at once; the rest get 503")
        ->check(finiteRange(1, 254))
        ->capture_default_str();
    cmd->add_option("--max-downloads", o->maxDownloads,
                    "Downloads (takes, exports) served at once; the rest get 503. Streams and "
                    "downloads together leave at least 2 of the HTTP threads for requests")
        ->check(finiteRange(1, 254))
        ->capture_default_str();
    cmd->callback([&exitCode, o] { exitCode = runServe(*o); });
}

}  // namespace caphub::firmware
