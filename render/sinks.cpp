#include "render/sinks.h"

#include <fmt/format.h>

#include "hal/core/log.h"

namespace caphub::render {

namespace {

class PngFolderSink final : public FrameSink {
public:
    explicit PngFolderSink(std::filesystem::path folder) : folder_(std::move(folder)) {}
    std::string name() const override { return fmt::format("png folder '{}'", folder_.string()); }
    Result<void> write(const Image& image, std::uint64_t frameIndex) override {
        if (!created_) {
            std::error_code ec;
            std::filesystem::create_directories(folder_, ec);
            if (ec) {
                return Error{ec.value(),
                             fmt::format("create '{}': {}", folder_.string(), ec.message())};
            }
            created_ = true;
        }
        return writePng(image, folder_ / fmt::format("frame_{:06d}.png", frameIndex));
    }

private:
    std::filesystem::path folder_;
    bool created_ = false;
};

class FbFrameSink final : public FrameSink {
public:
    explicit FbFrameSink(FramebufferSink fb) : fb_(std::move(fb)) {}
    std::string name() const override { return fmt::format("framebuffer '{}'", fb_.name()); }
    Result<void> write(const Image& image, std::uint64_t) override { return fb_.write(image); }

private:
    FramebufferSink fb_;
};

class MjpegFrameSink final : public FrameSink {
public:
    explicit MjpegFrameSink(std::unique_ptr<MjpegServer> s) : server_(std::move(s)) {}
    std::string name() const override {
        return fmt::format("MJPEG stream on port {}", server_->port());
    }
    Result<void> write(const Image& image, std::uint64_t) override {
        return server_->publish(image);
    }

private:
    std::unique_ptr<MjpegServer> server_;
};

class JpegSlotSink final : public FrameSink {
public:
    explicit JpegSlotSink(std::shared_ptr<JpegFrameSlot> slot) : slot_(std::move(slot)) {}
    std::string name() const override { return "the web page's preview"; }
    Result<void> write(const Image& image, std::uint64_t) override { return slot_->publish(image); }

private:
    std::shared_ptr<JpegFrameSlot> slot_;
};

}  // namespace

std::unique_ptr<FrameSink> makePngFolderSink(const std::filesystem::path& folder) {
    return std::make_unique<PngFolderSink>(folder);
}

std::unique_ptr<FrameSink> makeFramebufferSink(FramebufferSink fb) {
    return std::make_unique<FbFrameSink>(std::move(fb));
}

std::unique_ptr<FrameSink> makeMjpegSink(std::unique_ptr<MjpegServer> server) {
    return std::make_unique<MjpegFrameSink>(std::move(server));
}

std::unique_ptr<FrameSink> makeJpegSlotSink(std::shared_ptr<JpegFrameSlot> slot) {
    return std::make_unique<JpegSlotSink>(std::move(slot));
}

void SinkSet::addFailure(const std::string& what, const Error& error) {
    failures_.push_back(fmt::format("{}: {}", what, error.message));
    log::logger(log::Category::Render)
        .warn("preview sink {} unavailable: {}; going on without it", what, error.message);
}

void SinkSet::write(const Image& image, std::uint64_t frameIndex) {
    for (auto it = sinks_.begin(); it != sinks_.end();) {
        auto ok = (*it)->write(image, frameIndex);
        if (ok) {
            ++it;
            continue;
        }
        failures_.push_back(fmt::format("{}: {}", (*it)->name(), ok.error().message));
        log::logger(log::Category::Render)
            .warn("preview sink {} failed at frame {}: {}; dropped, capture goes on", (*it)->name(),
                  frameIndex, ok.error().message);
        it = sinks_.erase(it);
    }
}

}  // namespace caphub::render
