// The Linux framebuffer sink (/dev/fbN, e.g. a small SPI TFT): the panel's mode from the kernel,
// frames scaled to the panel and packed to its pixel format (RGB565, XRGB8888, ...) in the mmap.
// Depends on nothing but the C library, so that a static test program can use it.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>

#include "hal/core/error.h"
#include "render/image.h"

namespace caphub::render {

// One colour channel of a packed pixel: its lowest bit and its width.
struct FbChannel {
    int offset = 0;
    int length = 0;
};

// What FBIOGET_VSCREENINFO and FBIOGET_FSCREENINFO say about a panel, or what a test gives.
struct FbMode {
    int width = 0;
    int height = 0;
    int bitsPerPixel = 0;  // 16, 24 or 32
    int lineLengthBytes = 0;
    FbChannel red, green, blue;
};
// The two formats of small panels and HDMI consoles.
FbMode rgb565Mode(int width, int height);
FbMode xrgb8888Mode(int width, int height);

// Checks that the mode can be written: 16, 24 or 32 bits per pixel, channels of 1-8 bits inside
// the pixel, a line long enough for the width.
Result<void> validateMode(const FbMode& mode);

// Scales `image` to the panel keeping its aspect (nearest neighbour, black bars) and packs it
// into `dst`, which holds mode.height lines of mode.lineLengthBytes.
void convertFrame(const Image& image, const FbMode& mode, std::uint8_t* dst);

// Packs one colour as the mode stores it (host byte order).
std::uint32_t packPixel(const FbMode& mode, std::uint8_t r, std::uint8_t g, std::uint8_t b);

class FramebufferSink {
public:
    // A framebuffer device: the mode is read from the kernel. If requestBpp is not 0 and differs
    // from the current depth, FBIOPUT_VSCREENINFO asks for it first (vfb starts at 8 bpp).
    static Result<FramebufferSink> openDevice(const std::filesystem::path& device,
                                              int requestBpp = 0);
    // A regular file standing in for a framebuffer, with the mode given: created or resized to
    // mode.height * mode.lineLengthBytes bytes.
    static Result<FramebufferSink> openFile(const std::filesystem::path& file, const FbMode& mode);

    FramebufferSink(FramebufferSink&& other) noexcept;
    FramebufferSink& operator=(FramebufferSink&& other) noexcept;
    FramebufferSink(const FramebufferSink&) = delete;
    FramebufferSink& operator=(const FramebufferSink&) = delete;
    ~FramebufferSink();

    const FbMode& mode() const { return mode_; }
    const std::string& name() const { return name_; }
    Result<void> write(const Image& image);

private:
    FramebufferSink() = default;
    void release();

    FbMode mode_;
    std::string name_;
    int fd_ = -1;
    std::uint8_t* map_ = nullptr;
    std::size_t mapBytes_ = 0;
    std::size_t pageOffset_ = 0;  // the visible page's first byte in the map
};

}  // namespace caphub::render
