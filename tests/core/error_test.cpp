#include "hal/core/error.h"

#include <string>

#include <gtest/gtest.h>

namespace caphub {
namespace {

TEST(Error, ErrnoTextAcceptsEitherSign) {
    EXPECT_EQ(errnoText(ENODEV), errnoText(-ENODEV));
    EXPECT_EQ(errnoText(ENOENT), "No such file or directory");
}

TEST(Error, ErrnoErrorCarriesContextAndAPositiveCode) {
    const Error e = errnoError(-EACCES, "open '/dev/i2c-1'");
    EXPECT_EQ(e.code, EACCES);
    EXPECT_EQ(e.message, "open '/dev/i2c-1': Permission denied");
}

Result<int> parsePositive(int v) {
    if (v <= 0) {
        return Error{EINVAL, "not positive"};
    }
    return v;
}

TEST(Result, HoldsAValueOrAnError) {
    const auto good = parsePositive(3);
    ASSERT_TRUE(good.ok());
    EXPECT_EQ(*good, 3);
    const auto bad = parsePositive(-1);
    ASSERT_FALSE(bad.ok());
    EXPECT_EQ(bad.error().code, EINVAL);
    EXPECT_EQ(bad.error().message, "not positive");
}

TEST(Result, VoidResultDefaultsToSuccess) {
    const Result<void> ok;
    EXPECT_TRUE(ok.ok());
    const Result<void> bad = Error{EIO, "bus error"};
    EXPECT_FALSE(bad.ok());
    EXPECT_EQ(bad.error().code, EIO);
}

TEST(Result, MovesItsValueOut) {
    Result<std::string> r = std::string(100, 'x');
    const std::string s = std::move(r).value();
    EXPECT_EQ(s.size(), 100u);
}

}  // namespace
}  // namespace caphub
