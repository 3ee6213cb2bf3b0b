// caphub replay: a recording's poses played back through the preview (the default skin, OSMesa)
// into PNG files, a framebuffer or the MJPEG stream, paced to the recording's time or faster.
#include <chrono>
#include <thread>

#include <fmt/format.h>

#include "firmware/cli/app.h"
#include "firmware/cli/commands.h"
#include "firmware/cli/number_checks.h"
#include "firmware/cli/preview_sinks.h"
#include "firmware/export/pose_track.h"
#include "firmware/recording/reader.h"
#include "fusion/body/kinematics.h"
#include "render/renderer.h"
#include "render/skin_fit.h"
#include "render/skinning.h"

namespace caphub::firmware {

namespace {

struct ReplayOptions {
    std::string recording;
    double speed = 1.0;  // 0: as fast as it renders
    double fps = 10;
    std::vector<std::string> previews;
    std::optional<double> fromS;
    std::optional<double> toS;
    std::string camera = "follow";
};

int replay(const ReplayOptions& o) {
    auto reader = RecordingReader::open(o.recording);
    if (!reader) {
        fmt::print(stderr, "caphub replay: {}\n", reader.error().message);
        return kExitUsage;
    }
    exporter::TrackOptions to;
    to.fromS = o.fromS;
    to.toS = o.toS;
    to.rateHz = o.fps;
    auto track = exporter::readPoseTrack(**reader, to);
    if (!track) {
        fmt::print(stderr, "caphub replay: {}: {}\n", o.recording, track.error().message);
        return kExitUsage;
    }
    if (o.previews.empty()) {
        fmt::print(stderr, "caphub replay: give --preview png:DIR, fb:/dev/fbN or http:PORT\n");
        return kExitUsage;
    }
    for (const auto& spec : o.previews) {
        if (auto p = parsePreviewSpec(spec); !p) {
            fmt::print(stderr, "caphub replay: --{}\n", p.error().message);
            return kExitUsage;
        }
    }
    render::SinkSet sinks = openPreviewSinks(o.previews);
    for (const auto& f : sinks.failures()) {
        fmt::print(stderr, "caphub replay: preview {}\n", f);
    }
    if (sinks.liveCount() == 0) {
        return kExitRuntime;
    }
    auto defaultSkin = render::loadDefaultSkin();
    if (!defaultSkin) {
        fmt::print(stderr, "caphub replay: {}\n", defaultSkin.error().message);
        return kExitRuntime;
    }
    // The recording's subject (the dimensions its poses were solved with).
    auto skin = render::fitSkinToSubject(*defaultSkin, track->subject);
    if (!skin) {
        fmt::print(stderr, "caphub replay: {}\n", skin.error().message);
        return kExitRuntime;
    }
    render::RenderOptions ro;
    const auto preset = render::parseCameraPreset(o.camera);
    if (!preset) {
        fmt::print(stderr, "caphub replay: --camera: expected front, side, orbit or follow\n");
        return kExitUsage;
    }
    ro.camera = *preset;
    auto renderer = render::Renderer::create(*skin, ro);
    if (!renderer) {
        fmt::print(stderr, "caphub replay: {}\n", renderer.error().message);
        return kExitRuntime;
    }
    fmt::print("caphub replay: {} ({} frames, {:.2f} s at {:g} Hz), speed {:g}\n", o.recording,
               track->frames.size(), track->recordingDurationS, track->rateHz, o.speed);

    render::Skinner skinner(*skin);
    render::Image image;
    body::Pose pose;
    const auto start = std::chrono::steady_clock::now();
    const double t0 = track->frames.front().tS;
    std::uint64_t index = 0;
    for (const auto& f : track->frames) {
        if (o.speed > 0) {
            std::this_thread::sleep_until(
                start + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                            std::chrono::duration<double>((f.tS - t0) / o.speed)));
        }
        pose.qLocal = f.qLocal;
        body::worldFromLocal(pose);
        render::SkinPose sp;
        sp.qWorld = pose.qWorld;
        sp.pelvisM = f.rootM;
        skinner.setPose(sp);
        skinner.skin();
        render::FrameInput in;
        in.vertices = skinner.output();
        in.jointsM = skinner.jointPositionsM();
        in.timeS = f.tS - t0;
        if (auto ok = (*renderer)->render(in, image); !ok) {
            fmt::print(stderr, "caphub replay: {}\n", ok.error().message);
            return kExitRuntime;
        }
        sinks.write(image, index++);
        if (sinks.liveCount() == 0) {
            fmt::print(stderr, "caphub replay: every preview output failed\n");
            return kExitRuntime;
        }
    }
    const double wallS =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    fmt::print("{} frames in {:.2f} s{}\n", index, wallS,
               track->damagedBytes > 0
                   ? fmt::format(" ({} damaged bytes skipped)", track->damagedBytes)
                   : "");
    return kExitOk;
}

}  // namespace

void addReplayCommand(CLI::App& app, int& exitCode) {
    auto o = std::make_shared<ReplayOptions>();
    CLI::App* cmd = app.add_subcommand(
        "replay", "Play a recording's poses back through the preview (PNG, framebuffer, MJPEG)");
    cmd->add_option("recording", o->recording, "The recording (.cap)")->required();
    cmd->add_option("--speed", o->speed, "Recording seconds per real second (0: no pacing)")
        ->check(zeroOrRange(1e-3, 1e6))
        ->capture_default_str();
    // Bounded as an export's --rate (the frames are read at it): 1e308 was refused in that
    // option's words ("--rate 1e+308").
    cmd->add_option("--fps", o->fps, "Frames per second of recording time")
        ->check(finiteRange(1e-3, 10000))
        ->capture_default_str();
    cmd->add_option("--preview", o->previews, "png:DIR, fb:/dev/fbN or http:[HOST:]PORT")
        ->required();
    cmd->add_option("--from", o->fromS, "Start, seconds from the first pose");
    cmd->add_option("--to", o->toS, "End, seconds from the first pose");
    cmd->add_option("--camera", o->camera, "front, side, orbit or follow")->capture_default_str();
    cmd->callback([&exitCode, o] { exitCode = replay(*o); });
}

}  // namespace caphub::firmware
