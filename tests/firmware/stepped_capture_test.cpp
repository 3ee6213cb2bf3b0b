// The virtual suit's whole path (motion -> IMU model -> chip models -> buses -> drivers -> bus
// workers) on a stepped clock: what the drivers deliver is the physical truth up to the chips'
// quantisation, stamped with the right instants, and the same seed gives the same run.
#include "firmware/runtime/stepped_capture.h"

#include <chrono>
#include <cmath>
#include <filesystem>
#include <map>
#include <vector>

#include <gtest/gtest.h>

#include "board/loader.h"
#include "board/sim/virtual_suit.h"

namespace {

using namespace caphub;
using namespace std::chrono_literals;
namespace bs = board::sim;

const std::filesystem::path kSource(CAPHUB_SOURCE_DIR);

struct WalkRun {
    board::Board board;
    SimulatedClock clock{Timestamp{1s}};
    Timestamp start = clock.now();
    bs::ClipSuit clip;
    board::SuitHardware suit;
    std::vector<firmware::SensorSample> samples;

    WalkRun(const char* boardFile, bs::ErrorProfile profile, std::uint64_t seed,
            double chipDelayS = 0) {
        auto loaded = board::loadBoardFile(kSource / "board" / boardFile);
        board = *loaded.board;
        bs::ClipOptions o;
        o.bvh = kSource / "tests" / "data" / "bvh" / "cmu_12_01_walk.bvh";
        o.profile = profile;
        o.seed = seed;
        o.chipDelayS = chipDelayS;
        auto c = bs::clipSources(o, start);
        clip = std::move(*c);
        auto hw = bs::buildVirtualSuit(board, clock, clip.sources);
        suit = std::move(*hw);
    }

