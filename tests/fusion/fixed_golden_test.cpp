// The fixed-point filter is bit-identical on every architecture: its raw int32 state over a
// shipped BROAD excerpt hashes to the golden value written on x86-64 (the aarch64 ctest run
// executes this same test under qemu-aarch64). And the float filter agrees with it on that input.
#include "tests/fusion/fixed_golden.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <string>

#include <gtest/gtest.h>

namespace caphub::fusion::golden {
namespace {

const std::string kInput = std::string(CAPHUB_TEST_DATA_DIR) + "/" + kInputName;
const std::string kGolden = std::string(CAPHUB_TEST_DATA_DIR) + "/" + kGoldenName;

constexpr double kDeg = 0.017453292519943295;

std::string hex(std::uint64_t v) {
    char buf[17];
    std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(v));
    return buf;
}

// A file under the test's temporary folder with the given text.
std::string writeTemp(const std::string& name, const std::string& text) {
    const std::string path = ::testing::TempDir() + name;
    std::ofstream(path, std::ios::trunc) << text;
    return path;
}

TEST(Fnv1a64, MatchesThePublishedTestVectors) {
    // From the FNV reference (Fowler, Noll, Vo): "" and "a" and "foobar" with FNV-1a 64.
    EXPECT_EQ(Fnv1a64{}.value(), 0xcbf29ce484222325ULL);
    Fnv1a64 a;
    a.addBytes("a");
    EXPECT_EQ(a.value(), 0xaf63dc4c8601ec8cULL);
    Fnv1a64 foobar;
    foobar.addBytes("foobar");
    EXPECT_EQ(foobar.value(), 0x85944171f73967e8ULL);
}

TEST(Fnv1a64, HashesInt32AsLittleEndianBytes) {
    Fnv1a64 fromInt;
    fromInt.addInt32(0x64636261);  // the bytes 'a' 'b' 'c' 'd' in little-endian order
    Fnv1a64 fromText;
    fromText.addBytes("abcd");
    EXPECT_EQ(fromInt.value(), fromText.value());
}

TEST(FixedGolden, ExcerptReadsAsTheDocumentedRows) {
    auto samples = readExcerpt(kInput);
    ASSERT_TRUE(samples) << samples.error().message;
    // tests/data/README.md: data rows 12080-14399 of trial 24_disturbed_tapping_A.
    ASSERT_EQ(samples->size(), 2320u);
    EXPECT_DOUBLE_EQ(samples->front().tS, 42.28);
    EXPECT_DOUBLE_EQ(samples->front().accMps2.z(), 9.83374406);
    EXPECT_DOUBLE_EQ(samples->back().magUt.z(), -35.5576339);
}

TEST(FixedGolden, RawStateHashesToTheGoldenWrittenOnX8664) {
    auto samples = readExcerpt(kInput);
    ASSERT_TRUE(samples) << samples.error().message;
    auto expected = readGolden(kGolden);
    ASSERT_TRUE(expected) << expected.error().message;
    const std::vector<Checkpoint> actual = checkpoints(runFixedRaw(*samples));
    ASSERT_EQ(actual.size(), expected->size()) << "golden made from another input length";
    // Exact equality: the point of the test. The first differing checkpoint says after how many
    // samples the runs part (caphub_fixed_golden INPUT - RAW.csv gives the values to diff).
    for (std::size_t i = 0; i < actual.size(); ++i) {
        ASSERT_EQ(actual[i].samples, (*expected)[i].samples);
        ASSERT_EQ(hex(actual[i].hash), hex((*expected)[i].hash))
            << "raw state differs within the first " << actual[i].samples << " samples";
    }
}

TEST(FixedGolden, OneLsbChangeOfTheStateChangesTheHash) {
    auto samples = readExcerpt(kInput);
    ASSERT_TRUE(samples) << samples.error().message;
    std::vector<std::int32_t> raw = runFixedRaw(*samples);
    const auto before = checkpoints(raw);
    raw[raw.size() / 2] ^= 1;  // one bit of one value in the middle of the run
    const auto after = checkpoints(raw);
    ASSERT_EQ(before.size(), after.size());
    EXPECT_NE(before.back().hash, after.back().hash);
    EXPECT_EQ(before.front().hash, after.front().hash);  // the first checkpoint precedes it
}

TEST(FixedGolden, TheExcerptExercisesRestMotionAndTaps) {
    // The hash only proves what the input reaches: rest (bias averaging), motion, and taps far
    // beyond the dynamic threshold (|acc| up to 78 m/s^2 at sample 2220).
    auto samples = readExcerpt(kInput);
    ASSERT_TRUE(samples) << samples.error().message;
    double maxAcc = 0.0;
    double maxGyr = 0.0;
    for (const ImuSample& s : *samples) {
        maxAcc = std::max(maxAcc, s.accMps2.norm());
        maxGyr = std::max(maxGyr, s.gyrRadS.norm());
    }
    EXPECT_GT(maxAcc, 5.0 * 9.81);
    EXPECT_GT(maxGyr, 3.0);
    FilterParams params;
    params.gyrRateHz = params.accRateHz = params.magRateHz = kRateHz;
    OrientationFilter<FixedTypes> f(params);
    bool sawRest = false;
    for (const ImuSample& s : *samples) {
        using S = FixedTypes;
        f.updateGyr(fromDoubleVec<S::Gyr>(s.gyrRadS.x(), s.gyrRadS.y(), s.gyrRadS.z()));
        f.updateAcc(fromDoubleVec<S::Acc>(s.accMps2.x(), s.accMps2.y(), s.accMps2.z()));
        f.updateMag(fromDoubleVec<S::Mag>(s.magUt.x(), s.magUt.y(), s.magUt.z()));
        sawRest = sawRest || f.atRest();
    }
    EXPECT_TRUE(sawRest);
}

TEST(FixedGolden, FloatAndFixedAgreeOnTheExcerpt) {
    auto samples = readExcerpt(kInput);
    ASSERT_TRUE(samples) << samples.error().message;
    const auto fl = runFilter(*samples, kRateHz, 1, FilterVariant::Float);
    const auto fx = runFilter(*samples, kRateHz, 1, FilterVariant::Fixed);
    ASSERT_EQ(fl.size(), fx.size());
    double worstRad = 0.0;
    for (std::size_t i = 0; i < fl.size(); ++i) {
        worstRad = std::max(worstRad, fl[i].angularDistance(fx[i]));
    }
    // Both variants differ by rounding only: float carries 24 bits (6e-8 relative), the Q30
    // quaternion 1e-9. With about 100 rounded operations per sample, a random walk of float
    // rounding over 2320 samples is near 6e-8 * sqrt(2320 * 100) = 3e-5 rad (0.002 deg), and
    // the gravity and heading corrections pull both runs to the same measurements. 0.01 deg is
    // five times that estimate (measured on x86-64: 0.00014 deg). The synthetic comparison with
    // 16 g shocks is OrientationFilterFixedPoint in orientation_filter_test.cpp.
    RecordProperty("worst_deg", std::to_string(worstRad / kDeg));
    EXPECT_LT(worstRad / kDeg, 0.01);
}

TEST(FixedGolden, ExcerptErrorsNameFileLineAndWhatWasExpected) {
    const std::string header = "t,gyr_x,gyr_y,gyr_z,acc_x,acc_y,acc_z,mag_x,mag_y,mag_z\n";
    const std::string bad =
        writeTemp("golden_bad_row.csv", "# comment\n" + header +
                                            "0,0,0,0,0,0,9.8,20,0,-40\n"
                                            "0.0035,0,0,zero,0,0,9.8,20,0,-40\n");
    auto r = readExcerpt(bad);
    ASSERT_FALSE(r);
    EXPECT_NE(r.error().message.find(bad + ":4: expected a finite number in column 4"),
              std::string::npos)
        << r.error().message;

    const std::string noHeader = writeTemp("golden_no_header.csv", "0,0,0,0,0,0,9.8,20,0,-40\n");
    auto h = readExcerpt(noHeader);
    ASSERT_FALSE(h);
    EXPECT_NE(h.error().message.find(":1: expected the header"), std::string::npos)
        << h.error().message;

    auto missing = readExcerpt(::testing::TempDir() + "golden_does_not_exist.csv");
    EXPECT_FALSE(missing);
}

TEST(FixedGolden, GoldenFileErrorsNameFileLineAndWhatWasExpected) {
    const std::string bad =
        writeTemp("golden_bad.txt", "# c\nhash 256 0123456789abcdef\nhash 512 0123\n");
    auto r = readGolden(bad);
    ASSERT_FALSE(r);
    EXPECT_NE(r.error().message.find(bad + ":3: expected 'hash SAMPLES HEX'"), std::string::npos)
        << r.error().message;

    const std::string order =
        writeTemp("golden_order.txt", "hash 512 0123456789abcdef\nhash 256 0123456789abcdef\n");
    auto o = readGolden(order);
    ASSERT_FALSE(o);
    EXPECT_NE(o.error().message.find(":2: expected sample counts in increasing order"),
              std::string::npos)
        << o.error().message;
}

TEST(FixedGolden, GoldenFileRoundTripsThroughItsFormat) {
    const std::vector<Checkpoint> points{{256, 0x0123456789abcdefULL},
                                         {300, 0xfedcba9876543210ULL}};
    const std::string path = writeTemp("golden_round_trip.txt", formatGolden(points, "a\nb"));
    auto back = readGolden(path);
    ASSERT_TRUE(back) << back.error().message;
    EXPECT_EQ(*back, points);
}

}  // namespace
}  // namespace caphub::fusion::golden
