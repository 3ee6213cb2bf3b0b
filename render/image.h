// An RGB frame as the renderer produces it and the sinks consume it, and PNG files of it.
#pragma once

#include <cstdint>
#include <filesystem>
#include <vector>

#include "hal/core/error.h"

namespace caphub::render {

// 8-bit RGB, rows top to bottom, no padding.
struct Image {
    int width = 0;
    int height = 0;
    std::vector<std::uint8_t> rgb;

    Image() = default;
    Image(int w, int h) : width(w), height(h), rgb(static_cast<std::size_t>(w) * h * 3) {}
    std::uint8_t* pixel(int x, int y) {
        return rgb.data() + (static_cast<std::size_t>(y) * width + x) * 3;
    }
    const std::uint8_t* pixel(int x, int y) const {
        return rgb.data() + (static_cast<std::size_t>(y) * width + x) * 3;
    }
};

Result<void> writePng(const Image& image, const std::filesystem::path& path);
// Reads 8-bit RGB or RGBA PNGs (alpha dropped); anything else is an error naming the file.
Result<Image> readPng(const std::filesystem::path& path);

}  // namespace caphub::render
