// The preview renderer: OSMesa (Mesa's llvmpipe, no GPU or display) with a GL 3.3 core context;
// draws the lit skin, a floor grid, the skeleton and each sensor's state into an RGB Image.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string_view>

#include "hal/core/error.h"
#include "hal/core/quaternion.h"
#include "render/image.h"
#include "render/skin.h"
#include "render/skinning.h"

namespace caphub::render {

// What the preview shows for the sensor on a segment.
enum class SensorState : std::uint8_t {
    None,          // no sensor on this segment: nothing drawn
    Ok,            // green
    Lost,          // red: no data
    Uncalibrated,  // yellow
};

// Every preset follows the subject: it looks at the pelvis from far enough that the whole body
// (a sphere around the pelvis as large as the skin's reach, whatever the pose) fills the frame,
// wherever the subject has walked.
enum class CameraPreset : std::uint8_t {
    Front,   // from the front of the capture area (+Z)
    Side,    // from its side (+X)
    Orbit,   // circling the subject, one turn in 20 s
    Follow,  // front-left, three-quarter view
};

// "front", "side", "orbit" or "follow"; nothing for another name.
std::optional<CameraPreset> parseCameraPreset(std::string_view name);

struct RenderOptions {
    int width = 320;
    int height = 240;
    CameraPreset camera = CameraPreset::Front;
    bool drawGrid = true;
    bool drawSkeleton = true;
    bool drawSensors = true;
};

// Wall time of each stage of the last frame, nanoseconds (the benchmark's breakdown).
struct StageTimes {
    std::int64_t uploadNs = 0;    // vertices into the GL buffer
    std::int64_t drawNs = 0;      // clear, draw calls and glFinish (llvmpipe rasterises here)
    std::int64_t readbackNs = 0;  // the OSMesa buffer into the RGB image (flip, drop alpha)
};

// The state of one frame to draw.
struct FrameInput {
    std::span<const SkinnedVertex> vertices;           // skinned, as Skinner::output()
    std::array<Vec3d, kSegmentCount> jointsM;          // segment origins (Skinner::jointPositionsM)
    std::array<SensorState, kSegmentCount> sensors{};  // all None: no markers
    double timeS = 0;                                  // drives the orbit camera
};

class Renderer {
public:
    // Makes the OSMesa context (GL 3.3 core), compiles the shaders and uploads the skin's
    // triangles. Fails with the reason when OSMesa or the profile is unavailable.
    static Result<std::unique_ptr<Renderer>> create(const Skin& skin, const RenderOptions& options);
    ~Renderer();
    Renderer(const Renderer&) = delete;
    Renderer& operator=(const Renderer&) = delete;

    void setCamera(CameraPreset camera) { options_.camera = camera; }
    const RenderOptions& options() const { return options_; }

    // Draws one frame into `out` (resized to the options' size). `times` may be null.
    Result<void> render(const FrameInput& frame, Image& out, StageTimes* times = nullptr);

private:
    Renderer() = default;
    struct Gl;
    std::unique_ptr<Gl> gl_;
    RenderOptions options_;
    std::size_t vertexCount_ = 0;
    // The radius around the pelvis that holds the whole body in any pose: the skin's farthest
    // joint from the pelvis in its reference (T) pose, and a margin for the hands and head.
    double framingRadiusM_ = 1.1;
};

}  // namespace caphub::render
