// `caphub evaluate`: the body solver scored through the virtual suit's whole path (chip models,
// drivers, FusionStage, BodyStage with its T-pose calibration) against the simulation's ground
// truth, compared with the ideal-orientation evaluation of tests/body, and its command line.
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <gtest/gtest.h>

#include "board/loader.h"
#include "firmware/calibration_file.h"
#include "firmware/evaluation.h"
#include "tests/body/body_evaluation.h"
#include "tests/firmware/cli_run.h"

namespace {

using namespace caphub;
namespace fs = std::filesystem;

const fs::path kSource(CAPHUB_SOURCE_DIR);
const fs::path kWalk = kSource / "tests" / "data" / "bvh" / "cmu_12_01_walk.bvh";

board::Board simSuit() {
    return *board::loadBoardFile(kSource / "board" / "sim-suit.toml").board;
}

firmware::EvaluateOptions idealOptions(double strapDeg) {
    firmware::EvaluateOptions o;
    o.bvh = kWalk;
    o.profile = board::sim::ErrorProfile::Ideal;
    o.strapDeg = strapDeg;
    o.poseRateHz = 60;
    return o;
}

TEST(EvaluateThroughTheFilter, IdealSensorsComeCloseToTheIdealOrientationEvaluation) {
    const board::Board b = simSuit();
    auto real = firmware::evaluateClip(b, idealOptions(0));
    ASSERT_TRUE(real) << real.error().message;
    auto ideal = body::evaluation::scoreClip(kWalk, kSource / "board" / "sim-suit.toml", 60);
    ASSERT_TRUE(ideal) << ideal.error().message;
    const std::string tables = body::formatScoreTable(real->score) + "\nideal orientations:\n" +
                               body::evaluation::formatTable(*ideal);

    // Every scored pose is one of the clip's: 4.35 s at 60 Hz, less at most one pose per
    // sample that passes two grid points.
    EXPECT_NEAR(real->score.frames, 60 * 4.35, 10) << tables;
    // What the filter adds on ideal chips: the registers' quantisation, the inclination pulled
    // by the walk's accelerations, and orientations up to one sample period (1/~112 Hz) older
    // than the pose's grid time; at the limbs' rates of up to ~5 rad/s that is below 2.6 deg at
    // the worst instant and well below it on average. So each joint within 2 deg of the ideal
    // evaluation's error (the pelvis, whose world orientation carries the filter's whole
    // inclination and heading error, 0.45 deg measured), the mean within 0.75.
    for (int i = 0; i < body::kSegmentCount; ++i) {
        const auto u = static_cast<std::size_t>(i);
        EXPECT_NEAR(real->score.angleDeg[u], ideal->angleDeg[u], 2.0)
            << body::joints()[u].name << "\n"
            << tables;
    }
    EXPECT_NEAR(real->score.meanAngleDeg, ideal->meanAngleDeg, 0.75) << tables;
}

TEST(EvaluateThroughTheFilter, StrappedSensorsWithoutACalibrationScoreWorseThanAfterTheTPose) {
    const board::Board b = simSuit();
    auto calibrated = firmware::evaluateClip(b, idealOptions(10));
    ASSERT_TRUE(calibrated) << calibrated.error().message;
    firmware::EvaluateOptions none = idealOptions(10);
    none.calibrate.reset();
    auto nominal = firmware::evaluateClip(b, none);
    ASSERT_TRUE(nominal) << nominal.error().message;

    // The T-pose finds the strapped mountings (within a degree on ideal chips); the nominal
    // ones are the strapping error off (6.7 deg mean with seed 1), and every sensor-driven
    // joint inherits the error of its two segments.
    EXPECT_LT(calibrated->mountingErrorMeanDeg, 1.5);
    EXPECT_GT(nominal->mountingErrorMeanDeg, 4.0);
    EXPECT_GT(nominal->score.meanAngleDeg, calibrated->score.meanAngleDeg + 3.0)
        << body::formatScoreTable(calibrated->score) << "\nwithout calibration:\n"
        << body::formatScoreTable(nominal->score);
}

TEST(EvaluateThroughTheFilter, TheBodysAccelerationKeepsTheFiltersLevelAsTheWalkStarts) {
    // The lead-in's blend takes the subject from standing to walking at 0.9 m/s in 1.5 s. Every
    // filter that is not told takes that acceleration for a share of gravity and tilts forward
    // by about a degree for seconds (the pelvis: 1.29 deg mean measured); told the root's
    // acceleration from the foot contacts (BodyStage::Options::aidFilters), the pelvis is
    // within half a degree (0.45 measured), and the legs' joints sit closer to the truth.
    const board::Board b = simSuit();
    auto aided = firmware::evaluateClip(b, idealOptions(0));
    ASSERT_TRUE(aided) << aided.error().message;
    firmware::EvaluateOptions o = idealOptions(0);
    o.aidFilters = false;
    auto unaided = firmware::evaluateClip(b, o);
    ASSERT_TRUE(unaided) << unaided.error().message;
    const std::string tables = body::formatScoreTable(aided->score) + "\nnot aided:\n" +
                               body::formatScoreTable(unaided->score);
    EXPECT_GT(unaided->score.angleDeg[0], 1.0) << tables;
    EXPECT_LT(aided->score.angleDeg[0], 0.6) << tables;
    EXPECT_LT(aided->score.independentMeanPositionM,
              unaided->score.independentMeanPositionM - 0.002)
        << tables;
}

TEST(EvaluateThroughTheFilter, ThePapersSeventeenJointsMeetTheTargetsOnBothClipsAfterCalibration) {
    // The command on the `typical` profile: the sensors calibrated on the virtual suit
    // (`caphub calibrate gyro|accel|mag` into one file, in that order), then both shared clips
    // through fusion and body after the T-pose calibration. Targets: mean joint angle error
    // <= 3 deg and mean joint position error <= 2 cm from the root, on the paper's 17 joints
    // (measured with seed 1: 1.108 deg / 1.760 cm and 2.611 deg / 1.543 cm). The drift target
    // is not met on cmu_12_01 (docs/skeleton.md) and is not asserted here.
    const fs::path cal = fs::temp_directory_path() / "caphub_evaluate_targets_cal.toml";
    fs::remove(cal);
    for (const char* what : {"gyro", "accel", "mag"}) {
        const auto r =
            caphub::testing::caphub(std::string("calibrate ") + what + " --file " + cal.string());
        ASSERT_EQ(r.exitCode, 0) << r.output;
    }
    const board::Board b = simSuit();
    auto set = firmware::readCalibrationFile(cal);
    fs::remove(cal);
    ASSERT_TRUE(set) << set.error().message;
    for (const char* clip : {"cmu_12_01_walk.bvh", "cmu_131_01_start_walk_stop.bvh"}) {
        firmware::EvaluateOptions o;
        o.bvh = kSource / "tests" / "data" / "bvh" / clip;
        o.sensorCalibrations = firmware::calibrationsFor(b, *set, nullptr);
        auto r = firmware::evaluateClip(b, o);
        ASSERT_TRUE(r) << r.error().message;
        const std::string table = body::formatScoreTable(r->score);
        EXPECT_GT(r->score.frames, 200) << clip;
        EXPECT_LE(r->score.independentMeanAngleDeg, 3.0) << clip << "\n" << table;
        EXPECT_LE(r->score.independentMeanPositionM, 0.02) << clip << "\n" << table;
    }
}

TEST(EvaluateThroughTheFilter, RejectsABoardWithRealBuses) {
    const board::Board b = *board::loadBoardFile(kSource / "board" / "rpi4-suit.toml").board;
    auto r = firmware::evaluateClip(b, idealOptions(0));
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, EINVAL);
    EXPECT_NE(r.error().message.find("real buses"), std::string::npos) << r.error().message;
}