    void run(Duration d) {
        firmware::SteppedCapture capture(suit, clock);
        capture.runUntil(start + d,
                         [this](const firmware::SensorSample& s) { samples.push_back(s); });
    }
};

// One LSB of the sim boards' ranges: +-2000 dps and +-16 g over 16 bits; the AK09916's 0.15 uT.
constexpr double kGyroLsbRadS = 2000.0 / 32768.0 * hal::kPi / 180.0;
constexpr double kAccelLsbMps2 = 16.0 * hal::kStandardGravity / 32768.0;
constexpr double kMagLsbUt = 0.15;

// A sample's gyroscope and accelerometer within half an LSB of the signals (rounding to the
// nearest count, plus float rounding of the SI value).
::testing::AssertionResult readsWithinHalfAnLsb(const firmware::SensorSample& s,
                                                const bs::ImuSignals& truth) {
    for (int a = 0; a < 3; ++a) {
        if (std::abs(s.sample.gyrRadps[a] - truth.gyroRadS[a]) > 0.5 * kGyroLsbRadS * 1.001 ||
            std::abs(s.sample.accMps2[a] - truth.accelMps2[a]) > 0.5 * kAccelLsbMps2 * 1.001) {
            return ::testing::AssertionFailure()
                   << "sensor " << s.sensor << " axis " << a << ": gyro " << s.sample.gyrRadps[a]
                   << " against " << truth.gyroRadS[a] << ", accel " << s.sample.accMps2[a]
                   << " against " << truth.accelMps2[a];
        }
    }
    return ::testing::AssertionSuccess();
}

TEST(SteppedCapture, IdealSuitReadsThePhysicalTruthWithinHalfAnLsb) {
    WalkRun r("sim-suit.toml", bs::ErrorProfile::Ideal, 3);
    r.run(3s);
    std::vector<bs::SensorPlacement> placement;
    for (std::size_t i = 0; i < r.board.sensors.size(); ++i) {
        placement.push_back(r.clip.placement(r.board.sensors[i], static_cast<int>(i)));
    }
    std::map<int, int> perSensor;
    int magReadings = 0;
    bs::SegmentState seg;
    for (const auto& s : r.samples) {
        const auto& p = placement[static_cast<std::size_t>(s.sensor)];
        r.clip.motion->evaluate(p.segment, toNs(s.sample.t - r.start), seg);
        const bs::ImuSignals truth = bs::idealSignals(seg, p, r.clip.environment);
        ASSERT_TRUE(readsWithinHalfAnLsb(s, truth));
        // The magnetometer samples at its own instants (100 Hz continuous mode, read with the
        // next accel/gyro sample): it is checked against the field at the sample's instant within
        // what the field changes in one of its periods at walking rotation rates (< 6 uT).
        if ((s.sample.flags & hal::ImuSample::kMagFresh) != 0) {
            ++magReadings;
            EXPECT_NEAR((s.sample.magUt.cast<double>() - truth.magUt).norm(), 0.0, 6.0 + kMagLsbUt);
        }
        ++perSensor[s.sensor];
    }
    EXPECT_EQ(perSensor.size(), 17u);
    for (const auto& [sensor, n] : perSensor) {
        // 3 s at 100 Hz, less the start-up (a reset and configuration, under 0.3 s).
        EXPECT_GE(n, 270) << "sensor " << sensor;
        EXPECT_LE(n, 300) << "sensor " << sensor;
    }
    EXPECT_GT(magReadings, 17 * 200);
}

TEST(SteppedCapture, ADelayedChipReadsTheMotionThatLongBeforeItsSample) {
    // --chip-delay-ms: each reading is the truth 8 ms before the sample's time (within half an
    // LSB), which at walking rates is more than an LSB off the truth at the sample's time.
    constexpr double kDelayS = 0.008;
    WalkRun r("sim-upper10.toml", bs::ErrorProfile::Ideal, 3, kDelayS);
    r.run(2s);
    ASSERT_GT(r.samples.size(), 800u);  // 10 sensors, 2 s at 100 Hz less the start-up
    int offNow = 0;
    bs::SegmentState then;
    bs::SegmentState now;
    for (const auto& s : r.samples) {
        const bs::SensorPlacement p =
            r.clip.placement(r.board.sensors[static_cast<std::size_t>(s.sensor)], s.sensor);
        const std::int64_t tNs = toNs(s.sample.t - r.start);
        r.clip.motion->evaluate(p.segment, tNs - static_cast<std::int64_t>(kDelayS * 1e9), then);
        r.clip.motion->evaluate(p.segment, tNs, now);
        const bs::ImuSignals delayed = bs::idealSignals(then, p, r.clip.environment);
        const bs::ImuSignals current = bs::idealSignals(now, p, r.clip.environment);
        ASSERT_TRUE(readsWithinHalfAnLsb(s, delayed));
        if ((s.sample.gyrRadps.cast<double>() - current.gyroRadS).cwiseAbs().maxCoeff() >
            2 * kGyroLsbRadS) {
            ++offNow;
        }
    }
    EXPECT_GT(offNow, static_cast<int>(r.samples.size()) / 2);
}

TEST(SteppedCapture, SameSeedGivesTheSameSamplesAndAnotherSeedDoesNot) {
    WalkRun a("sim-upper10.toml", bs::ErrorProfile::Typical, 7);
    WalkRun b("sim-upper10.toml", bs::ErrorProfile::Typical, 7);
    WalkRun c("sim-upper10.toml", bs::ErrorProfile::Typical, 8);
    a.run(1s);
    b.run(1s);
    c.run(1s);
    ASSERT_EQ(a.samples.size(), b.samples.size());
    ASSERT_GT(a.samples.size(), 300u);
    int differing = 0;
    for (std::size_t i = 0; i < a.samples.size(); ++i) {
        EXPECT_EQ(a.samples[i].sensor, b.samples[i].sensor);
        EXPECT_EQ(a.samples[i].sample.t, b.samples[i].sample.t);
        EXPECT_EQ(a.samples[i].sample.gyrRadps, b.samples[i].sample.gyrRadps);
        EXPECT_EQ(a.samples[i].sample.accMps2, b.samples[i].sample.accMps2);
        if (i < c.samples.size() && c.samples[i].sample.gyrRadps != a.samples[i].sample.gyrRadps) {
            ++differing;
        }
    }
    EXPECT_GT(differing, static_cast<int>(a.samples.size()) / 2);
}

TEST(SteppedCapture, StrappedMountingsAreOffTheNominalOnesByRealisticAngles) {
    WalkRun r("sim-suit.toml", bs::ErrorProfile::Typical, 1);
    int offByMoreThanOneDegree = 0;
    for (std::size_t i = 0; i < r.board.sensors.size(); ++i) {
        const Quatd truth = r.clip.placement(r.board.sensors[i], static_cast<int>(i)).mounting;
        const double deg = truth.angularDistance(r.board.sensors[i].mounting) * 180.0 / hal::kPi;
        EXPECT_LE(deg, 30.0 + 1e-9);  // capped at three times the 10-degree scale
        offByMoreThanOneDegree += deg > 1.0;
    }
    // A half-normal of scale 10 degrees is under 1 degree with probability 8 %.
    EXPECT_GE(offByMoreThanOneDegree, 12);
    EXPECT_TRUE(bs::strappedMounting(Quatd::Identity(), 0.0, 1, 0).isApprox(Quatd::Identity()));
}

}  // namespace
