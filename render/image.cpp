#include "render/image.h"

#include <cerrno>
#include <cstdio>
#include <memory>

#include <fcntl.h>
#include <fmt/format.h>
#include <png.h>
#include <sys/stat.h>
#include <unistd.h>

namespace caphub::render {

namespace {

struct FileCloser {
    void operator()(std::FILE* f) const { std::fclose(f); }
};
using File = std::unique_ptr<std::FILE, FileCloser>;

}  // namespace

Result<void> writePng(const Image& image, const std::filesystem::path& path) {
    // A regular file only: a symbolic link is not followed (it would write wherever it points),
    // and neither a FIFO (its open would wait for a reader for ever) nor a device is written.
    const int fd = ::open(path.c_str(),
                          O_WRONLY | O_CREAT | O_TRUNC | O_NOFOLLOW | O_NONBLOCK | O_CLOEXEC, 0644);
    if (fd < 0) {
        const int err = errno;
        return errnoError(-err, fmt::format("write '{}'{}", path.string(),
                                            err == ELOOP   ? " (a symbolic link: not followed)"
                                            : err == ENXIO ? " (a FIFO: not written)"
                                                           : ""));
    }
    struct stat st {};
    if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
        ::close(fd);
        return Error{EINVAL, fmt::format("write '{}': not a regular file", path.string())};
    }
    File f(::fdopen(fd, "wb"));
    if (!f) {
        const int err = errno;
        ::close(fd);
        return errnoError(-err, fmt::format("write '{}'", path.string()));
    }
    png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
    png_infop info = png ? png_create_info_struct(png) : nullptr;
    if (!info) {
        png_destroy_write_struct(&png, nullptr);
        return Error{ENOMEM, fmt::format("write '{}': libpng could not start", path.string())};
    }
    // libpng reports errors by longjmp; nothing with a destructor is live between here and the
    // end of the writes.
    if (setjmp(png_jmpbuf(png))) {
        png_destroy_write_struct(&png, &info);
        return Error{EIO, fmt::format("write '{}': libpng failed", path.string())};
    }
    png_init_io(png, f.get());
    png_set_IHDR(png, info, static_cast<png_uint_32>(image.width),
                 static_cast<png_uint_32>(image.height), 8, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE,
                 PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
    // Level 3: previews are written every frame; the best levels cost several times the time
    // for a few percent of size.
    png_set_compression_level(png, 3);
    png_write_info(png, info);
    for (int y = 0; y < image.height; ++y) {
        png_write_row(png, const_cast<png_bytep>(image.pixel(0, y)));
    }
    png_write_end(png, nullptr);
    png_destroy_write_struct(&png, &info);
    if (std::fflush(f.get()) != 0) {
        return errnoError(-errno, fmt::format("write '{}'", path.string()));
    }
    return {};
}

Result<Image> readPng(const std::filesystem::path& path) {
    File f(std::fopen(path.c_str(), "rb"));
    if (!f) {
        return errnoError(-errno, fmt::format("open '{}'", path.string()));
    }
    png_byte sig[8] = {};
    if (std::fread(sig, 1, 8, f.get()) != 8 || png_sig_cmp(sig, 0, 8) != 0) {
        return Error{EINVAL, fmt::format("{}: not a PNG file", path.string())};
    }
    png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
    png_infop info = png ? png_create_info_struct(png) : nullptr;
    if (!info) {
        png_destroy_read_struct(&png, nullptr, nullptr);
        return Error{ENOMEM, fmt::format("{}: libpng could not start", path.string())};
    }
    Image* img = new Image;  // raw: must survive a longjmp without leaking its destructor call
    if (setjmp(png_jmpbuf(png))) {
        png_destroy_read_struct(&png, &info, nullptr);
        delete img;
        return Error{EINVAL, fmt::format("{}: corrupt PNG data", path.string())};
    }
    png_init_io(png, f.get());
    png_set_sig_bytes(png, 8);
    png_read_info(png, info);
    const auto w = png_get_image_width(png, info);
    const auto h = png_get_image_height(png, info);
    const int depth = png_get_bit_depth(png, info);
    const int type = png_get_color_type(png, info);
    if (depth != 8 || (type != PNG_COLOR_TYPE_RGB && type != PNG_COLOR_TYPE_RGBA) || w == 0 ||
        h == 0 || w > 16384 || h > 16384) {
        png_destroy_read_struct(&png, &info, nullptr);
        delete img;
        return Error{EINVAL, fmt::format("{}: {}x{} depth {} colour type {}: expected 8-bit RGB "
                                         "or RGBA up to 16384x16384",
                                         path.string(), w, h, depth, type)};
    }
    if (type == PNG_COLOR_TYPE_RGBA) {
        png_set_strip_alpha(png);
    }
    png_read_update_info(png, info);
    *img = Image(static_cast<int>(w), static_cast<int>(h));
    for (int y = 0; y < img->height; ++y) {
        png_read_row(png, img->pixel(0, y), nullptr);
    }
    png_destroy_read_struct(&png, &info, nullptr);
    Image out = std::move(*img);
    delete img;
    return out;
}

}  // namespace caphub::render
