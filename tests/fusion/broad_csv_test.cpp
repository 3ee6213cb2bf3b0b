// The BROAD-layout reader and writer: what the replay and the virtual suit read and write.
#include "firmware/io/broad_csv.h"

#include <cmath>
#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

namespace caphub::firmware {
namespace {

std::filesystem::path writeText(const std::string& name, const std::string& text) {
    const auto p = std::filesystem::temp_directory_path() / name;
    std::ofstream(p) << text;
    return p;
}

const char* kHeader =
    "t,gyr_x,gyr_y,gyr_z,acc_x,acc_y,acc_z,mag_x,mag_y,mag_z,opt_w,opt_x,opt_y,opt_z,movement\n";

TEST(BroadCsv, ReadsRateNameSamplesAndTruth) {
    const auto p = writeText("caphub_broad_ok.csv",
                             std::string("# BROAD trial demo; sampling_rate_hz=100.0\n") + kHeader +
                                 "0.00,0.1,0.2,0.3,0,0,9.8,0,20,-40,1,0,0,0,0\n"
                                 "0.01,0.1,0.2,0.3,0,0,9.8,0,20,-40,nan,nan,nan,nan,1\n");
    auto t = readBroadCsv(p);
    std::filesystem::remove(p);
    ASSERT_TRUE(t) << t.error().message;
    EXPECT_EQ(t->name, "demo");
    EXPECT_DOUBLE_EQ(t->rateHz, 100.0);
    ASSERT_EQ(t->samples.size(), 2u);
    EXPECT_DOUBLE_EQ(t->samples[1].gyrRadS.z(), 0.3);
    EXPECT_TRUE(t->hasTruth());
    EXPECT_TRUE(std::isnan(t->truth[1].w()));
    EXPECT_TRUE(t->movement[1]);
}

TEST(BroadCsv, AcceptsImuColumnsOnlyAndDerivesTheRateFromTime) {
    const auto p = writeText("caphub_broad_imu.csv",
                             "t,gyr_x,gyr_y,gyr_z,acc_x,acc_y,acc_z,mag_x,mag_y,mag_z\n"
                             "0.000,0,0,0,0,0,9.8,0,20,-40\n0.005,0,0,0,0,0,9.8,0,20,-40\n"
                             "0.010,0,0,0,0,0,9.8,0,20,-40\n");
    auto t = readBroadCsv(p);
    std::filesystem::remove(p);
    ASSERT_TRUE(t) << t.error().message;
    EXPECT_FALSE(t->hasTruth());
    EXPECT_NEAR(t->rateHz, 200.0, 1e-6);
}

TEST(BroadCsv, NamesFileLineAndFieldOfAMalformedRow) {
    const auto p =
        writeText("caphub_broad_bad.csv", std::string(kHeader) +
                                              "0.00,0.1,0.2,0.3,0,0,9.8,0,20,-40,1,0,0,0,0\n"
                                              "0.01,0.1,abc,0.3,0,0,9.8,0,20,-40,1,0,0,0,0\n");
    auto t = readBroadCsv(p);
    std::filesystem::remove(p);
    ASSERT_FALSE(t);
    // Line 3, column 10: where 'abc' starts.
    EXPECT_NE(t.error().message.find("caphub_broad_bad.csv:3:10:"), std::string::npos)
        << t.error().message;
    EXPECT_NE(t.error().message.find("gyr_y"), std::string::npos) << t.error().message;
}

TEST(BroadCsv, RefusesShortRowsNanImuValuesAndTimeGoingBack) {
    const std::string base = std::string(kHeader) + "0.00,0,0,0,0,0,9.8,0,20,-40,1,0,0,0,0\n";
    // Each with the line and column of the field at fault (a missing one: past the row's end).
    const struct {
        const char* row;
        const char* expect;
    } cases[] = {
        {"0.01,0,0,0,0,0,9.8,0,20\n", ":3:24: expected 15 fields, got 9"},
        {"0.01,nan,0,0,0,0,9.8,0,20,-40,1,0,0,0,0\n", ":3:6: field 'gyr_x'"},
        {"0.00,0,0,0,0,0,9.8,0,20,-40,1,0,0,0,0\n", ":3:1: expected t to increase"},
        {"0.01,0,0,0,0,0,9.8,0,20,-40,1,0,0,0,2\n", ":3:37: field 'movement': expected 0 or 1"},
    };
    for (const auto& c : cases) {
        const auto p = writeText("caphub_broad_case.csv", base + c.row);
        auto t = readBroadCsv(p);
        std::filesystem::remove(p);
        ASSERT_FALSE(t) << c.row;
        EXPECT_NE(t.error().message.find(":3:"), std::string::npos) << t.error().message;
        EXPECT_NE(t.error().message.find(c.expect), std::string::npos) << t.error().message;
    }
}

TEST(BroadCsv, RefusesValuesNoSampleCanHoldWithTheirLineAndField) {
    // A reading past any sensor's range would be infinite as a recording's float; a time past
    // 1e6 s overflows the capture clock once multiplied by a rate.
    const auto acc = writeText("caphub_broad_acc_1e39.csv",
                               std::string(kHeader) + "0,0,0,0,0,0,9.8,20,0,-40,1,0,0,0,0\n" +
                                   "0.01,0,0,0,0,1e39,9.8,20,0,-40,1,0,0,0,0\n");
    auto a = readBroadCsv(acc);
    ASSERT_FALSE(a.ok());
    EXPECT_EQ(a.error().message, acc.string() +
                                     ":3:14: field 'acc_y': 1e39 is out of range "
                                     "(at most 1e+06 either way)");
    const auto t = writeText("caphub_broad_t_1e10.csv",
                             std::string(kHeader) + "0,0,0,0,0,0,9.8,20,0,-40,1,0,0,0,0\n" +
                                 "1e10,0,0,0,0,0,9.8,20,0,-40,1,0,0,0,0\n");
    auto b = readBroadCsv(t);
    ASSERT_FALSE(b.ok());
    EXPECT_EQ(b.error().message,
              t.string() + ":3:1: field 't': 1e10 is out of range (at most 1e+06 either way)");
}

TEST(BroadCsv, AFifoWithoutAWriterReadsAsEmptyInsteadOfWaiting) {
    const auto p = std::filesystem::temp_directory_path() /
                   ("caphub_broad_fifo_" + std::to_string(::getpid()));
    std::filesystem::remove(p);
    ASSERT_EQ(::mkfifo(p.c_str(), 0644), 0);
    auto r = readBroadCsv(p);  // returned at all: before, the open waited for a writer
    std::filesystem::remove(p);
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().message, p.string() +
                                     ":1:1: expected the header line, found the end of "
                                     "the file");
}

TEST(BroadCsv, RefusesAWrongHeader) {
    const auto p = writeText("caphub_broad_hdr.csv",
                             "t,gyr_x,gyr_y,gyr_z,acc_x,acc_y,acc_z,mag_x,mag_y,magz\n");
    auto t = readBroadCsv(p);
    std::filesystem::remove(p);
    ASSERT_FALSE(t);
    EXPECT_NE(t.error().message.find(":1:51: header column 10: expected 'mag_z', got 'magz'"),
              std::string::npos)
        << t.error().message;
}

TEST(BroadCsv, ReportsAMissingFile) {
    auto t = readBroadCsv("/nonexistent/caphub/trial.csv.gz");
    ASSERT_FALSE(t);
    EXPECT_NE(t.error().message.find("open '/nonexistent/caphub/trial.csv.gz'"), std::string::npos)
        << t.error().message;
}

TEST(BroadCsv, WritesGzipThatReadsBackTheSameTrial) {
    BroadTrial t;
    t.name = "roundtrip";
    t.rateHz = 285.714286;
    for (int i = 0; i < 50; ++i) {
        fusion::ImuSample s;
        s.tS = i * 0.0035;
        s.gyrRadS = Vec3d(0.001 * i, -0.5, 0.25);
        s.accMps2 = Vec3d(0.1, 9.79, -0.3);
        s.magUt = Vec3d(12.5, -30.0, 7.0 + i);
        t.samples.push_back(s);
        t.truth.push_back(i % 7 == 0 ? Quatd(NAN, NAN, NAN, NAN) : Quatd(1, 0, 0, 0));
        t.movement.push_back(i > 10);
    }
    const auto p = std::filesystem::temp_directory_path() / "caphub_broad_rt.csv.gz";
    ASSERT_TRUE(writeBroadCsv(p, t));
    auto back = readBroadCsv(p);
    std::filesystem::remove(p);
    ASSERT_TRUE(back) << back.error().message;
    EXPECT_EQ(back->name, "roundtrip");
    EXPECT_NEAR(back->rateHz, t.rateHz, 1e-6);
    ASSERT_EQ(back->samples.size(), t.samples.size());
    for (std::size_t i = 0; i < t.samples.size(); ++i) {
        // Nine significant digits are written.
        EXPECT_NEAR(back->samples[i].magUt.z(), t.samples[i].magUt.z(), 1e-7);
        EXPECT_EQ(back->movement[i], t.movement[i]);
        EXPECT_EQ(std::isnan(back->truth[i].w()), std::isnan(t.truth[i].w()));
    }
}

}  // namespace
}  // namespace caphub::firmware
