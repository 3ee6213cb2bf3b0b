// caphub fusion replay, run as a person would: a recording with a glitched sample.
#include <cmath>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include "tests/firmware/cli_run.h"

namespace {

using ::testing::HasSubstr;

using caphub::testing::caphub;
using caphub::testing::CliRun;

// 4 s at 100 Hz of a sensor lying still and flat, facing north, in the BROAD layout (IMU columns
// only); row `spikeRow` reads `gyrX` rad/s about x.
std::string writeStillTrial(const std::string& path, int spikeRow, double gyrX,
                            const std::string& rateHz = "100") {
    std::ofstream f(path);
    f << "# BROAD trial still_with_spike; sampling_rate_hz=" << rateHz << "\n";
    f << "t,gyr_x,gyr_y,gyr_z,acc_x,acc_y,acc_z,mag_x,mag_y,mag_z\n";
    for (int i = 0; i < 400; ++i) {
        f << i * 0.01 << ',' << (i == spikeRow ? gyrX : 0.0) << ",0,0,0,0,9.81,0,19,-45\n";
    }
    return path;
}

// The rows of an estimate file (t,qw,qx,qy,qz), as numbers.
std::vector<std::vector<double>> readEstimate(const std::string& path) {
    std::ifstream f(path);
    std::string line;
    std::getline(f, line);  // header
    std::vector<std::vector<double>> rows;
    while (std::getline(f, line)) {
        std::vector<double> row;
        std::stringstream ss(line);
        std::string field;
        while (std::getline(ss, field, ',')) {
            row.push_back(std::strtod(field.c_str(), nullptr));  // "-nan" reads as NaN
        }
        rows.push_back(row);
    }
    return rows;
}

TEST(CliFusionReplay, AGyroscopeSpikeIsRejectedAndTheEstimateStaysFinite) {
    const std::string dir =
        ::testing::TempDir() + "caphub-fusion-spike-" + std::to_string(getpid());
    const std::string in = writeStillTrial(dir + "-in.csv", 200, 5000.0);
    for (const std::string variant : {"", " --fixed"}) {
        const std::string out = dir + "-est.csv";
        const CliRun r = caphub("fusion replay --in " + in + " --out " + out + variant);
        ASSERT_EQ(r.exitCode, 0) << variant << ": " << r.output;
        EXPECT_THAT(r.output, HasSubstr("rejected 1 gyroscope sample")) << variant;
        const auto rows = readEstimate(out);
        ASSERT_EQ(rows.size(), 400U) << variant;
        for (std::size_t i = 0; i < rows.size(); ++i) {
            ASSERT_EQ(rows[i].size(), 5U) << variant << " row " << i;
            for (double v : rows[i]) {
                ASSERT_TRUE(std::isfinite(v)) << variant << " row " << i;
            }
            // The sensor never moves: the estimate stays level and north (w = 1 within a
            // 0.1 deg turn); 5000 rad/s for one 10 ms sample, had it been used, turns it by
            // 50 rad, and even the 64 rad/s the fixed-point format can hold by 37 deg.
            EXPECT_GT(std::abs(rows[i][1]), std::cos(0.5 * 0.1 * 0.017453292519943295))
                << variant << " row " << i;
        }
    }
}

// The file's rate sets the filter's sample period: one the filter cannot run at is an error
// that names the file, not a run on meaningless coefficients.
TEST(CliFusionReplay, ARateTheFilterCannotRunAtIsAnError) {
    const std::string in = writeStillTrial(
        ::testing::TempDir() + "caphub-fusion-rate-" + std::to_string(getpid()) + ".csv", -1, 0.0,
        "1e9");
    const CliRun r = caphub("fusion replay --in " + in);
    EXPECT_EQ(r.exitCode, 2) << r.output;  // the file given cannot be used
    EXPECT_THAT(r.output, HasSubstr(in));
    EXPECT_THAT(r.output, HasSubstr("cannot run at 1e+09 Hz"));
}

// caphub fusion cv on three copies of the shipped BROAD excerpt: every fold's training trials are
// the same data as its held-out one, so the held-out columns must equal the best-on-all ones.
TEST(CliFusionCv, HeldOutEqualsInSampleBestOnIdenticalTrials) {
    const std::string trial =
        std::string(CAPHUB_SOURCE_DIR) + "/tests/data/broad/21_fast_combined_excerpt.csv.gz";
    const CliRun r =
        caphub("fusion cv --no-fixed --in " + trial + " --in " + trial + " --in " + trial);
    ASSERT_EQ(r.exitCode, 0) << r.output;
    EXPECT_THAT(r.output, HasSubstr("leave-one-out over 3 trials: 27 parameter sets"));
    EXPECT_THAT(r.output, HasSubstr("leave-one-out (held-out)"));
    // The mean rows: "mean of 3" then nine numbers (defaults, best on all, held-out).
    std::istringstream in(r.output);
    std::string line;
    int meanRows = 0;
    while (std::getline(in, line)) {
        if (line.rfind("mean of 3", 0) != 0) {
            continue;
        }
        std::istringstream nums(line.substr(9));
        double v[9];
        for (double& x : v) {
            ASSERT_TRUE(nums >> x) << line;
        }
        for (int k = 0; k < 3; ++k) {
            EXPECT_EQ(v[3 + k], v[6 + k]) << line;
        }
        ++meanRows;
    }
    EXPECT_EQ(meanRows, 2);  // float at the file's rate and at 57 Hz
}

TEST(CliFusionCv, RefusesTooFewTrialsAndATrialWithoutGroundTruth) {
    const std::string trial =
        std::string(CAPHUB_SOURCE_DIR) + "/tests/data/broad/21_fast_combined_excerpt.csv.gz";
    CliRun r = caphub("fusion cv --in " + trial + " --in " + trial);
    EXPECT_EQ(r.exitCode, 2) << r.output;
    EXPECT_THAT(r.output, HasSubstr("at least 3"));
    const std::string noTruth = writeStillTrial(
        ::testing::TempDir() + "caphub-fusion-cv-" + std::to_string(getpid()) + ".csv", -1, 0.0);
    r = caphub("fusion cv --in " + trial + " --in " + trial + " --in " + noTruth);
    EXPECT_EQ(r.exitCode, 2) << r.output;
    EXPECT_THAT(r.output, HasSubstr(noTruth + " has no ground truth"));
}

}  // namespace

