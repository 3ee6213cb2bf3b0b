// caphub-render-preview: renders the default skin (or a .mesh / glTF skin) in a pose taken from a
// BVH clip at a given time, or in the reference pose, into a PNG (docs/preview-walk.png).
#include <cstdio>
#include <string>

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include "board/sim/bvh.h"
#include "board/sim/joint_map.h"
#include "board/sim/motion.h"
#include "render/image.h"
#include "render/renderer.h"
#include "render/skin.h"
#include "render/skinning.h"

namespace {

using namespace caphub;

int fail(const Error& e) {
    std::fprintf(stderr, "caphub-render-preview: %s\n", e.message.c_str());
    return 1;
}

}  // namespace

int main(int argc, char** argv) {
    CLI::App app{"Render caphub's preview of a skin in a BVH pose to a PNG"};
    std::string mesh, bvh, out = "preview.png", camera = "front";
    double timeS = 0;
    int width = 640, height = 480;
    bool sensors = true;
    app.add_option("--mesh", mesh, "a .mesh skin (default: the shipped default skin)");
    app.add_option("--bvh", bvh, "a BVH clip (CMU naming) for the pose; none: reference pose");
    app.add_option("--time", timeS, "time in the clip, s")->capture_default_str();
    app.add_option("--camera", camera, "front, side, orbit or follow")->capture_default_str();
    app.add_option("--width", width)->capture_default_str();
    app.add_option("--height", height)->capture_default_str();
    app.add_flag("!--no-sensors", sensors, "do not draw the sensor markers");
    app.add_option("-o,--output", out, "PNG to write")->capture_default_str();
    CLI11_PARSE(app, argc, argv);

    auto skin = mesh.empty() ? render::loadDefaultSkin() : render::loadSkin(mesh);
    if (!skin) {
        return fail(skin.error());
    }
    render::SkinPose pose;
    pose.pelvisM =
        Vec3d(skin->jointOriginsM[0][0], skin->jointOriginsM[0][1], skin->jointOriginsM[0][2]);
    if (!bvh.empty()) {
        auto clip = board::sim::loadBvh(bvh);
        if (!clip) {
            return fail(clip.error());
        }
        const auto* map = board::sim::detectJointMap(*clip);
        if (!map) {
            return fail(
                Error{EINVAL, fmt::format("{}: no built-in joint map fits its joints", bvh)});
        }
        board::sim::MotionOptions opt;
        opt.reference = board::sim::ReferencePose{board::sim::ReferencePose::Kind::TPose, 0};
        auto motion = board::sim::Motion::fromClip(*clip, *map, opt);
        if (!motion) {
            return fail(motion.error());
        }
        board::sim::SuitState state;
        motion->evaluateAll(static_cast<std::int64_t>(timeS * 1e9), state);
        for (int s = 0; s < render::kSegmentCount; ++s) {
            pose.qWorld[static_cast<std::size_t>(s)] =
                state[static_cast<std::size_t>(s)].qWorldSegment;
        }
        // Keep the skin's own pelvis height; move it over the floor as the clip does.
        pose.pelvisM.x() = state[0].positionM.x();
        pose.pelvisM.z() = state[0].positionM.z();
    }
    render::RenderOptions ro;
    ro.width = width;
    ro.height = height;
    const auto preset = render::parseCameraPreset(camera);
    if (!preset) {
        return fail(Error{
            EINVAL, fmt::format("--camera {}: expected front, side, orbit or follow", camera)});
    }
    ro.camera = *preset;
    render::Skinner skinner(*skin);
    skinner.setPose(pose);
    skinner.skin();
    auto renderer = render::Renderer::create(*skin, ro);
    if (!renderer) {
        return fail(renderer.error());
    }
    render::FrameInput frame;
    frame.vertices = skinner.output();
    frame.jointsM = skinner.jointPositionsM();
    frame.timeS = timeS;
    if (sensors) {
        // The full suit's sensors, one of each state on show: the left forearm's lost, the right
        // shank's uncalibrated.
        for (auto s : {board::Segment::Pelvis, board::Segment::T12, board::Segment::Skull,
                       board::Segment::LUpperarm, board::Segment::LForearm,
                       board::Segment::RUpperarm, board::Segment::RForearm, board::Segment::LThigh,
                       board::Segment::LCalf, board::Segment::RThigh, board::Segment::RCalf,
                       board::Segment::LHindfoot, board::Segment::RHindfoot}) {
            frame.sensors[static_cast<std::size_t>(s)] = render::SensorState::Ok;
        }
        frame.sensors[static_cast<std::size_t>(board::Segment::LForearm)] =
            render::SensorState::Lost;
        frame.sensors[static_cast<std::size_t>(board::Segment::RCalf)] =
            render::SensorState::Uncalibrated;
    }
    render::Image image;
    if (auto ok = (*renderer)->render(frame, image); !ok) {
        return fail(ok.error());
    }
    if (auto ok = render::writePng(image, out); !ok) {
        return fail(ok.error());
    }
    std::printf("%s: %dx%d\n", out.c_str(), image.width, image.height);
    return 0;
}
