// The framebuffer section of the kernel-level guest: the render library's FramebufferSink on a
// real kernel's fbdev (vfb). The sink reads the mode with FBIOGET_VSCREENINFO/FSCREENINFO, asks
// for 16 and then 32 bits per pixel, scales and packs a frame into its mmap; this file reads the
// device back through read() (the kernel's copy path, not the sink's mapping) and through a
// second mapping, and compares every pixel with a value computed here from the bitfields the
// kernel reports and the nearest-neighbour rule of render/framebuffer.h.

#include "tests/kernel/guest_fb_checks.h"

#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include <fcntl.h>
#include <linux/fb.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <unistd.h>

#include "render/framebuffer.h"
#include "render/image.h"

namespace caphub::kernel_test {

namespace {

using render::FramebufferSink;
using render::Image;

std::string num(long v) {
    return std::to_string(v);
}

std::string hex(std::uint32_t v) {
    char buf[16];
    std::snprintf(buf, sizeof buf, "0x%08X", v);
    return buf;
}

// What the kernel says about the device, asked directly and not through the sink.
struct KernelMode {
    fb_var_screeninfo var{};
    fb_fix_screeninfo fix{};
};

bool queryMode(const std::string& device, KernelMode& mode, std::string& why) {
    const int fd = ::open(device.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) {
        why = "open: " + errnoText(errno);
        return false;
    }
    bool ok = true;
    if (ioctl(fd, FBIOGET_VSCREENINFO, &mode.var) != 0) {
        why = "FBIOGET_VSCREENINFO: " + errnoText(errno);
        ok = false;
    } else if (ioctl(fd, FBIOGET_FSCREENINFO, &mode.fix) != 0) {
        why = "FBIOGET_FSCREENINFO: " + errnoText(errno);
        ok = false;
    }
    ::close(fd);
    return ok;
}

std::string describe(const KernelMode& m) {
    auto channel = [](const char* name, const fb_bitfield& f) {
        return std::string(name) + " " + num(f.offset) + "/" + num(f.length);
    };
    return num(m.var.xres) + "x" + num(m.var.yres) + ", " + num(m.var.bits_per_pixel) +
           " bpp, lines of " + num(m.fix.line_length) + " bytes, y offset " + num(m.var.yoffset) +
           ", " + channel("red", m.var.red) + " " + channel("green", m.var.green) + " " +
           channel("blue", m.var.blue) + ", visual " + num(m.fix.visual) + ", " +
           num(m.fix.smem_len) + " bytes of memory";
}

// A pixel as the kernel's bitfields define it: each 8-bit component keeps its top `length` bits,
// placed at bit `offset`; the other bits are zero.
std::uint32_t expectedPixel(const fb_var_screeninfo& var, const std::uint8_t* rgb) {
    auto field = [](std::uint8_t v, const fb_bitfield& f) {
        return (static_cast<std::uint32_t>(v) >> (8 - f.length)) << f.offset;
    };
    return field(rgb[0], var.red) | field(rgb[1], var.green) | field(rgb[2], var.blue);
}

// The pixel at (x, y) of a page read back: bits_per_pixel / 8 bytes, little-endian (x86-64).
std::uint32_t pixelAt(const std::vector<std::uint8_t>& page, const KernelMode& m, int x, int y) {
    const std::size_t bytes = m.var.bits_per_pixel / 8;
    const std::uint8_t* p = page.data() + static_cast<std::size_t>(y) * m.fix.line_length +
                            static_cast<std::size_t>(x) * bytes;
    std::uint32_t v = 0;
    for (std::size_t i = 0; i < bytes; ++i) {
        v |= static_cast<std::uint32_t>(p[i]) << (8 * i);
    }
    return v;
}

// The visible page through read(): from yoffset lines in, yres lines.
bool readVisiblePage(const std::string& device, const KernelMode& m,
                     std::vector<std::uint8_t>& page, std::string& why) {
    const int fd = ::open(device.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) {
        why = "open: " + errnoText(errno);
        return false;
    }
    page.assign(static_cast<std::size_t>(m.var.yres) * m.fix.line_length, 0);
    const off_t start = static_cast<off_t>(m.var.yoffset) * m.fix.line_length;
    std::size_t done = 0;
    bool ok = lseek(fd, start, SEEK_SET) == start;
    if (!ok) {
        why = "lseek: " + errnoText(errno);
    }
    while (ok && done < page.size()) {
        const ssize_t n = ::read(fd, page.data() + done, page.size() - done);
        if (n <= 0) {
            why = n == 0 ? "read: end of device after " + num(static_cast<long>(done)) + " bytes"
                         : "read: " + errnoText(errno);
            ok = false;
        } else {
            done += static_cast<std::size_t>(n);
        }
    }
    ::close(fd);
    return ok;
}

// The visible page through a mapping of its own (read-only, separate from the sink's).
bool mapVisiblePage(const std::string& device, const KernelMode& m, std::vector<std::uint8_t>& page,
                    std::string& why) {
    const int fd = ::open(device.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) {
        why = "open: " + errnoText(errno);
        return false;
    }
    const std::size_t bytes = m.fix.smem_len;
    void* p = mmap(nullptr, bytes, PROT_READ, MAP_SHARED, fd, 0);
    ::close(fd);
    if (p == MAP_FAILED) {
        why = "mmap: " + errnoText(errno);
        return false;
    }
    const std::size_t start = static_cast<std::size_t>(m.var.yoffset) * m.fix.line_length;
    const std::size_t size = static_cast<std::size_t>(m.var.yres) * m.fix.line_length;
    const auto* base = static_cast<const std::uint8_t*>(p);
    page.assign(base + start, base + start + size);
    munmap(p, bytes);
    return true;
}

// A frame whose neighbouring pixels differ in every channel's top bits (so that a pixel taken
// from the wrong column or row shows at 16 bpp too), with low bits that RGB565 must drop.
Image pattern(int width, int height) {
    Image img(width, height);
    for (int y = 0; y < height; ++y) {
        for (int x = 0; x < width; ++x) {
            std::uint8_t* p = img.pixel(x, y);
            p[0] = static_cast<std::uint8_t>(x * 8 + (y & 7));
            p[1] = static_cast<std::uint8_t>(y * 4 + (x & 3));
            p[2] = static_cast<std::uint8_t>((x * 3 + y * 5) * 8 + ((x + y) & 7));
        }
    }
    return img;
}

// Compares a page read back with the frame as render/framebuffer.h says it is shown: scaled to
// the largest size with the frame's aspect that fits, centred, nearest neighbour (panel pixel x
// of a picture w wide shows source column floor(x * width / w)), black outside.
void expectFrame(Checks& checks, const std::string& what, const std::vector<std::uint8_t>& page,
                 const KernelMode& m, const Image& frame) {
    const int pw = static_cast<int>(m.var.xres);
    const int ph = static_cast<int>(m.var.yres);
    int w = pw;
    int h = static_cast<int>(static_cast<long>(pw) * frame.height / frame.width);
    if (h > ph) {
        h = ph;
        w = static_cast<int>(static_cast<long>(ph) * frame.width / frame.height);
    }
    const int x0 = (pw - w) / 2;
    const int y0 = (ph - h) / 2;
    long mismatches = 0;
    long barPixels = 0;
    std::string first;
    for (int y = 0; y < ph; ++y) {
        for (int x = 0; x < pw; ++x) {
            std::uint32_t want = 0;
            if (x >= x0 && x < x0 + w && y >= y0 && y < y0 + h) {
                const int sx = static_cast<int>(static_cast<long>(x - x0) * frame.width / w);
                const int sy = static_cast<int>(static_cast<long>(y - y0) * frame.height / h);
                want = expectedPixel(m.var, frame.pixel(sx, sy));
            } else {
                ++barPixels;
            }
            const std::uint32_t got = pixelAt(page, m, x, y);
            if (got != want) {
                if (mismatches == 0) {
                    first = "first at (" + num(x) + ", " + num(y) + "): got " + hex(got) +
                            ", expected " + hex(want);
                }
                ++mismatches;
            }
        }
    }
    checks.expect(mismatches == 0,
                  what + ": all " + num(static_cast<long>(pw) * ph) + " pixels as expected (" +
                      num(w) + "x" + num(h) + " picture at (" + num(x0) + ", " + num(y0) + "), " +
                      num(barPixels) + " black bar pixels)",
                  num(mismatches) + " pixels differ, " + first);
}

// One depth: the sink asks for it, writes two frames; each is read back and compared.
void checkDepth(const std::string& device, int bpp, Checks& checks) {
    std::printf("== framebuffer %s at %d bpp (render/framebuffer)\n", device.c_str(), bpp);
    auto sink = FramebufferSink::openDevice(device, bpp);
    if (!checks.expect(sink.ok(), "the sink opens " + device + " asking for " + num(bpp) + " bpp",
                       sink.ok() ? "" : sink.error().message)) {
        return;
    }
    KernelMode m;
    std::string why;
    if (!checks.expect(queryMode(device, m, why), "the kernel reports the mode", why)) {
        return;
    }
    Checks::info("kernel: " + describe(m));
    checks.expect(
        static_cast<int>(m.var.bits_per_pixel) == bpp && m.fix.visual == FB_VISUAL_TRUECOLOR,
        "the kernel now runs " + num(bpp) + " bpp true-colour",
        "got " + num(m.var.bits_per_pixel) + " bpp, visual " + num(m.fix.visual));
    const render::FbMode& s = sink->mode();
    const bool same = s.width == static_cast<int>(m.var.xres) &&
                      s.height == static_cast<int>(m.var.yres) &&
                      s.bitsPerPixel == static_cast<int>(m.var.bits_per_pixel) &&
                      s.lineLengthBytes == static_cast<int>(m.fix.line_length) &&
                      s.red.offset == static_cast<int>(m.var.red.offset) &&
                      s.red.length == static_cast<int>(m.var.red.length) &&
                      s.green.offset == static_cast<int>(m.var.green.offset) &&
                      s.green.length == static_cast<int>(m.var.green.length) &&
                      s.blue.offset == static_cast<int>(m.var.blue.offset) &&
                      s.blue.length == static_cast<int>(m.var.blue.length);
    checks.expect(same, "the sink's mode is the kernel's (size, depth, line length, bitfields)",
                  "sink: " + num(s.width) + "x" + num(s.height) + " " + num(s.bitsPerPixel) +
                      " bpp, line " + num(s.lineLengthBytes));
    const int pw = static_cast<int>(m.var.xres);
    const int ph = static_cast<int>(m.var.yres);
    if (!checks.expect(pw % 4 == 0 && ph % 4 == 0 && pw >= 8 && ph >= 8,
                       "the panel's size is a multiple of 4 (the first frame is a quarter of it)",
                       num(pw) + "x" + num(ph))) {
        return;
    }

    // A quarter-size frame of the panel's aspect: every source pixel becomes a 4x4 block.
    const Image quarter = pattern(pw / 4, ph / 4);
    auto written = sink->write(quarter);
    checks.expect(written.ok(),
                  "the sink writes a " + num(quarter.width) + "x" + num(quarter.height) + " frame",
                  written.ok() ? "" : written.error().message);
    std::vector<std::uint8_t> page;
    if (checks.expect(readVisiblePage(device, m, page, why),
                      "read() returns the visible page (" +
                          num(static_cast<long>(m.var.yres) * m.fix.line_length) + " bytes)",
                      why)) {
        expectFrame(checks, num(bpp) + " bpp, quarter frame scaled 4x, read()", page, m, quarter);
    }

    // A 2:1 frame at a scale that is not a whole number: letterboxed, black bars above and below.
    const Image wide = pattern(pw * 25 / 64, pw * 25 / 128);
    written = sink->write(wide);
    checks.expect(written.ok(),
                  "the sink writes a " + num(wide.width) + "x" + num(wide.height) + " frame",
                  written.ok() ? "" : written.error().message);
    std::vector<std::uint8_t> mapped;
    if (checks.expect(readVisiblePage(device, m, page, why), "read() returns the visible page",
                      why)) {
        expectFrame(checks, num(bpp) + " bpp, 2:1 frame letterboxed, read()", page, m, wide);
        if (checks.expect(mapVisiblePage(device, m, mapped, why), "a second mmap of the device",
                          why)) {
            checks.expect(mapped == page, "the second mapping shows the bytes read() returned");
        }
    }
}

}  // namespace

void checkFramebuffer(const std::string& device, Checks& checks) {
    std::printf("== framebuffer %s: errors (render/framebuffer)\n", device.c_str());
    KernelMode start;
    std::string why;
    if (checks.expect(queryMode(device, start, why), "the kernel reports " + device + "'s mode",
                      why)) {
        Checks::info("kernel at load: " + describe(start));
        // vfb starts at 8 bpp with a palette; the sink writes true-colour pixels only and must
        // say so rather than write nonsense.
        checks.expect(start.fix.visual != FB_VISUAL_TRUECOLOR,
                      "vfb starts in a mode that is not true-colour (8 bpp pseudocolour)",
                      "visual " + num(start.fix.visual));
        auto asIs = FramebufferSink::openDevice(device);
        if (asIs.ok()) {
            checks.expect(false, "the sink refuses the pseudocolour mode", "it opened");
        } else {
            Checks::info("message: " + asIs.error().message);
            checks.expect(asIs.error().code == EINVAL &&
                              asIs.error().message.find(device) != std::string::npos &&
                              asIs.error().message.find("true-colour") != std::string::npos,
                          "the sink refuses the pseudocolour mode with EINVAL, naming the device",
                          "got " + errnoText(asIs.error().code));
        }
    }
    const std::string absent = "/dev/fb9";
    auto missing = FramebufferSink::openDevice(absent, 16);
    if (missing.ok()) {
        checks.expect(false, "the sink fails on " + absent, "it opened");
    } else {
        Checks::info("message: " + missing.error().message);
        checks.expect(missing.error().code == ENOENT &&
                          missing.error().message.find(absent) != std::string::npos,
                      "the sink fails on " + absent + " with ENOENT, naming the device",
                      "got " + errnoText(missing.error().code));
    }
    for (int bpp : {16, 32}) {
        checkDepth(device, bpp, checks);
    }
}

}  // namespace caphub::kernel_test