namespace {

// The non-causal estimate (fusion/smoother.h) on the shared BROAD excerpt: scored beside the
// causal filter, and more accurate there (its inclination from the forward and backward runs).
TEST(CliFusionReplay, TheSmoothedEstimateIsScoredBesideTheCausalOneAndBeatsItOnTheExcerpt) {
    const std::string in =
        std::string(CAPHUB_TEST_DATA_DIR) + "/broad/21_fast_combined_excerpt.csv.gz";
    const CliRun r = caphub("fusion replay --smooth --summary --in " + in);
    ASSERT_EQ(r.exitCode, 0) << r.output;
    std::istringstream lines(r.output);
    std::string line;
    double causal = -1;
    double smoothed = -1;
    while (std::getline(lines, line)) {
        if (line.rfind("mean of 1", 0) == 0) {
            std::istringstream fields(line.substr(9));
            fields >> causal >> smoothed;
        }
    }
    ASSERT_GT(causal, 0) << r.output;
    ASSERT_GT(smoothed, 0) << r.output;
    EXPECT_LT(smoothed, 0.9 * causal) << r.output;

    const std::string out =
        ::testing::TempDir() + "caphub-fusion-smooth-" + std::to_string(getpid()) + ".csv";
    ASSERT_EQ(caphub("fusion replay --smooth --in " + in + " --out " + out).exitCode, 0);
    const auto rows = readEstimate(out);
    ASSERT_EQ(rows.size(), 6000U);
    for (const auto& row : rows) {
        ASSERT_EQ(row.size(), 5U);
        const double n = std::hypot(std::hypot(row[1], row[2]), std::hypot(row[3], row[4]));
        ASSERT_NEAR(n, 1.0, 1e-6);
    }
}

}  // namespace
