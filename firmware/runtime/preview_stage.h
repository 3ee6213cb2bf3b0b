// The preview: a thread of its own renders the body's latest pose (skinned default mesh, OSMesa)
// a few times a second into the sinks (PNG folder, framebuffer, MJPEG stream). The pipeline only
// hands over the latest pose through a slot it never waits for, so rendering never stalls
// sampling; frames the renderer cannot keep up with are skipped, not queued. At the end the
// latest pose handed over is drawn before the thread stops.
#pragma once

#include <array>
#include <atomic>
#include <condition_variable>
#include <memory>
#include <mutex>
#include <thread>

#include "board/board.h"
#include "firmware/runtime/capture.h"
#include "firmware/runtime/pose_feed.h"
#include "render/renderer.h"
#include "render/sinks.h"
#include "render/skin.h"

namespace caphub::firmware {

class PreviewStage final : public PipelineStage {
public:
    struct Options {
        double fps = 10;  // frames per second of capture-clock time
        render::RenderOptions render;
    };

    // Draws the poses published to `poses` (the body stage's feed; the body stage must be added
    // to the capture before this stage). The skin is fitted to board.subject
    // (render/skin_fit.h).
    PreviewStage(const board::Board& board, const PoseFeed& poses, render::Skin skin,
                 render::SinkSet sinks, const Options& options);
    ~PreviewStage() override;

    void onSample(const SensorSample& s) override;
    void onEvent(const RuntimeEvent& e) override;
    void finish(Timestamp now) override;

    std::uint64_t framesRendered() const { return rendered_.load(); }
    // Frames not drawn: replaced by a newer one while the renderer was busy.
    std::uint64_t framesSkipped() const { return skipped_.load(); }
    // Why the renderer could not start (empty when it did).
    std::string error() const;

private:
    struct Frame {
        render::SkinPose pose;
        std::array<render::SensorState, render::kSegmentCount> sensors{};
        double timeS = 0;
        std::uint64_t serial = 0;
    };

    void renderLoop();

    const PoseFeed& poses_;
    PoseFrame pose_;  // the latest taken from the feed
    render::Skin skin_;
    render::SinkSet sinks_;
    Options options_;
    Duration period_;
    std::array<render::SensorState, render::kSegmentCount> sensors_{};
    std::vector<int> segmentOf_;  // board sensor -> segment
    std::optional<Timestamp> first_;
    Timestamp next_{};
    std::uint64_t lastPoses_ = 0;

    mutable std::mutex mutex_;  // guards slot_, stop_, error_; the pipeline only try-locks it
    std::condition_variable wake_;
    Frame slot_;
    bool stop_ = false;
    std::string error_;
    std::atomic<std::uint64_t> rendered_{0};
    std::atomic<std::uint64_t> skipped_{0};
    std::thread thread_;
};

}  // namespace caphub::firmware
