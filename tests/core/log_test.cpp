#include "hal/core/log.h"

#include <set>
#include <string>

#include <gtest/gtest.h>

namespace caphub::log {
namespace {

TEST(Log, EveryModuleHasItsOwnNamedLogger) {
    std::set<std::string> names;
    std::set<const spdlog::logger*> loggers;
    for (int i = 0; i < kCategoryCount; ++i) {
        const auto c = static_cast<Category>(i);
        EXPECT_EQ(logger(c).name(), std::string(name(c)));
        names.insert(logger(c).name());
        loggers.insert(&logger(c));
    }
    EXPECT_EQ(names.size(), static_cast<std::size_t>(kCategoryCount));
    EXPECT_EQ(loggers.size(), static_cast<std::size_t>(kCategoryCount));
}

TEST(Log, DefaultLevelAppliesToAllAndOverridesToOne) {
    ASSERT_TRUE(configure("warn,hal=debug").ok());
    EXPECT_EQ(logger(Category::Hal).level(), spdlog::level::debug);
    EXPECT_EQ(logger(Category::Fusion).level(), spdlog::level::warn);
    ASSERT_TRUE(configure(" fusion = trace ").ok());
    EXPECT_EQ(logger(Category::Fusion).level(), spdlog::level::trace);
    EXPECT_EQ(logger(Category::Hal).level(), spdlog::level::debug);  // untouched
    ASSERT_TRUE(configure("info").ok());
}

TEST(Log, UnknownLevelIsRejectedAndChangesNothing) {
    ASSERT_TRUE(configure("info").ok());
    const auto r = configure("hal=debug,board=loud");
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("loud"), std::string::npos);
    EXPECT_EQ(logger(Category::Hal).level(), spdlog::level::info);
}

TEST(Log, UnknownCategoryIsRejectedByName) {
    const auto r = configure("gpu=debug");
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("'gpu'"), std::string::npos);
    EXPECT_NE(r.error().message.find("fusion"), std::string::npos);  // lists the known ones
}

}  // namespace
}  // namespace caphub::log
