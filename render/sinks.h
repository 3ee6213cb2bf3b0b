// Where preview frames go: PNG files in a folder, a Linux framebuffer, the MJPEG stream. A
// SinkSet feeds several; a sink that fails is reported once and dropped, and capture goes on.
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "hal/core/error.h"
#include "render/framebuffer.h"
#include "render/image.h"
#include "render/mjpeg_server.h"

namespace caphub::render {

class FrameSink {
public:
    virtual ~FrameSink() = default;
    virtual std::string name() const = 0;
    virtual Result<void> write(const Image& image, std::uint64_t frameIndex) = 0;
};

// frame_000000.png, frame_000001.png, ... in a folder (created if missing).
std::unique_ptr<FrameSink> makePngFolderSink(const std::filesystem::path& folder);
std::unique_ptr<FrameSink> makeFramebufferSink(FramebufferSink fb);
std::unique_ptr<FrameSink> makeMjpegSink(std::unique_ptr<MjpegServer> server);
// Into a slot another server reads (`caphub serve`'s /preview.mjpeg).
std::unique_ptr<FrameSink> makeJpegSlotSink(std::shared_ptr<JpegFrameSlot> slot);

class SinkSet {
public:
    void add(std::unique_ptr<FrameSink> sink) { sinks_.push_back(std::move(sink)); }
    // Records a sink that could not be opened: reported, and capture goes on without it.
    void addFailure(const std::string& what, const Error& error);
    // Writes to every live sink; one that fails is logged with the reason and dropped.
    void write(const Image& image, std::uint64_t frameIndex);
    std::size_t liveCount() const { return sinks_.size(); }
    const std::vector<std::string>& failures() const { return failures_; }

private:
    std::vector<std::unique_ptr<FrameSink>> sinks_;
    std::vector<std::string> failures_;
};

}  // namespace caphub::render
