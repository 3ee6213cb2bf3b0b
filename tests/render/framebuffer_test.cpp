// The framebuffer sink against a file standing in for /dev/fbN.
#include "render/framebuffer.h"

#include <cstring>
#include <filesystem>
#include <fstream>
#include <vector>

#include <gtest/gtest.h>

namespace caphub::render {
namespace {

std::filesystem::path tempFile(const char* name) {
    return std::filesystem::temp_directory_path() /
           (std::string("caphub_fb_") + std::to_string(::getpid()) + "_" + name);
}

std::vector<std::uint8_t> readAll(const std::filesystem::path& p) {
    std::ifstream f(p, std::ios::binary);
    return {std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>()};
}

// 2x2 image: red, green / blue, white.
Image quad() {
    Image img(2, 2);
    const std::uint8_t px[4][3] = {{255, 0, 0}, {0, 255, 0}, {0, 0, 255}, {255, 255, 255}};
    std::memcpy(img.rgb.data(), px, sizeof px);
    return img;
}

TEST(Framebuffer, Rgb565PacksFiveSixFiveBits) {
    const FbMode m = rgb565Mode(4, 4);
    EXPECT_EQ(packPixel(m, 255, 0, 0), 0xF800u);
    EXPECT_EQ(packPixel(m, 0, 255, 0), 0x07E0u);
    EXPECT_EQ(packPixel(m, 0, 0, 255), 0x001Fu);
    EXPECT_EQ(packPixel(m, 0x84, 0x82, 0x08), (0x10u << 11) | (0x20u << 5) | 0x01u);
}

TEST(Framebuffer, Xrgb8888PutsRedInBits16To23) {
    const FbMode m = xrgb8888Mode(4, 4);
    EXPECT_EQ(packPixel(m, 0x12, 0x34, 0x56), 0x123456u);
}

TEST(Framebuffer, FileFakeReceivesTheScaledFrameInXrgb8888) {
    const auto path = tempFile("xrgb");
    {
        auto fb = FramebufferSink::openFile(path, xrgb8888Mode(4, 4));
        ASSERT_TRUE(fb) << fb.error().message;
        ASSERT_TRUE(fb->write(quad()));
    }
    const auto bytes = readAll(path);
    std::filesystem::remove(path);
    ASSERT_EQ(bytes.size(), 4u * 4 * 4);
    auto at = [&](int x, int y) {
        std::uint32_t v;
        std::memcpy(&v, bytes.data() + (y * 4 + x) * 4, 4);
        return v;
    };
    // 2x2 scaled to 4x4: each source pixel covers a 2x2 block.
    EXPECT_EQ(at(0, 0), 0xFF0000u);
    EXPECT_EQ(at(1, 1), 0xFF0000u);
    EXPECT_EQ(at(3, 0), 0x00FF00u);
    EXPECT_EQ(at(0, 3), 0x0000FFu);
    EXPECT_EQ(at(3, 3), 0xFFFFFFu);
}

TEST(Framebuffer, FileFakeReceivesRgb565WithLetterboxAndLinePadding) {
    const auto path = tempFile("rgb565");
    FbMode m = rgb565Mode(4, 4);
    m.lineLengthBytes = 12;  // padded lines, as some drivers have
    {
        Image wide(2, 1);
        const std::uint8_t px[6] = {255, 0, 0, 0, 0, 255};
        std::memcpy(wide.rgb.data(), px, 6);
        auto fb = FramebufferSink::openFile(path, m);
        ASSERT_TRUE(fb) << fb.error().message;
        ASSERT_TRUE(fb->write(wide));
    }
    const auto bytes = readAll(path);
    std::filesystem::remove(path);
    ASSERT_EQ(bytes.size(), 12u * 4);
    auto at = [&](int x, int y) {
        std::uint16_t v;
        std::memcpy(&v, bytes.data() + y * 12 + x * 2, 2);
        return v;
    };
    // A 2:1 frame on a 1:1 panel: 4x2 in the middle, black bars above and below.
    EXPECT_EQ(at(0, 0), 0u);
    EXPECT_EQ(at(0, 1), 0xF800u);
    EXPECT_EQ(at(1, 2), 0xF800u);
    EXPECT_EQ(at(3, 2), 0x001Fu);
    EXPECT_EQ(at(3, 3), 0u);
}

TEST(Framebuffer, UnsupportedDepthIsRefused) {
    FbMode m = xrgb8888Mode(4, 4);
    m.bitsPerPixel = 8;
    auto fb = FramebufferSink::openFile(tempFile("bad"), m);
    ASSERT_FALSE(fb);
    EXPECT_NE(fb.error().message.find("8 bpp"), std::string::npos);
}

TEST(Framebuffer, MissingDeviceSaysWhy) {
    auto fb = FramebufferSink::openDevice("/dev/fb_caphub_missing");
    ASSERT_FALSE(fb);
    EXPECT_NE(fb.error().message.find("/dev/fb_caphub_missing"), std::string::npos);
}

TEST(Framebuffer, MalformedImageIsAnError) {
    const auto path = tempFile("malformed");
    auto fb = FramebufferSink::openFile(path, xrgb8888Mode(4, 4));
    ASSERT_TRUE(fb) << fb.error().message;
    Image bad(4, 4);
    bad.rgb.resize(5);
    EXPECT_FALSE(fb->write(bad));
    std::filesystem::remove(path);
}

}  // namespace
}  // namespace caphub::render