TEST(EvaluateThroughTheFilter, RejectsAMalformedClipWithItsFileAndLine) {
    const board::Board b = simSuit();
    firmware::EvaluateOptions o = idealOptions(0);
    const fs::path bad = fs::temp_directory_path() / "caphub_evaluate_test_bad.bvh";
    {
        std::ofstream f(bad);
        f << "HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0\n";
    }
    o.bvh = bad;
    auto r = firmware::evaluateClip(b, o);
    fs::remove(bad);
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, EINVAL);
    EXPECT_NE(r.error().message.find("caphub_evaluate_test_bad.bvh: line 4"), std::string::npos)
        << r.error().message;
}

TEST(EvaluateCli, PrintsThePipelineFactsAndThePerJointTable) {
    const fs::path json = fs::temp_directory_path() / "caphub_evaluate_test.json";
    const auto r = caphub::testing::caphub("evaluate --profile ideal --bvh " + kWalk.string() +
                                           " --json " + json.string());
    EXPECT_EQ(r.exitCode, 0) << r.output;
    EXPECT_NE(r.output.find("samples through fusion and body"), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("body calibration: tpose; mountings off the true"), std::string::npos)
        << r.output;
    EXPECT_NE(r.output.find("| joint | segment | angle error (deg) | position error (cm) |"),
              std::string::npos)
        << r.output;
    EXPECT_NE(r.output.find("| l_knee | l_calf |"), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("| vl5+vt12 | pelvis - t12 |"), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("| **mean** |"), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("root: true horizontal path"), std::string::npos) << r.output;
    std::ifstream in(json);
    std::stringstream text;
    text << in.rdbuf();
    EXPECT_NE(text.str().find("\"clip\": \"cmu_12_01_walk.bvh\""), std::string::npos) << text.str();
    EXPECT_NE(text.str().find("\"joint\": \"r_metatarsophalangeal\""), std::string::npos);
    EXPECT_NE(text.str().find("\"joint\": \"vl5+vt12\""), std::string::npos);
    EXPECT_NE(text.str().find("\"independent_mean_angle_deg\": "), std::string::npos);
    EXPECT_NE(text.str().find("\"gyro_clipped\": {\"pelvis\": 0,"), std::string::npos);
    fs::remove(json);
}

TEST(EvaluateCli, RejectsAMissingClipWithExitCode2) {
    const auto r = caphub::testing::caphub("evaluate --bvh /nonexistent/walk.bvh");
    EXPECT_EQ(r.exitCode, 2) << r.output;
    EXPECT_NE(r.output.find("'/nonexistent/walk.bvh': no such file"), std::string::npos)
        << r.output;
}

TEST(EvaluateCli, RejectsAnUnknownBoardWithExitCode2) {
    const auto r =
        caphub::testing::caphub("evaluate --board /nonexistent/suit.toml --bvh " + kWalk.string());
    EXPECT_EQ(r.exitCode, 2) << r.output;
}

TEST(EvaluateCli, RejectsAnUnknownCalibrationWithExitCode2) {
    const auto r = caphub::testing::caphub("evaluate --calibrate apose --bvh " + kWalk.string());
    EXPECT_EQ(r.exitCode, 2) << r.output;
    EXPECT_NE(r.output.find("expected tpose, npose or none"), std::string::npos) << r.output;
}

}  // namespace
