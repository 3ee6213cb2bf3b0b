#include "firmware/cli/capture_setup.h"

#include <atomic>
#include <csignal>

#include <fmt/format.h>

#include "firmware/calibration_file.h"
#include "firmware/cli/data_dir.h"
#include "firmware/cli/number_checks.h"
#include "hal/core/log.h"
#include "render/skin.h"

namespace caphub::firmware {

namespace {

namespace fs = std::filesystem;

std::atomic<Capture*> gCapture{nullptr};
std::atomic<bool> gStopSignalled{false};

extern "C" void onStopSignal(int) {
    gStopSignalled.store(true);
    if (Capture* c = gCapture.load()) {
        c->requestStop();
    }
}

}  // namespace

void addVirtualSuitOptions(CLI::App& cmd, CaptureSetupOptions& o) {
    // 1e300 overflowed the simulated clock: its workers spun with no sample taken.
    cmd.add_option("--speed", o.speed, "Virtual suit only: simulated seconds per real second")
        ->check(finiteRange(1e-3, 1e6))
        ->capture_default_str();
    cmd.add_option("--bvh", o.bvh,
                   "Virtual suit: the motion (BVH); default: the shipped walking clip")
        ->check(nonEmptyPath());
    cmd.add_option("--map", o.map, "Virtual suit: joint-name map (TOML) for the BVH file")
        ->check(nonEmptyPath());
    cmd.add_option("--profile", o.profile, "Virtual suit: sensor errors: ideal, typical, harsh")
        ->capture_default_str();
    cmd.add_option("--seed", o.seed, "Virtual suit: seed of the sensor errors")
        ->check(seedNumber())
        ->capture_default_str();
    cmd.add_flag("--rest", o.rest, "Virtual suit: stand still instead of playing a clip");
}

Result<CaptureSetup> buildCaptureSetup(const board::Board& b, const CaptureSetupOptions& o) {
    CaptureSetup s;
    s.sim = board::allBusesSimulated(b);
    if (!o.calibration.empty()) {
        auto set = readCalibrationFile(o.calibration);
        if (!set) {
            return Error{EINVAL, set.error().message};
        }
        std::vector<std::string> unknown;
        s.calibrations = calibrationsFor(b, *set, &unknown);
        for (const auto& name : unknown) {
            log::logger(log::Category::Firmware)
                .warn("{}: sensor '{}' is not on board '{}'; its calibration is unused",
                      o.calibration, name, b.name);
        }
        s.calibrationText = formatCalibration(*set);
    }
    s.boardText = b.text;
    // The virtual suit's paced clock is made once its clip is loaded (seconds in a debug or
    // sanitizer build), starting where the clip starts: made before, it ran on through the
    // loading and the capture began that long, times the speed, into the motion.
    const Timestamp simStart = MonotonicClock().now();
    board::sim::SourceFactory sources;
    if (s.sim && !o.rest) {
        board::sim::ClipOptions clip;
        clip.bvh = o.bvh.empty() ? defaultMotionClip() : fs::path(o.bvh);
        clip.map = o.map;
        clip.seed = o.seed;
        if (o.leadInPose) {
            // The virtual subject first stands in the calibration pose.
            clip.tposeHoldS = o.holdS;
            clip.leadInPose = body::referencePose(*o.leadInPose);
        }
        const auto profile = board::sim::parseErrorProfile(o.profile);
        if (!profile) {
            return Error{EINVAL,
                         fmt::format("unknown profile '{}' (ideal, typical or harsh)", o.profile)};
        }
        clip.profile = *profile;
        if (clip.bvh.empty()) {
            log::logger(log::Category::Sim)
                .warn("no motion clip found (give --bvh FILE): the virtual suit stands still");
        } else {
            auto suitMotion = board::sim::clipSources(clip, simStart);
            if (!suitMotion) {
                return Error{EINVAL, suitMotion.error().message};
            }
            sources = suitMotion->sources;
            s.placementOf = suitMotion->placement;
            s.motionText = fmt::format("{} ({:.1f} s, {} profile)", clip.bvh.filename().string(),
                                       static_cast<double>(suitMotion->motion->durationNs()) * 1e-9,
                                       o.profile);
        }
    }
    if (s.sim) {
        s.clock = std::make_unique<SimulatedClock>(simStart, o.speed);
    } else {
        s.clock = std::make_unique<MonotonicClock>();
    }
    if (s.sim && o.wrapSources) {
        sources = o.wrapSources(std::move(sources));
    }
    auto suit = s.sim ? board::sim::buildVirtualSuit(b, *s.clock, sources)
                      : board::openLinuxSuit(b, *s.clock);
    if (!suit) {
        return Error{suit.error().code == EINVAL ? EIO : suit.error().code, suit.error().message};
    }
    s.suit.emplace(std::move(*suit));
    return s;
}

void attachPreview(HubOptions& ho, render::SinkSet sinks, double fps, std::string_view command) {
    for (const auto& f : sinks.failures()) {
        fmt::print(stderr, "{}: preview {}\n", command, f);
    }
    if (sinks.liveCount() == 0) {
        return;
    }
    auto skin = render::loadDefaultSkin();
    if (!skin) {
        fmt::print(stderr, "{}: preview off: {}\n", command, skin.error().message);
        return;
    }
    ho.previewSkin = std::move(*skin);
    ho.previewSinks = std::move(sinks);
    ho.preview.fps = fps;
}

StopSignals::StopSignals() {
    for (std::size_t i = 0; i < kStopping.size(); ++i) {
        (void)::sigaction(kStopping[i], nullptr, &previous_[i]);
        // A terminal's hang-up ignored at the start (nohup) stays ignored.
        if (kStopping[i] == SIGHUP && previous_[i].sa_handler == SIG_IGN) {
            continue;
        }
        struct sigaction sa {};
        sa.sa_handler = onStopSignal;
        sigemptyset(&sa.sa_mask);
        (void)::sigaction(kStopping[i], &sa, nullptr);
    }
}

StopSignals::~StopSignals() {
    for (std::size_t i = 0; i < kStopping.size(); ++i) {
        (void)::sigaction(kStopping[i], &previous_[i], nullptr);
    }
    gCapture.store(nullptr);
}

void StopSignals::arm(Capture& capture) {
    gCapture.store(&capture);
    if (gStopSignalled.load()) {
        capture.requestStop();  // signalled while the hub was being built: stop at once
    }
}

bool StopSignals::signalled() {
    return gStopSignalled.load();
}

}  // namespace caphub::firmware
