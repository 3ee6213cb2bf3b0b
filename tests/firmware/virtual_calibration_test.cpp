// Calibrating on the virtual suit, through the whole path (scripted motion -> IMU model -> chip
// models -> drivers -> bus workers): the calibration algorithms recover each simulated part's
// true errors (the ones the same seed gives it when it plays a clip).
#include <chrono>
#include <filesystem>
#include <vector>

#include <Eigen/SVD>
#include <gtest/gtest.h>

#include "board/loader.h"
#include "board/sim/virtual_suit.h"
#include "firmware/runtime/stepped_capture.h"
#include "fusion/calibration/accel_six_position.h"
#include "fusion/calibration/ellipsoid_fit.h"
#include "fusion/calibration/gyro_bias.h"
#include "fusion/calibration/imu_axes.h"

namespace {

using namespace caphub;
using namespace std::chrono_literals;
namespace bs = board::sim;

const std::filesystem::path kSource(CAPHUB_SOURCE_DIR);
constexpr double kDeg = hal::kPi / 180.0;

struct Recorded {
    board::Board board;
    std::vector<bs::ImuConstants> truth;
    std::vector<std::vector<Vec3d>> gyr, acc, mag;
};

Recorded record(bs::Script script, double seconds) {
    Recorded r;
    r.board = *board::loadBoardFile(kSource / "board" / "sim-upper10.toml").board;
    const std::size_t n = r.board.sensors.size();
    r.gyr.resize(n);
    r.acc.resize(n);
    r.mag.resize(n);
    SimulatedClock clock(Timestamp{1s});
    const Timestamp start = clock.now() + 500ms;
    bs::ScriptOptions o;
    o.script = script;
    o.timing.tumbleS = seconds;
    o.seed = 5;
    const bs::ScriptedSuit scripted = bs::scriptedSources(o, start);
    auto suit = bs::buildVirtualSuit(r.board, clock, scripted.sources);
    for (std::size_t i = 0; i < n; ++i) {
        const auto& sc = r.board.sensors[i];
        const bs::VirtualImu part(
            *scripted.motion, scripted.environment, scripted.placement(sc, static_cast<int>(i)),
            *bs::errorSpec(sc.chip->name, o.profile), bs::partSeed(o.seed, static_cast<int>(i)),
            sc.achievedOdrHz, sc.magOdrHz > 0 ? sc.magOdrHz : sc.achievedOdrHz);
        r.truth.push_back(part.constants());
    }
    firmware::SteppedCapture capture(*suit, clock);
    capture.runUntil(start + durationFromSeconds(seconds), [&](const firmware::SensorSample& s) {
        if (s.sample.t < start) {
            return;
        }
        const auto i = static_cast<std::size_t>(s.sensor);
        r.gyr[i].push_back(s.sample.gyrRadps.cast<double>());
        r.acc[i].push_back(s.sample.accMps2.cast<double>());
        if ((s.sample.flags & hal::ImuSample::kMagFresh) != 0) {
            r.mag[i].push_back(s.sample.magUt.cast<double>());
        }
    });
    return r;
}

TEST(VirtualCalibration, GyroBiasAtRestIsTheTrueTurnOnBias) {
    const Recorded r = record(bs::Script::Rest, 5.0);
    for (std::size_t i = 0; i < r.truth.size(); ++i) {
        const auto est = fusion::estimateGyroBias(r.gyr[i]);
        ASSERT_TRUE(est) << est.error().message;
        // 250 samples (50 Hz) of 0.015 dps/sqrt(Hz) noise: the mean's error is 0.004 dps; the
        // bias drift over 5 s adds less; 0.03 dps (a quarter of an LSB step of the mean) bounds
        // both with margin, and is far below the turn-on biases of up to 5 dps.
        EXPECT_LT((est->biasRadS - r.truth[i].gyroBiasRadS).norm(), 0.03 * kDeg) << i;
    }
}

TEST(VirtualCalibration, SixPositionsGiveTheTrueAccelerometerOffsetAndScale) {
    const Recorded r = record(bs::Script::SixPositions, 25.5);
    for (std::size_t i = 0; i < r.truth.size(); ++i) {
        const double rateHz = r.board.sensors[i].achievedOdrHz;
        const auto means = fusion::findSixPositions(r.acc[i], r.gyr[i], rateHz);
        ASSERT_TRUE(means) << means.error().message;
        const auto est = fusion::calibrateAccelSixPosition(*means);
        ASSERT_TRUE(est) << est.error().message;
        // The model has cross-axis terms (2 %) the six-position fit does not: they tilt each
        // position's reading by up to 0.2 m/s^2 off its axis but move its axis component by
        // 0.02 % only; with noise and the 0.0048 m/s^2 LSB the offsets come within 0.01 m/s^2.
        EXPECT_LT((est->offsetMps2 - r.truth[i].accelBiasMps2).norm(), 0.01) << i;
        EXPECT_LT((est->scale - r.truth[i].accelMatrix.diagonal()).cwiseAbs().maxCoeff(), 0.001)
            << i;
    }
}

TEST(VirtualCalibration, FourteenPositionsGiveTheTrueAccelerometerAndGyroscopeAxes) {
    const Recorded r = record(bs::Script::FourteenPositions, 14 * 3.0 + 13 * 1.5);
    for (std::size_t i = 0; i < r.truth.size(); ++i) {
        const double rateHz = r.board.sensors[i].achievedOdrHz;
        const auto held = fusion::findHeldPositions(r.acc[i], r.gyr[i], rateHz);
        ASSERT_TRUE(held) << held.error().message;
        ASSERT_EQ(held->size(), 14u) << i;
        std::vector<Vec3d> means;
        for (const auto& h : *held) {
            means.push_back(h.meanAccMps2);
        }
        const auto acc = fusion::calibrateAccelAxes(means);
        ASSERT_TRUE(acc) << acc.error().message;
        EXPECT_LT((acc->offsetMps2 - r.truth[i].accelBiasMps2).norm(), 0.01) << i;
        // The part reads raw = M f + b: the calibrated A M must be a rotation (the frame the
        // accelerometer defines) within 0.1 % (its scale and cross-axis errors are 0.5 % and 2 %).
        const Eigen::Matrix3d p = acc->matrix * r.truth[i].accelMatrix;
        EXPECT_LT((p.transpose() * p - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff(), 1e-3)
            << i;
        // The gyroscope (1.5 % scale, 2 % cross-axis) must read rates in that same frame:
        // G Mg = the rotation of A M, within 0.2 %.
        const auto gyro = fusion::calibrateGyroAxes(r.gyr[i], rateHz, *held, *acc);
        ASSERT_TRUE(gyro) << gyro.error().message;
        const Eigen::JacobiSVD<Eigen::Matrix3d> svd(p, Eigen::ComputeFullU | Eigen::ComputeFullV);
        const Eigen::Matrix3d frame = svd.matrixU() * svd.matrixV().transpose();
        EXPECT_LT((gyro->matrix * r.truth[i].gyroMatrix - frame).cwiseAbs().maxCoeff(), 2e-3) << i;
        EXPECT_LT(gyro->residualDeg, 0.1 * gyro->uncalibratedDeg) << i;
    }
}

TEST(VirtualCalibration, TumbleGivesTheTrueHardIronAndFieldWithin2Percent) {
    const Recorded r = record(bs::Script::Tumble, 40.0);
    for (std::size_t i = 0; i < r.truth.size(); ++i) {
        const auto est = fusion::fitEllipsoid(r.mag[i]);
        ASSERT_TRUE(est) << est.error().message;
        EXPECT_GT(est->coverage, 0.9) << i;
        // The hard iron (offsets of up to a few hundred uT) within 2 % of the 50 uT field.
        EXPECT_LT((est->hardIronUt - r.truth[i].magOffsetUt).norm(), 0.02 * 50.0) << i;
        // softIron undoes the part's matrix up to the fitted norm's scale: their product is a
        // multiple of the identity within 2 %.
        const Eigen::Matrix3d p = est->softIron * r.truth[i].magMatrix;
        const double s = p.trace() / 3.0;
        EXPECT_LT((p / s - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff(), 0.02) << i;
    }
}

}  // namespace
