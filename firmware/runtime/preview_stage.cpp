#include "firmware/runtime/preview_stage.h"

#include "firmware/runtime/thread_policy.h"
#include "hal/core/log.h"
#include "render/skin_fit.h"
#include "render/skinning.h"

namespace caphub::firmware {

PreviewStage::PreviewStage(const board::Board& board, const PoseFeed& poses, render::Skin skin,
                           render::SinkSet sinks, const Options& options)
    : poses_(poses),
      skin_(std::move(skin)),
      sinks_(std::move(sinks)),
      options_(options),
      period_(periodFromHz(options.fps)) {
    // The skin is fitted to the board's subject, so that its joints sit on the body's skeleton;
    // a subject the body stage cannot use makes it fall back to the default subject, and so
    // does this.
    auto fitted = render::fitSkinToSubject(skin_, board.subject);
    if (!fitted) {
        log::logger(log::Category::Render)
            .warn("preview skin fitted to the default subject: {}", fitted.error().message);
        fitted = render::fitSkinToSubject(skin_, board::SubjectConfig{});
    }
    if (fitted) {
        skin_ = std::move(*fitted);
    } else {
        log::logger(log::Category::Render)
            .warn("preview skin left unfitted: {}", fitted.error().message);
    }
    sensors_.fill(render::SensorState::None);
    for (const auto& s : board.sensors) {
        segmentOf_.push_back(static_cast<int>(s.segment));
        sensors_[static_cast<std::size_t>(s.segment)] = render::SensorState::Uncalibrated;
    }
    thread_ = std::thread([this] { renderLoop(); });
}

PreviewStage::~PreviewStage() {
    finish(Timestamp{});
}

void PreviewStage::onSample(const SensorSample& s) {
    const Timestamp t = s.sample.t;
    if (!first_) {
        first_ = t;
        next_ = t;
    }
    if (t < next_ || poses_.published() == lastPoses_) {
        return;
    }
    next_ = t + period_;
    // Never wait for the renderer: if it holds the slot, this frame is skipped.
    std::unique_lock lock(mutex_, std::try_to_lock);
    if (!lock.owns_lock()) {
        skipped_.fetch_add(1, std::memory_order_relaxed);
        return;
    }
    lastPoses_ = poses_.latest(pose_);
    for (std::size_t i = 0; i < slot_.pose.qWorld.size(); ++i) {
        slot_.pose.qWorld[i] = pose_.world[i].cast<double>();
    }
    slot_.pose.pelvisM = pose_.rootM.cast<double>();
    for (std::size_t i = 0; i < sensors_.size(); ++i) {
        // A segment the pose did not measure (its sensor out) is drawn as lost, whatever the
        // events said last.
        const bool measured = (pose_.notMeasured >> i & 1u) == 0;
        slot_.sensors[i] =
            !measured && sensors_[i] != render::SensorState::None ? render::SensorState::Lost
            : sensors_[i] == render::SensorState::Uncalibrated && pose_.bodyCalibrated
                ? render::SensorState::Ok
                : sensors_[i];
    }
    slot_.timeS = toSeconds(t - *first_);
    ++slot_.serial;
    lock.unlock();
    wake_.notify_one();
}

void PreviewStage::onEvent(const RuntimeEvent& e) {
    if (e.sensor < 0 || static_cast<std::size_t>(e.sensor) >= segmentOf_.size()) {
        return;
    }
    auto& state =
        sensors_[static_cast<std::size_t>(segmentOf_[static_cast<std::size_t>(e.sensor)])];
    if (e.kind == RuntimeEvent::Kind::SensorLost || e.kind == RuntimeEvent::Kind::LineSilent) {
        state = render::SensorState::Lost;
    } else if (e.kind == RuntimeEvent::Kind::SensorOnline) {
        state = render::SensorState::Uncalibrated;  // Ok once the body is calibrated
    }
}

void PreviewStage::finish(Timestamp) {
    {
        std::lock_guard lock(mutex_);
        stop_ = true;
    }
    wake_.notify_one();
    if (thread_.joinable()) {
        thread_.join();
    }
}

std::string PreviewStage::error() const {
    std::lock_guard lock(mutex_);
    return error_;
}

void PreviewStage::renderLoop() {
    // Named, on the normal scheduler: rendering is what the capture threads preempt.
    (void)applyToThisThread(ThreadPolicy{}, "caphub-preview");
    // The OSMesa context belongs to the thread that makes it current: this one.
    auto renderer = render::Renderer::create(skin_, options_.render);
    if (!renderer) {
        std::lock_guard lock(mutex_);
        error_ = renderer.error().message;
        log::logger(log::Category::Render).error("preview off: {}", error_);
        return;
    }
    render::Skinner skinner(skin_);
    render::Image image;
    std::uint64_t shown = 0;
    Frame frame;
    while (true) {
        {
            std::unique_lock lock(mutex_);
            wake_.wait(lock, [&] { return stop_ || slot_.serial != shown; });
            if (slot_.serial == shown) {
                return;  // stopping, and the last pose is drawn
            }
            // Frames handed over while the last one was drawn were replaced: skipped. When
            // stopping, the latest is still drawn, so that the last frame shows the last pose.
            skipped_.fetch_add(slot_.serial - shown - 1, std::memory_order_relaxed);
            frame = slot_;
            shown = slot_.serial;
        }
        skinner.setPose(frame.pose);
        skinner.skin();
        render::FrameInput in;
        in.vertices = skinner.output();
        in.jointsM = skinner.jointPositionsM();
        in.sensors = frame.sensors;
        in.timeS = frame.timeS;
        if (auto ok = (*renderer)->render(in, image); !ok) {
            std::lock_guard lock(mutex_);
            error_ = ok.error().message;
            log::logger(log::Category::Render).error("preview stopped: {}", error_);
            return;
        }
        sinks_.write(image, rendered_.fetch_add(1));
    }
}

}  // namespace caphub::firmware
