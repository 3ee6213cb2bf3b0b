// Input files named by a person: read when they are files, and otherwise refused with what they
// are (a directory, a device), never read as an empty or garbled file.
#include "hal/core/input_file.h"

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <unistd.h>

namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

std::string tempPath(const std::string& name) {
    return ::testing::TempDir() + "caphub_input_file_" + std::to_string(getpid()) + "_" + name;
}

TEST(InputFile, AFileIsReadWhole) {
    const std::string p = tempPath("text");
    std::ofstream(p, std::ios::binary) << std::string("a\0b\n", 4);
    auto text = caphub::readInputFile(p);
    ASSERT_TRUE(text.ok()) << text.error().message;
    EXPECT_EQ(*text, std::string("a\0b\n", 4));
}

TEST(InputFile, ADirectoryIsSaidToBeOne) {
    const std::string d = tempPath("dir");
    fs::create_directories(d);
    auto text = caphub::readInputFile(d);
    ASSERT_FALSE(text.ok());
    EXPECT_EQ(text.error().code, EISDIR);
    EXPECT_EQ(text.error().message, "'" + d + "' is a directory, not a file");
    EXPECT_FALSE(caphub::openInputFile(d).ok());
    EXPECT_FALSE(caphub::checkInputFile(d).ok());
}

TEST(InputFile, ADeviceIsNotOpened) {
    auto f = caphub::openInputFile("/dev/zero");  // would read forever
    ASSERT_FALSE(f.ok());
    EXPECT_EQ(f.error().code, ENODEV);
    EXPECT_THAT(f.error().message, HasSubstr("'/dev/zero' is a device"));
}

TEST(InputFile, AMissingFileGivesTheSystemsReason) {
    auto text = caphub::readInputFile(tempPath("absent"));
    ASSERT_FALSE(text.ok());
    EXPECT_EQ(text.error().code, ENOENT);
    EXPECT_THAT(text.error().message, HasSubstr("No such file or directory"));
}

TEST(InputFile, ASymlinkToAFileIsReadAndOneToADirectoryIsRefused) {
    const std::string target = tempPath("target");
    std::ofstream(target) << "hello";
    const std::string link = tempPath("link");
    fs::remove(link);
    fs::create_symlink(target, link);
    auto text = caphub::readInputFile(link);
    ASSERT_TRUE(text.ok()) << text.error().message;
    EXPECT_EQ(*text, "hello");
    const std::string dirLink = tempPath("dirlink");
    fs::remove(dirLink);
    fs::create_symlink("/", dirLink);
    EXPECT_EQ(caphub::readInputFile(dirLink).error().code, EISDIR);
}

TEST(InputFile, AFileOverTheLimitIsRefusedUnread) {
    const std::string p = tempPath("big");
    std::ofstream(p) << std::string(1000, 'x');
    auto text = caphub::readInputFile(p, 999);
    ASSERT_FALSE(text.ok());
    EXPECT_EQ(text.error().code, EFBIG);
    EXPECT_THAT(text.error().message, HasSubstr("is 1000 bytes, more than the 999 bytes allowed"));
    EXPECT_TRUE(caphub::readInputFile(p, 1000).ok());
}

}  // namespace
