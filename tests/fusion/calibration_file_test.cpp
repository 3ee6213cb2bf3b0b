// The calibration file: a written set reads back identically; bad files name file, line, key.
#include "firmware/calibration_file.h"

#include <filesystem>

#include <fmt/format.h>
#include <gtest/gtest.h>

namespace caphub::firmware {
namespace {

CalibrationSet sampleSet() {
    CalibrationSet set;
    fusion::SensorCalibration a;
    a.hasGyro = true;
    a.gyroBiasRadS = Vec3d(0.001, -0.0021, 1.0 / 3.0);
    a.hasAccel = true;
    a.accOffsetMps2 = Vec3d(0.05, -0.02, 0.1);
    a.accMatrix << 0.998, 0.01, 0.0, 0.01, 1.002, -0.003, 0.0, -0.003, 0.999;
    a.hasGyroAxes = true;
    a.gyroMatrix << 1.01, 0.02, 0.0, -0.01, 0.99, 0.01, 0.004, 0.0, 2.0 / 3.0;
    a.hasMag = true;
    a.magHardIronUt = Vec3d(12.0, -3.5, 40.2);
    a.magSoftIron << 1.01, 0.02, 0.0, 0.02, 0.99, 0.01, 0.0, 0.01, 1.0;
    a.magQualityPct = 0.8;
    a.magCoverage = 0.92;
    set["l_forearm"] = a;
    fusion::SensorCalibration b;
    b.hasGyro = true;
    b.gyroBiasRadS = Vec3d(-0.004, 0.0, 0.002);
    set["pelvis 2"] = b;  // a name that needs quoting
    return set;
}

TEST(CalibrationFile, ReadsBackWhatItWroteExactly) {
    const auto path = std::filesystem::temp_directory_path() / "caphub_calibration_test.toml";
    const CalibrationSet set = sampleSet();
    ASSERT_TRUE(writeCalibrationFile(path, set));
    auto back = readCalibrationFile(path);
    std::filesystem::remove(path);
    ASSERT_TRUE(back) << back.error().message;
    ASSERT_EQ(back->size(), 2u);
    const auto& a = back->at("l_forearm");
    const auto& e = set.at("l_forearm");
    EXPECT_EQ(a.gyroBiasRadS, e.gyroBiasRadS);  // 17 significant digits: exact
    EXPECT_EQ(a.accOffsetMps2, e.accOffsetMps2);
    EXPECT_EQ(a.accMatrix, e.accMatrix);
    EXPECT_TRUE(a.hasGyroAxes);
    EXPECT_EQ(a.gyroMatrix, e.gyroMatrix);
    EXPECT_EQ(a.magSoftIron, e.magSoftIron);
    EXPECT_EQ(a.magCoverage, e.magCoverage);
    const auto& b = back->at("pelvis 2");
    EXPECT_TRUE(b.hasGyro);
    EXPECT_FALSE(b.hasGyroAxes);
    EXPECT_FALSE(b.hasAccel);
    EXPECT_FALSE(b.hasMag);
}

TEST(CalibrationFile, ReadsThePerAxisScaleOfEarlierFilesAsADiagonalMatrix) {
    auto r = parseCalibration(
        "format = 1\n[sensors.a]\nacc_offset_m_s2 = [0.1, 0, 0]\nacc_scale = [1.25, 2, 0.5]\n",
        "c.toml");
    ASSERT_TRUE(r) << r.error().message;
    const auto& a = r->at("a");
    EXPECT_TRUE(a.hasAccel);
    EXPECT_EQ(a.accMatrix, Eigen::Matrix3d(Eigen::Vector3d(0.8, 0.5, 2.0).asDiagonal()));
    auto both = parseCalibration(
        "format = 1\n[sensors.a]\nacc_scale = [1, 1, 1]\n"
        "acc_matrix = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\n",
        "c.toml");
    ASSERT_FALSE(both);
    EXPECT_NE(both.error().message.find("not both"), std::string::npos) << both.error().message;
}

TEST(CalibrationFile, NamesTheLineAndKeyOfAWrongValue) {
    const std::string text =
        "format = 1\n"
        "[sensors.head]\n"
        "gyro_bias_rad_s = [0.1, 0.2]\n";
    auto r = parseCalibration(text, "cal.toml");
    ASSERT_FALSE(r);
    EXPECT_NE(r.error().message.find("cal.toml:3:"), std::string::npos) << r.error().message;
    EXPECT_NE(r.error().message.find("sensors.head.gyro_bias_rad_s"), std::string::npos)
        << r.error().message;
}

TEST(CalibrationFile, RefusesUnknownKeysAndOtherFormats) {
    auto r = parseCalibration("format = 1\n[sensors.head]\ngyro_bias = [0, 0, 0]\n", "c.toml");
    ASSERT_FALSE(r);
    EXPECT_NE(r.error().message.find("unknown key"), std::string::npos) << r.error().message;
    auto v = parseCalibration("format = 7\n", "c.toml");
    ASSERT_FALSE(v);
    EXPECT_NE(v.error().message.find("c.toml:1:"), std::string::npos) << v.error().message;
}

TEST(CalibrationFile, ReportsTomlSyntaxErrorsWithTheirPosition) {
    auto r = parseCalibration("format = 1\n[sensors.head\n", "c.toml");
    ASSERT_FALSE(r);
    EXPECT_NE(r.error().message.find("c.toml:2:"), std::string::npos) << r.error().message;
}

TEST(CalibrationFile, RefusesASingularMatrix) {
    for (const char* key : {"mag_soft_iron", "acc_matrix", "gyro_matrix"}) {
        auto r = parseCalibration(fmt::format("format = 1\n[sensors.a]\n{} = [[1, 0, 0], [0, 0, "
                                              "0], [0, 0, 1]]\n",
                                              key),
                                  "c.toml");
        ASSERT_FALSE(r) << key;
        EXPECT_NE(r.error().message.find("singular"), std::string::npos) << r.error().message;
        EXPECT_NE(r.error().message.find(key), std::string::npos) << r.error().message;
    }
}

// A damaged file or a typing slip: values no sensor has are refused with their line and key,
// not applied to every sample (a bias of 1e300 made every corrected sample overflow).
TEST(CalibrationFile, RefusesValuesNoSensorHas) {
    const struct {
        const char* line;
        const char* says;
    } cases[] = {
        {"gyro_bias_rad_s = [1e300, 0, 0]", "beyond what a sensor has"},
        {"gyro_bias_rad_s = [0, -0.6, 0]", "beyond what a sensor has"},
        {"acc_offset_m_s2 = [0, 0, 9.81]", "beyond what a sensor has"},
        {"mag_hard_iron_ut = [0, 1e6, 0]", "beyond what a sensor has"},
        {"acc_scale = [1, 1, 1e-3]", "expected scales from 0.5 to 2"},
        {"acc_matrix = [[1e9, 0, 0], [0, 1, 0], [0, 0, 1]]", "the matrix scales by"},
        {"gyro_matrix = [[0, 1, 0], [-3, 0, 0], [0, 0, 1]]", "the matrix scales by"},
        {"mag_soft_iron = [[100, 0, 0], [0, 100, 0], [0, 0, 100]]", "the matrix scales by"},
        {"mag_coverage = 3", "expected 0 to 1"},
        {"mag_quality_pct = -1", "expected 0 to 100"},
    };
    for (const auto& c : cases) {
        auto r = parseCalibration(fmt::format("format = 1\n[sensors.a]\n{}\n", c.line), "c.toml");
        ASSERT_FALSE(r) << c.line;
        EXPECT_NE(r.error().message.find("c.toml:3:"), std::string::npos) << r.error().message;
        EXPECT_NE(r.error().message.find(c.says), std::string::npos) << r.error().message;
    }
    // What the calibrators write (a rotation within the axes matrix included) is read.
    auto ok = parseCalibration(
        "format = 1\n[sensors.a]\ngyro_bias_rad_s = [0.1, -0.05, 0.02]\n"
        "gyro_matrix = [[0, 1.02, 0], [-0.98, 0, 0], [0, 0, 1]]\n"
        "acc_offset_m_s2 = [0.4, -0.3, 1.0]\nmag_hard_iron_ut = [300, -40, 1200]\n"
        "mag_soft_iron = [[1.3, 0.1, 0], [0.1, 0.7, 0], [0, 0, 1]]\n"
        "mag_quality_pct = 1.5\nmag_coverage = 0.92\n",
        "c.toml");
    EXPECT_TRUE(ok) << ok.error().message;
}

}  // namespace
}  // namespace caphub::firmware
