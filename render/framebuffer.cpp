#include "render/framebuffer.h"

#include <algorithm>
#include <cstring>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <fcntl.h>
#include <linux/fb.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <unistd.h>

namespace caphub::render {

namespace {

// A message with each "{}" replaced by the next argument: the sink formats its messages without
// fmt, so that the static kernel-test guest links nothing but the C and C++ libraries.
std::string toText(const std::string& s) {
    return s;
}
template <typename T>
std::string toText(T v) {
    return std::to_string(v);
}

template <typename... Args>
std::string text(std::string_view pattern, const Args&... args) {
    const std::string values[] = {toText(args)..., std::string()};
    std::string out;
    std::size_t next = 0;
    for (std::size_t i = 0; i < pattern.size(); ++i) {
        if (pattern[i] == '{' && i + 1 < pattern.size() && pattern[i + 1] == '}' &&
            next < sizeof...(Args)) {
            out += values[next++];
            ++i;
        } else {
            out += pattern[i];
        }
    }
    return out;
}

}  // namespace

FbMode rgb565Mode(int width, int height) {
    return FbMode{width, height, 16, width * 2, {11, 5}, {5, 6}, {0, 5}};
}

FbMode xrgb8888Mode(int width, int height) {
    return FbMode{width, height, 32, width * 4, {16, 8}, {8, 8}, {0, 8}};
}

Result<void> validateMode(const FbMode& m) {
    if (m.bitsPerPixel != 16 && m.bitsPerPixel != 24 && m.bitsPerPixel != 32) {
        return Error{EINVAL,
                     text("framebuffer depth {} bpp: expected 16, 24 or 32", m.bitsPerPixel)};
    }
    if (m.width <= 0 || m.height <= 0 || m.width > 8192 || m.height > 8192) {
        return Error{EINVAL,
                     text("framebuffer size {}x{}: expected 1 to 8192 each", m.width, m.height)};
    }
    if (m.lineLengthBytes < m.width * m.bitsPerPixel / 8) {
        return Error{EINVAL, text("framebuffer line of {} bytes: expected at least {}",
                                  m.lineLengthBytes, m.width * m.bitsPerPixel / 8)};
    }
    for (const FbChannel* c : {&m.red, &m.green, &m.blue}) {
        if (c->length < 1 || c->length > 8 || c->offset < 0 ||
            c->offset + c->length > m.bitsPerPixel) {
            return Error{EINVAL, text("framebuffer channel at bit {} of {} bits: expected "
                                      "1 to 8 bits inside a {}-bit pixel",
                                      c->offset, c->length, m.bitsPerPixel)};
        }
    }
    return {};
}

std::uint32_t packPixel(const FbMode& m, std::uint8_t r, std::uint8_t g, std::uint8_t b) {
    auto ch = [](std::uint8_t v, const FbChannel& c) {
        return static_cast<std::uint32_t>(v >> (8 - c.length)) << c.offset;
    };
    return ch(r, m.red) | ch(g, m.green) | ch(b, m.blue);
}

void convertFrame(const Image& image, const FbMode& m, std::uint8_t* dst) {
    const int bytes = m.bitsPerPixel / 8;
    // The largest size with the image's aspect that fits the panel, centred.
    int w = m.width;
    int h = image.width > 0
                ? static_cast<int>(static_cast<long>(m.width) * image.height / image.width)
                : 0;
    if (h > m.height) {
        h = m.height;
        w = image.height > 0
                ? static_cast<int>(static_cast<long>(m.height) * image.width / image.height)
                : 0;
    }
    const int x0 = (m.width - w) / 2;
    const int y0 = (m.height - h) / 2;
    std::vector<int> srcX(static_cast<std::size_t>(std::max(w, 0)));
    for (int x = 0; x < w; ++x) {
        srcX[static_cast<std::size_t>(x)] =
            static_cast<int>(static_cast<long>(x) * image.width / w);
    }
    for (int y = 0; y < m.height; ++y) {
        std::uint8_t* line = dst + static_cast<std::size_t>(y) * m.lineLengthBytes;
        std::memset(line, 0, static_cast<std::size_t>(m.width * bytes));
        if (y < y0 || y >= y0 + h) {
            continue;
        }
        const int sy = static_cast<int>(static_cast<long>(y - y0) * image.height / h);
        for (int x = 0; x < w; ++x) {
            const std::uint8_t* s = image.pixel(srcX[static_cast<std::size_t>(x)], sy);
            const std::uint32_t v = packPixel(m, s[0], s[1], s[2]);
            std::memcpy(line + static_cast<std::size_t>(x0 + x) * bytes, &v,
                        static_cast<std::size_t>(bytes));  // little-endian: the low bytes
        }
    }
}

Result<FramebufferSink> FramebufferSink::openDevice(const std::filesystem::path& device,
                                                    int requestBpp) {
    const int fd = ::open(device.c_str(), O_RDWR | O_CLOEXEC);
    if (fd < 0) {
        return errnoError(-errno, text("open framebuffer '{}'", device.string()));
    }
    FramebufferSink sink;
    sink.fd_ = fd;
    sink.name_ = device.string();
    fb_var_screeninfo var{};
    if (ioctl(fd, FBIOGET_VSCREENINFO, &var) != 0) {
        return errnoError(-errno, text("FBIOGET_VSCREENINFO on '{}'", device.string()));
    }
    if (requestBpp != 0 && static_cast<int>(var.bits_per_pixel) != requestBpp) {
        var.bits_per_pixel = static_cast<std::uint32_t>(requestBpp);
        if (ioctl(fd, FBIOPUT_VSCREENINFO, &var) != 0 || ioctl(fd, FBIOGET_VSCREENINFO, &var)) {
            return errnoError(
                -errno, text("FBIOPUT_VSCREENINFO {} bpp on '{}'", requestBpp, device.string()));
        }
    }
    fb_fix_screeninfo fix{};
    if (ioctl(fd, FBIOGET_FSCREENINFO, &fix) != 0) {
        return errnoError(-errno, text("FBIOGET_FSCREENINFO on '{}'", device.string()));
    }
    FbMode m;
    m.width = static_cast<int>(var.xres);
    m.height = static_cast<int>(var.yres);
    m.bitsPerPixel = static_cast<int>(var.bits_per_pixel);
    m.lineLengthBytes = static_cast<int>(fix.line_length);
    m.red = {static_cast<int>(var.red.offset), static_cast<int>(var.red.length)};
    m.green = {static_cast<int>(var.green.offset), static_cast<int>(var.green.length)};
    m.blue = {static_cast<int>(var.blue.offset), static_cast<int>(var.blue.length)};
    if (fix.type != FB_TYPE_PACKED_PIXELS || fix.visual != FB_VISUAL_TRUECOLOR) {
        return Error{EINVAL, text("framebuffer '{}': type {} visual {}: expected packed "
                                  "true-colour pixels",
                                  device.string(), fix.type, fix.visual)};
    }
    if (auto ok = validateMode(m); !ok) {
        return Error{EINVAL, text("framebuffer '{}': {}", device.string(), ok.error().message)};
    }
    // The visible page starts at the y offset the console panned to.
    const std::size_t bytes = static_cast<std::size_t>(fix.smem_len);
    const std::size_t need = static_cast<std::size_t>(var.yoffset + var.yres) * fix.line_length;
    if (bytes < need) {
        return Error{EINVAL, text("framebuffer '{}': {} bytes of memory for {} needed",
                                  device.string(), bytes, need)};
    }
    void* p = mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
    if (p == MAP_FAILED) {
        return errnoError(-errno, text("mmap framebuffer '{}'", device.string()));
    }
    sink.map_ = static_cast<std::uint8_t*>(p);
    sink.mapBytes_ = bytes;
    sink.mode_ = m;
    // Write into the visible page: an offset map view would complicate release(); a pointer
    // offset is enough.
    sink.pageOffset_ = static_cast<std::size_t>(var.yoffset) * fix.line_length;
    return sink;
}

Result<FramebufferSink> FramebufferSink::openFile(const std::filesystem::path& file,
                                                  const FbMode& mode) {
    if (auto ok = validateMode(mode); !ok) {
        return Error{EINVAL, text("framebuffer file '{}': {}", file.string(), ok.error().message)};
    }
    const int fd = ::open(file.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    if (fd < 0) {
        return errnoError(-errno, text("open framebuffer file '{}'", file.string()));
    }
    FramebufferSink sink;
    sink.fd_ = fd;
    sink.name_ = file.string();
    const std::size_t bytes = static_cast<std::size_t>(mode.height) * mode.lineLengthBytes;
    if (ftruncate(fd, static_cast<off_t>(bytes)) != 0) {
        return errnoError(-errno, text("resize framebuffer file '{}'", file.string()));
    }
    void* p = mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
    if (p == MAP_FAILED) {
        return errnoError(-errno, text("mmap framebuffer file '{}'", file.string()));
    }
    sink.map_ = static_cast<std::uint8_t*>(p);
    sink.mapBytes_ = bytes;
    sink.mode_ = mode;
    return sink;
}

FramebufferSink::FramebufferSink(FramebufferSink&& o) noexcept {
    *this = std::move(o);
}

FramebufferSink& FramebufferSink::operator=(FramebufferSink&& o) noexcept {
    if (this != &o) {
        release();
        mode_ = o.mode_;
        name_ = std::move(o.name_);
        fd_ = std::exchange(o.fd_, -1);
        map_ = std::exchange(o.map_, nullptr);
        mapBytes_ = std::exchange(o.mapBytes_, 0);
        pageOffset_ = std::exchange(o.pageOffset_, 0);
    }
    return *this;
}

FramebufferSink::~FramebufferSink() {
    release();
}

void FramebufferSink::release() {
    if (map_) {
        munmap(map_, mapBytes_);
        map_ = nullptr;
    }
    if (fd_ >= 0) {
        ::close(fd_);
        fd_ = -1;
    }
}

Result<void> FramebufferSink::write(const Image& image) {
    if (!map_) {
        return Error{EBADF, text("framebuffer '{}' is not open", name_)};
    }
    if (image.width <= 0 || image.height <= 0 ||
        image.rgb.size() != static_cast<std::size_t>(image.width) * image.height * 3) {
        return Error{EINVAL, text("framebuffer '{}': frame of {}x{} with {} bytes: "
                                  "expected width * height * 3",
                                  name_, image.width, image.height, image.rgb.size())};
    }
    convertFrame(image, mode_, map_ + pageOffset_);
    return {};
}

}  // namespace caphub::render
