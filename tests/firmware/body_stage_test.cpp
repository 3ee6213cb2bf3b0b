// The body stage on the virtual suit: the subject stands in the T-pose while the filters settle,
// the stage calibrates the mountings from it (finding the sensors' true, strapped mountings far
// better than the board's nominal ones), then solves a pose per frame at the output rate; the
// preview renders those poses on its own thread.
#include "firmware/runtime/body_stage.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <limits>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <gtest/gtest.h>
#include <unistd.h>

#include "board/loader.h"
#include "board/sim/virtual_suit.h"
#include "firmware/reprocess.h"
#include "firmware/runtime/fusion_stage.h"
#include "firmware/runtime/preview_stage.h"
#include "firmware/runtime/stepped_capture.h"

namespace {

using namespace caphub;
using namespace std::chrono_literals;
namespace bs = board::sim;

const std::filesystem::path kSource(CAPHUB_SOURCE_DIR);

// The virtual subject holds `pose` for 4 s, the stage calibrates in it, then the clip plays;
// each sensor's calibrated mounting is compared with its true (strapped) one.
void calibrateInPose(body::ReferencePoseKind pose, body::CalibrationMethod method) {
    const board::Board b = *board::loadBoardFile(kSource / "board" / "sim-suit.toml").board;
    SimulatedClock clock(Timestamp{1s});
    bs::ClipOptions o;
    o.bvh = kSource / "tests" / "data" / "bvh" / "cmu_12_01_walk.bvh";
    o.profile = bs::ErrorProfile::Ideal;
    o.tposeHoldS = 4.0;
    o.leadInPose = body::referencePose(pose);
    auto clip = bs::clipSources(o, clock.now());
    ASSERT_TRUE(clip) << clip.error().message;
    auto suit = bs::buildVirtualSuit(b, clock, clip->sources);
    ASSERT_TRUE(suit) << suit.error().message;

    firmware::FusionStage fusion(b, nullptr);
    firmware::BodyStage::Options bo;
    bo.rateHz = 50;
    bo.calibrate = pose;
    firmware::BodyStage bodyStage(b, fusion, nullptr, clock, bo);
    firmware::SteppedCapture capture(*suit, clock);
    const Timestamp start = clock.now();
    capture.runUntil(start + 8s, [&](const firmware::SensorSample& s) {
        fusion.onSample(s);
        bodyStage.onSample(s);
    });

    ASSERT_TRUE(bodyStage.calibrated()) << bodyStage.calibrationError();
    EXPECT_EQ(bodyStage.calibration().method, method);
    double calibrated = 0;
    double nominal = 0;
    for (std::size_t i = 0; i < b.sensors.size(); ++i) {
        const auto& sc = b.sensors[i];
        const Quatd truth = clip->placement(sc, static_cast<int>(i)).mounting;
        const double e =
            bodyStage.calibration().mounting[static_cast<std::size_t>(sc.segment)].angularDistance(
                truth);
        // Each sensor's calibrated mounting within 6 deg of the truth: what the filters' heading
        // has converged to 3 s after start-up bounds it (docs/body-calibration.md).
        EXPECT_LT(e * 180 / hal::kPi, 6.0) << sc.name;
        calibrated += e;
        nominal += sc.mounting.angularDistance(truth);
    }
    // On average far closer than the nominal mountings (which are the strapping error off).
    EXPECT_LT(calibrated, 0.5 * nominal);
    // Calibrated after 2.5 + 1 s of the 8 s (the first samples come ~0.2 s in), then 50 Hz.
    EXPECT_NEAR(static_cast<double>(bodyStage.poses()), 50 * (8.0 - 3.7), 15);
}

TEST(FusionStage, CountsTheEpisodesOfGyroscopeClippingPerSensor) {
    const board::Board b = *board::loadBoardFile(kSource / "board" / "sim-suit.toml").board;
    firmware::FusionStage fusion(b, nullptr);
    firmware::SensorSample s;
    s.sample.accMps2 = Eigen::Vector3f(0, 0, 9.81f);
    s.sample.gyrRadps = Eigen::Vector3f(34.9f, 0, 0);
    const auto feed = [&](int sensor, bool saturated, int n) {
        s.sensor = sensor;
        s.sample.flags = saturated ? hal::ImuSample::kGyrSaturated : 0;
        for (int i = 0; i < n; ++i) {
            fusion.onSample(s);
        }
    };
    feed(3, false, 5);
    feed(3, true, 4);
    feed(3, false, 2);
    feed(3, true, 1);
    feed(5, false, 10);
    EXPECT_EQ(fusion.clipEvents(3), 2U);
    EXPECT_EQ(fusion.clipEvents(5), 0U);
    EXPECT_EQ(fusion.clipEvents(99), 0U);  // no such sensor
}

// A sensor whose data-ready line falls silent is out: it has no orientation (the body marks its
// segment), and when it is back its filter starts again from its first samples instead of
// turning slowly from where it was. Here the sensor comes back upside down (re-strapped, or the
// chip reset): before the fix it kept its old orientation through the outage and then needed
// seconds to turn over.
TEST(FusionStage, ASensorThatWasOutStartsAgainFromItsFirstSamples) {
    const board::Board b = *board::loadBoardFile(kSource / "board" / "sim-suit.toml").board;
    firmware::FusionStage fusion(b, nullptr);
    firmware::SensorSample s;
    s.sensor = 2;
    s.sample.flags = hal::ImuSample::kMagFresh;
    const double odr = b.sensors[2].achievedOdrHz;
    Timestamp t{1s};
    const auto feed = [&](const Eigen::Vector3f& acc, const Eigen::Vector3f& mag, int n) {
        s.sample.accMps2 = acc;
        s.sample.magUt = mag;
        s.sample.gyrRadps.setZero();
        for (int i = 0; i < n; ++i) {
            s.sample.t = t;
            t += periodFromHz(odr);
            fusion.onSample(s);
        }
    };
    // Level, facing north (field 20 uT north, 40 uT down): sensor frame = ENU.
    feed({0, 0, 9.81f}, {0, 20, -40}, static_cast<int>(odr * 3));
    ASSERT_NE(fusion.latest(2), nullptr);
    EXPECT_LT(fusion.latest(2)->orientation.angularDistance(Eigen::Quaternionf::Identity()), 0.05);

    firmware::RuntimeEvent silent{firmware::RuntimeEvent::Kind::LineSilent, 2, t, -ETIMEDOUT};
    fusion.onEvent(silent);
    EXPECT_EQ(fusion.latest(2), nullptr);
    EXPECT_EQ(fusion.resets(2), 1u);
    fusion.onEvent(silent);  // one outage, one reset
    EXPECT_EQ(fusion.resets(2), 1u);

    // Back, turned 180 deg about east (x): gravity and the field seen the other way up.
    const Eigen::Quaternionf flipped(
        Eigen::AngleAxisf(static_cast<float>(hal::kPi), Eigen::Vector3f::UnitX()));
    feed({0, 0, -9.81f}, {0, -20, 40}, 5);
    ASSERT_NE(fusion.latest(2), nullptr);
    EXPECT_LT(fusion.latest(2)->orientation.angularDistance(flipped) * 180 / hal::kPi, 5.0);
}

// A glitched bus read (a 5000 rad/s rate, a NaN specific force) is rejected by the sensor's
// filter and counted per sensor; the sensor's orientation stays finite.
TEST(FusionStage, CountsTheRejectedSamplesPerSensorAndStaysFinite) {
    const board::Board b = *board::loadBoardFile(kSource / "board" / "sim-suit.toml").board;
    firmware::FusionStage fusion(b, nullptr);
    firmware::SensorSample s;
    s.sensor = 3;
    s.sample.accMps2 = Eigen::Vector3f(0, 0, 9.81f);
    s.sample.gyrRadps = Eigen::Vector3f(0.1f, 0, 0);
    fusion.onSample(s);
    s.sample.gyrRadps = Eigen::Vector3f(5000.0f, 0, 0);
    fusion.onSample(s);
    s.sample.gyrRadps = Eigen::Vector3f(0.1f, 0, 0);
    s.sample.accMps2 = Eigen::Vector3f(0, std::nanf(""), 9.81f);
    fusion.onSample(s);
    s.sample.accMps2 = Eigen::Vector3f(0, 0, 9.81f);
    for (int i = 0; i < 10; ++i) {
        fusion.onSample(s);
    }
    ASSERT_NE(fusion.latest(3), nullptr);
    EXPECT_TRUE(fusion.latest(3)->orientation.coeffs().allFinite());
    EXPECT_EQ(fusion.rejections(3).gyr, 1U);
    EXPECT_EQ(fusion.rejections(3).acc, 1U);
    EXPECT_EQ(fusion.rejections(5).samples(), 0U);
    EXPECT_EQ(fusion.rejections(99).samples(), 0U);  // no such sensor
}

// The sensor's magnetometer rate (its output rate when the board gives none).
double magOdrOf(const board::SensorConfig& c) {
    return c.magOdrHz > 0 ? c.magOdrHz : c.achievedOdrHz;
}

// Every how many accelerometer/gyroscope samples the sensor's magnetometer reads one.
int magEveryOf(const board::SensorConfig& c) {
    return std::max(1, static_cast<int>(std::lround(c.achievedOdrHz / magOdrOf(c))));
}

// Still sensors of a suit without a magnetometer calibration, each in an orientation of its
// own, fed from startS for seconds: sensor i's chip adds offsets[i] (uT, sensor frame) to the
// earth's field. Only the first `sensors` sensors are fed (all: every one).
void feedStillSuit(firmware::FusionStage& fusion, const board::Board& b,
                   const std::vector<Eigen::Vector3d>& offsets, double startS, double seconds,
                   std::size_t sensors = std::numeric_limits<std::size_t>::max()) {
    const Eigen::Vector3d field(0.0, 50.0 * std::cos(1.05), -50.0 * std::sin(1.05));  // ENU
    const double odr = b.sensors[0].achievedOdrHz;
    for (int k = 0; k < static_cast<int>(seconds * odr); ++k) {
        for (std::size_t i = 0; i < std::min(sensors, b.sensors.size()); ++i) {
            const Quatd q(Eigen::AngleAxisd(
                0.4 * static_cast<double>(i),
                Eigen::Vector3d(1.0, 0.5, 0.2 * static_cast<double>(i)).normalized()));
            firmware::SensorSample s;
            s.sensor = static_cast<int>(i);
            s.sample.t = Timestamp{durationFromSeconds(startS)} + periodFromHz(odr) * k;
            s.sample.accMps2 = (q.conjugate() * Eigen::Vector3d(0, 0, 9.81)).cast<float>();
            s.sample.magUt = (q.conjugate() * field + offsets[i]).cast<float>();
            s.sample.flags = k % magEveryOf(b.sensors[i]) == 0 ? hal::ImuSample::kMagFresh : 0;
            fusion.onSample(s);
        }
    }
}

// A raw field is taken as it is only when the suit's first readings agree on the earth's field
// (fusion::FieldVote), and every heading is the gyroscope's until they have voted. With the
// same field everywhere (offsets of 0-2 uT) every sensor is read raw; one sensor whose 20 uT
// offset gives a field of the earth's size and magnitude (54 uT, 8 % more) but 22 deg nearer
// the vertical is not; with large offsets everywhere none is.
TEST(FusionStage, ReadsAMagnetometerRawOnlyWhenTheSuitsFirstFieldsAgree) {
    const board::Board b = *board::loadBoardFile(kSource / "board" / "sim-suit.toml").board;
    const std::size_t n = b.sensors.size();
    std::vector<Eigen::Vector3d> small(n);
    for (std::size_t i = 0; i < n; ++i) {
        small[i] = Eigen::Vector3d(0.3, -0.2, 0.1) * static_cast<double>(i % 5);
    }
    const auto modes = [&](const firmware::FusionStage& fusion) {
        std::string m;
        for (std::size_t i = 0; i < n; ++i) {
            m += fusion.magMode(static_cast<int>(i)) == firmware::MagMode::Raw ? 'R' : 'g';
        }
        return m;
    };
    {
        firmware::FusionStage fusion(b, nullptr);
        // Ten sensors in, for less than the vote's window: it waits for the other seven.
        feedStillSuit(fusion, b, small, 1.0, 0.3, 10);
        EXPECT_EQ(modes(fusion), std::string(n, 'g')) << "before the vote";
        EXPECT_TRUE(fusion.headingFree(0));
        feedStillSuit(fusion, b, small, 1.3, 1.0);
        EXPECT_EQ(modes(fusion), std::string(n, 'R'));
    }
    {
        // Sensor 2 (turned 0.8 rad about its axis in feedStillSuit): its offset is across the
        // earth's field in its frame, towards its up.
        const Eigen::Vector3d field(0.0, 50.0 * std::cos(1.05), -50.0 * std::sin(1.05));
        const Quatd q2(Eigen::AngleAxisd(0.8, Eigen::Vector3d(1.0, 0.5, 0.4).normalized()));
        const Eigen::Vector3d f2 = q2.conjugate() * field;
        const Eigen::Vector3d up2 = q2.conjugate() * Eigen::Vector3d::UnitZ();
        std::vector<Eigen::Vector3d> offsets = small;
        offsets[2] = (up2 - up2.dot(f2) / f2.squaredNorm() * f2).normalized() * 20.0;
        const Eigen::Vector3d m2 = f2 + offsets[2];
        ASSERT_NEAR(m2.norm(), 53.85, 0.01);
        ASSERT_NEAR(std::acos(f2.dot(up2) / 50.0) - std::acos(m2.dot(up2) / m2.norm()),
                    std::atan(0.4), 1e-9);
        firmware::FusionStage fusion(b, nullptr);
        feedStillSuit(fusion, b, offsets, 1.0, 1.0);
        std::string expected(n, 'R');
        expected[2] = 'g';
        EXPECT_EQ(modes(fusion), expected);
    }
    {
        std::vector<Eigen::Vector3d> large(n);
        for (std::size_t i = 0; i < n; ++i) {
            large[i] = Eigen::Vector3d(120.0 - 15.0 * static_cast<double>(i), -80.0, 40.0);
        }
        firmware::FusionStage fusion(b, nullptr);
        feedStillSuit(fusion, b, large, 1.0, 1.0);
        EXPECT_EQ(modes(fusion), std::string(n, 'g'));
    }
}

// A sensor without a magnetometer calibration whose chip reads a 200 uT offset: its first field
// does not look like the earth's, so its heading is the gyroscope's while it turns; once the
// online estimate has seen enough turns it is magnetic again, with the offset subtracted, and
// the heading ends at magnetic north. The sensor starts facing 120 deg off north.
TEST(FusionStage, EstimatesAnUncalibratedMagnetometersOffsetOnlineAndReturnsToMagneticHeading) {
    const board::Board b = *board::loadBoardFile(kSource / "board" / "sim-suit.toml").board;
    firmware::FusionStage fusion(b, nullptr);
    const int sensor = 4;
    const double odr = b.sensors[sensor].achievedOdrHz;
    const int magEvery = magEveryOf(b.sensors[sensor]);
    const Eigen::Vector3d field(0.0, 50.0 * std::cos(1.05), -50.0 * std::sin(1.05));  // ENU
    const Eigen::Vector3d offset(180.0, -60.0, 70.0);
    Quatd truth(Eigen::AngleAxisd(120.0 * hal::kPi / 180.0, Eigen::Vector3d::UnitZ()));
    const double dt = 1.0 / odr;
    firmware::SensorSample s;
    s.sensor = sensor;
    Timestamp t{1s};
    EXPECT_EQ(fusion.magMode(sensor), firmware::MagMode::Estimating);  // until told otherwise
    double clockS = 0;  // the motion's own time: a run goes on where the last one ended
    const auto run = [&](double seconds, bool turning) {
        const int n = static_cast<int>(seconds * odr);
        for (int i = 0; i < n; ++i) {
            const double tau = clockS + static_cast<double>(i) * dt;
            // A tumble about an axis that wanders over the sphere (sensor frame).
            const Eigen::Vector3d w =
                turning ? Eigen::Vector3d(1.2 * std::cos(0.31 * tau), 1.2 * std::sin(0.31 * tau),
                                          0.8 * std::cos(0.13 * tau))
                        : Eigen::Vector3d::Zero();
            truth = (truth * Quatd(Eigen::AngleAxisd(w.norm() * dt, w.normalized()))).normalized();
            if (!turning) {
                truth.normalize();
            }
            s.sample.gyrRadps = w.cast<float>();
            s.sample.accMps2 = (truth.conjugate() * Eigen::Vector3d(0, 0, 9.81)).cast<float>();
            s.sample.magUt = (truth.conjugate() * field + offset).cast<float>();
            s.sample.flags = (i % magEvery == 0) ? hal::ImuSample::kMagFresh : 0;
            s.sample.t = t;
            t += periodFromHz(odr);
            fusion.onSample(s);
        }
        clockS += static_cast<double>(n) * dt;
    };
    run(3.0, false);
    EXPECT_EQ(fusion.magMode(sensor), firmware::MagMode::Estimating);
    // What the heading waits for (the status and the page say it): first readings, ...
    auto learning = fusion.magLearning(sensor);
    ASSERT_TRUE(learning.has_value());
    EXPECT_STREQ(learning->waitingFor, "readings");
    EXPECT_NEAR(learning->readingsS, 3.0, 0.2);
    EXPECT_EQ(learning->neededS, 10.0);
    // ... then, still for longer than the readings it needs, turns: the field has taken one
    // direction in the sensor frame.
    run(9.0, false);
    learning = fusion.magLearning(sensor);
    ASSERT_TRUE(learning.has_value());
    EXPECT_STREQ(learning->waitingFor, "turns");
    EXPECT_LT(learning->spread, learning->neededSpread);
    // Tumbling, it is good and its heading measured before it turns magnetic.
    bool measured = false;
    for (int k = 0; k < 240 && fusion.magMode(sensor) == firmware::MagMode::Estimating; ++k) {
        run(1.0, true);
        learning = fusion.magLearning(sensor);
        measured = measured || (learning && learning->measuring &&
                                std::string_view(learning->waitingFor) == "the heading measured");
    }
    EXPECT_TRUE(measured);
    run(120.0, true);
    EXPECT_EQ(fusion.magMode(sensor), firmware::MagMode::Online);
    EXPECT_FALSE(fusion.magLearning(sensor).has_value());  // only a gyroscope-only heading learns
    const fusion::HardIronEstimate e = fusion.magEstimate(sensor);
    EXPECT_TRUE(e.good);
    EXPECT_LT((e.offsetUt - offset).norm(), 2.0);
    EXPECT_NEAR(e.fieldNormUt, 50.0, 1.0);
    run(30.0, false);
    ASSERT_NE(fusion.latest(sensor), nullptr);
    const double errDeg =
        fusion.latest(sensor)->orientation.cast<double>().angularDistance(truth) * 180 / hal::kPi;
    EXPECT_LT(errDeg, 3.0);
    // The saved sums start another run's estimator where this one ended.
    firmware::FusionStage next(b, nullptr);
    ASSERT_TRUE(next.setMagEstimatorState(sensor, *fusion.magEstimatorState(sensor)));
    EXPECT_TRUE(next.magEstimate(sensor).good);
    EXPECT_EQ(next.magEstimate(sensor).offsetUt, fusion.magEstimate(sensor).offsetUt);
}

// The same sensor, free (gyroscope-only) while the estimate learns: the moment the estimate is
// good, the heading error is averaged over ~2 s of readings and the filter's heading is turned by
// it in one step, reported (count, angle, time) for the stages after. The angle is the one
// between the truth and the free heading before the step, and the orientation is right from the
// step on (no slow blend).
TEST(FusionStage, StepsAFreeHeadingToMagneticNorthAndReportsTheAngle) {
    const board::Board b = *board::loadBoardFile(kSource / "board" / "sim-suit.toml").board;
    firmware::FusionStage fusion(b, nullptr);
    const int sensor = 6;
    const double odr = b.sensors[sensor].achievedOdrHz;
    const int magEvery = magEveryOf(b.sensors[sensor]);
    const Eigen::Vector3d field(0.0, 50.0 * std::cos(1.05), -50.0 * std::sin(1.05));  // ENU
    const Eigen::Vector3d offset(-150.0, 90.0, 40.0);
    Quatd truth(Eigen::AngleAxisd(-75.0 * hal::kPi / 180.0, Eigen::Vector3d::UnitZ()));
    const double dt = 1.0 / odr;
    firmware::SensorSample s;
    s.sensor = sensor;
    Timestamp t{1s};
    // Heading of a rotation that is (nearly) about ENU up: Rz(a) takes north to (-sin a, cos a).
    const auto yawOf = [](const Quatd& r) {
        const Eigen::Vector3d n = r * Eigen::Vector3d::UnitY();
        return std::atan2(-n.x(), n.y());
    };
    std::optional<double> expected;
    double errAtStepDeg = -1;
    bool freeBefore = true;
    for (int i = 0; i < static_cast<int>(300 * odr) && !expected; ++i) {
        const double tau = static_cast<double>(i) * dt;
        const Eigen::Vector3d w =
            i < static_cast<int>(3 * odr)
                ? Eigen::Vector3d::Zero()
                : Eigen::Vector3d(1.1 * std::cos(0.37 * tau), 1.3 * std::sin(0.29 * tau),
                                  0.9 * std::cos(0.17 * tau));
        const Quatd before = fusion.latest(sensor) != nullptr
                                 ? fusion.latest(sensor)->orientation.cast<double>()
                                 : Quatd::Identity();
        const Quatd truthBefore = truth;
        if (w.norm() > 0) {
            truth = (truth * Quatd(Eigen::AngleAxisd(w.norm() * dt, w.normalized()))).normalized();
        }
        s.sample.gyrRadps = w.cast<float>();
        s.sample.accMps2 = (truth.conjugate() * Eigen::Vector3d(0, 0, 9.81)).cast<float>();
        s.sample.magUt = (truth.conjugate() * field + offset).cast<float>();
        s.sample.flags = (i % magEvery == 0) ? hal::ImuSample::kMagFresh : 0;
        s.sample.t = t;
        t += periodFromHz(odr);
        const bool freeNow = fusion.headingFree(sensor);
        fusion.onSample(s);
        if (fusion.headingStep(sensor).count > 0) {
            freeBefore = freeNow;
            expected = yawOf(truthBefore * before.conjugate());
            errAtStepDeg =
                fusion.latest(sensor)->orientation.cast<double>().angularDistance(truth) * 180 /
                hal::kPi;
        }
    }
    ASSERT_TRUE(expected) << "no step in 300 s";
    const firmware::FusionStage::HeadingStep& step = fusion.headingStep(sensor);
    EXPECT_EQ(step.count, 1U);
    EXPECT_EQ(step.t, t - periodFromHz(odr));
    EXPECT_TRUE(freeBefore);
    EXPECT_FALSE(fusion.headingFree(sensor));
    EXPECT_EQ(fusion.magMode(sensor), firmware::MagMode::Online);
    // The free heading started where the first sample put it (the truth's -75 deg unknown to it),
    // and drifted little since: the step is about that.
    EXPECT_GT(std::abs(*expected), 30 * hal::kPi / 180);
    EXPECT_NEAR(std::remainder(step.angleRad - *expected, 2 * hal::kPi), 0.0, 2.0 * hal::kPi / 180);
    EXPECT_LT(errAtStepDeg, 3.0);
    EXPECT_EQ(fusion.alignReadings(sensor),
              static_cast<std::uint32_t>(std::lround(2 * magOdrOf(b.sensors[sensor]))));
}

// What a reprocess and a live body stage write, kept to compare.
struct KeptRecords final : firmware::ReprocessSink {
    struct PoseRec {
        Timestamp t{};
        std::vector<Eigen::Quaternionf> joints;
    };
    struct EventRec {
        Timestamp t{};
        firmware::cap::EventKind kind{};
        int sensor = -1;
        std::string text;
    };
    std::vector<PoseRec> poses;
    std::vector<EventRec> events;
    std::vector<std::string> metadataRecords;
    void rawSample(int, const hal::ImuSample&) override {}
    void orientation(int, Timestamp, const Eigen::Quaternionf&) override {}
    void pose(Timestamp t, const Eigen::Vector3f&, std::span<const Eigen::Quaternionf> joints,
              std::uint32_t) override {
        poses.push_back({t, std::vector<Eigen::Quaternionf>(joints.begin(), joints.end())});
    }
    void event(Timestamp t, firmware::cap::EventKind kind, int sensor, int,
               std::string_view text) override {
        events.push_back({t, kind, sensor, std::string(text)});
    }
    void metadata(Timestamp, std::string_view toml) override { metadataRecords.emplace_back(toml); }
    void marker(Timestamp, std::string_view) override {}
    std::vector<EventRec> reexpressions() const {
        std::vector<EventRec> out;
        for (const auto& e : events) {
            if (e.kind == firmware::cap::EventKind::Calibrated && e.sensor >= 0) {
                out.push_back(e);
            }
        }
        return out;
    }
};

// A first run without any sensor calibration (typical chips, hard iron up to 300 uT), the body
// calibrated in the T-pose while the headings are free: once the walk has given the online
// estimates their turns, the free headings are stepped to magnetic north and the body calibration
// re-expressed, each recorded as a calibration event of the sensor with the new calibration's
// metadata. The raw samples reprocessed (docs/reprocess.md) do the same at the same samples: the
// same events and the same poses.
TEST(BodyStage, ReExpressesAFreeHeadingsCalibrationAndAReprocessDoesTheSame) {
    const board::Board b = *board::loadBoardFile(kSource / "board" / "sim-suit.toml").board;
    SimulatedClock clock(Timestamp{1s});
    bs::ClipOptions o;
    o.bvh = kSource / "tests" / "data" / "bvh" / "cmu_131_01_start_walk_stop.bvh";
    o.profile = bs::ErrorProfile::Typical;
    o.seed = 1;
    o.tposeHoldS = 4.0;
    auto clip = bs::clipSources(o, clock.now());
    ASSERT_TRUE(clip) << clip.error().message;
    auto suit = bs::buildVirtualSuit(b, clock, clip->sources);
    ASSERT_TRUE(suit) << suit.error().message;

    KeptRecords live;
    firmware::FusionStage fusion(b, nullptr);
    firmware::BodyStage::Options bo;
    bo.calibrate = body::ReferencePoseKind::T;
    firmware::BodyStage bodyStage(b, fusion, &live, clock, bo);
    firmware::SourceRecording recording;
    firmware::SteppedCapture capture(*suit, clock);
    const Timestamp start = clock.now();
    body::SegmentMask freeAtCalibration = 0;
    capture.runUntil(start + 13700ms, [&](const firmware::SensorSample& s) {
        firmware::SourceRecording::Item it;
        it.type = firmware::cap::RecordType::RawSample;
        it.t = s.sample.t;
        it.sensor = s.sensor;
        it.sample = s.sample;
        recording.items.push_back(it);
        ++recording.samples;
        fusion.onSample(s);
        bodyStage.onSample(s);
        if (freeAtCalibration == 0) {
            freeAtCalibration = bodyStage.tracker().freeAtCalibration();
        }
    });
    ASSERT_TRUE(bodyStage.calibrated()) << bodyStage.calibrationError();
    // Every sensor was free or unchecked at the calibration (none is corrected yet)...
    EXPECT_GE(std::popcount(freeAtCalibration), 10);
    // ... and some were stepped and re-expressed by the end.
    const auto steps = live.reexpressions();
    ASSERT_GE(steps.size(), 5U);
    EXPECT_EQ(std::popcount(bodyStage.tracker().freeAtCalibration()),
              std::popcount(freeAtCalibration) - static_cast<int>(steps.size()));
    for (const auto& e : steps) {
        EXPECT_EQ(fusion.headingStep(e.sensor).count, 1U) << e.text;
        EXPECT_EQ(fusion.headingStep(e.sensor).t, e.t) << e.text;
        EXPECT_NE(e.text.find("re-expressed"), std::string::npos) << e.text;
    }
    // A metadata record per calibration: the first and each re-expression.
    ASSERT_EQ(live.metadataRecords.size(), steps.size() + 1);
    // The first names each free heading's mounting as taken from the nominal heading (the
    // T-pose: no measured one among them); each re-expression one fewer.
    auto count = [](const std::string& text, const std::string& what) {
        int n = 0;
        for (auto p = text.find(what); p != std::string::npos; p = text.find(what, p + 1)) {
            ++n;
        }
        return n;
    };
    for (std::size_t k = 0; k < live.metadataRecords.size(); ++k) {
        const std::string& m = live.metadataRecords[k];
        const int freeLeft = std::popcount(freeAtCalibration) - static_cast<int>(k);
        EXPECT_EQ(count(m, "heading_free "), freeLeft) << m;
        EXPECT_EQ(count(m, " nominal-heading"), freeLeft) << m;
    }

    firmware::ReprocessOptions ro;
    ro.calibration.kind = firmware::CalibrationChoice::Kind::TPose;
    ro.calibration.atS = {2.5};
    KeptRecords again;
    auto done = firmware::reprocess(b, recording, ro, again);
    ASSERT_TRUE(done) << done.error().message;
    const auto stepsAgain = again.reexpressions();
    ASSERT_EQ(stepsAgain.size(), steps.size());
    for (std::size_t i = 0; i < steps.size(); ++i) {
        EXPECT_EQ(stepsAgain[i].t, steps[i].t);
        EXPECT_EQ(stepsAgain[i].sensor, steps[i].sensor);
        EXPECT_EQ(stepsAgain[i].text, steps[i].text);
    }
    EXPECT_EQ(again.metadataRecords, live.metadataRecords);
    ASSERT_EQ(again.poses.size(), live.poses.size());
    double worst = 0;
    for (std::size_t i = 0; i < live.poses.size(); ++i) {
        ASSERT_EQ(again.poses[i].t, live.poses[i].t);
        for (std::size_t j = 0; j < live.poses[i].joints.size(); ++j) {
            worst = std::max(worst, static_cast<double>(again.poses[i].joints[j].angularDistance(
                                        live.poses[i].joints[j])));
        }
    }
    EXPECT_LT(worst, 1e-3);
}

TEST(BodyStage, CalibratesInTheTPoseThenPosesAtTheOutputRate) {
    calibrateInPose(body::ReferencePoseKind::T, body::CalibrationMethod::TPose);
}

// The arms hang in the N-pose: a calibration that assumed the T-pose would put the arm sensors'
// mountings 90 deg off, so this checks that the virtual subject holds the N-pose and the stage
// calibrates against it.
TEST(BodyStage, CalibratesInTheNPoseThenPosesAtTheOutputRate) {
    calibrateInPose(body::ReferencePoseKind::N, body::CalibrationMethod::NPose);
}

// Poses come on a fixed grid (60 Hz) that the sensors' samples (100 Hz) do not fall on. Each
// pose must show the body at its own grid time: were it to take the newest orientations as they
// are, they would be 0-10 ms old in a repeating pattern, and the rotation from one pose to the
// next would be 0.6, 1.2, 1.2 times the true one (the joint rates, the foot contacts' velocities
// and the root's path with them). Checked on the thighs while the subject walks.
TEST(BodyStage, SolvesEachPoseForItsGridTimeBetweenTheSensorsSamples) {
    const board::Board b = *board::loadBoardFile(kSource / "board" / "sim-suit.toml").board;
    SimulatedClock clock(Timestamp{1s});
    const Timestamp start = clock.now();
    bs::ClipOptions o;
    o.bvh = kSource / "tests" / "data" / "bvh" / "cmu_12_01_walk.bvh";
    o.profile = bs::ErrorProfile::Ideal;
    o.tposeHoldS = 4.0;
    auto clip = bs::clipSources(o, start);
    ASSERT_TRUE(clip) << clip.error().message;
    auto suit = bs::buildVirtualSuit(b, clock, clip->sources);
    ASSERT_TRUE(suit) << suit.error().message;

    firmware::FusionStage fusion(b, nullptr);
    firmware::BodyStage::Options bo;
    bo.rateHz = 60;
    bo.calibrate = body::ReferencePoseKind::T;
    firmware::BodyStage bodyStage(b, fusion, nullptr, clock, bo);
    firmware::SteppedCapture capture(*suit, clock);

    const std::array segments{body::Segment::LThigh, body::Segment::RThigh};
    std::array<Quatd, 2> lastPose{};
    std::array<Quatd, 2> lastTruth{};
    std::uint64_t posesSeen = 0;
    std::vector<double> ratio;
    bs::SegmentState seg;
    capture.runUntil(start + Duration{clip->leadInNs} + 3s, [&](const firmware::SensorSample& s) {
        fusion.onSample(s);
        bodyStage.onSample(s);
        if (bodyStage.poses() == posesSeen) {
            return;
        }
        const bool consecutive = bodyStage.poses() == posesSeen + 1 && posesSeen > 0;
        posesSeen = bodyStage.poses();
        const std::int64_t tNs = toNs(bodyStage.poseTime() - start);
        for (std::size_t k = 0; k < segments.size(); ++k) {
            const Quatd pose = bodyStage.pose().world(segments[k]);
            clip->trajectory->evaluate(static_cast<board::Segment>(body::idx(segments[k])), tNs,
                                       seg);
            const double truthStep = lastTruth[k].angularDistance(seg.qWorldSegment);
            // Steps of at least 1 deg (60 deg/s): the swing of each leg.
            if (consecutive && tNs > clip->leadInNs && truthStep > 1.0 * hal::kPi / 180) {
                ratio.push_back(lastPose[k].angularDistance(pose) / truthStep);
            }
            lastPose[k] = pose;
            lastTruth[k] = seg.qWorldSegment;
        }
    });
    ASSERT_TRUE(bodyStage.calibrated()) << bodyStage.calibrationError();
    ASSERT_GT(ratio.size(), 60U);
    double meanAbsDeviation = 0;
    for (const double r : ratio) {
        meanAbsDeviation += std::abs(r - 1);
    }
    meanAbsDeviation /= static_cast<double>(ratio.size());
    // Measured: 0.05 (the filters' own step-to-step wobble); from the newest orientations as
    // they are, 0.27.
    EXPECT_LT(meanAbsDeviation, 0.1);
}

// The walk on ideal chips from `clock`'s now: what a board's sensors read of it.
auto idealWalkSources(SimulatedClock& clock) {
    bs::ClipOptions o;
    o.bvh = kSource / "tests" / "data" / "bvh" / "cmu_12_01_walk.bvh";
    o.profile = bs::ErrorProfile::Ideal;
    return bs::clipSources(o, clock.now());
}

// The streams' "calibrated" flags (VMC's calibration state, caphub's frame) said calibrated on
// the nominal mountings (`run --calibrate none`): the published frames say so only after a
// body calibration.
TEST(BodyStage, PublishedFramesAreCalibratedOnlyAfterABodyCalibration) {
    const board::Board b = *board::loadBoardFile(kSource / "board" / "sim-upper10.toml").board;
    for (const bool tpose : {false, true}) {
        SimulatedClock clock(Timestamp{1s});
        auto clip = idealWalkSources(clock);
        auto suit = bs::buildVirtualSuit(b, clock, clip->sources);
        ASSERT_TRUE(suit) << suit.error().message;
        firmware::FusionStage fusion(b, nullptr);
        firmware::BodyStage::Options bo;
        if (tpose) {
            bo.calibrate = body::ReferencePoseKind::T;
        }
        firmware::BodyStage bodyStage(b, fusion, nullptr, clock, bo);
        firmware::PoseFeed poses;
        bodyStage.publishTo(poses);
        firmware::SteppedCapture capture(*suit, clock);
        capture.runUntil(clock.now() + 5s, [&](const firmware::SensorSample& s) {
            fusion.onSample(s);
            bodyStage.onSample(s);
        });
        firmware::PoseFrame latest;
        ASSERT_GT(poses.latest(latest), 0u) << "no pose published, T-pose " << tpose;
        EXPECT_EQ(latest.bodyCalibrated, tpose);
    }
}

TEST(PreviewStage, RendersTheBodysPosesIntoTheSinksWithoutHoldingThePipeline) {
    const board::Board b = *board::loadBoardFile(kSource / "board" / "sim-upper10.toml").board;
    SimulatedClock clock(Timestamp{1s});
    auto clip = idealWalkSources(clock);
    auto suit = bs::buildVirtualSuit(b, clock, clip->sources);
    ASSERT_TRUE(suit) << suit.error().message;

    const std::filesystem::path dir = std::filesystem::path(::testing::TempDir()) /
                                      ("caphub-preview-" + std::to_string(getpid()));
    std::filesystem::remove_all(dir);
    firmware::FusionStage fusion(b, nullptr);
    firmware::BodyStage bodyStage(b, fusion, nullptr, clock, firmware::BodyStage::Options{});
    firmware::PoseFeed poses;
    bodyStage.publishTo(poses);
    render::SinkSet sinks;
    sinks.add(render::makePngFolderSink(dir));
    auto skin = render::loadDefaultSkin();
    ASSERT_TRUE(skin) << skin.error().message;
    firmware::PreviewStage::Options po;
    po.fps = 5;
    {
        firmware::PreviewStage preview(b, poses, std::move(*skin), std::move(sinks), po);
        firmware::SteppedCapture capture(*suit, clock);
        capture.runUntil(clock.now() + 3s, [&](const firmware::SensorSample& s) {
            fusion.onSample(s);
            bodyStage.onSample(s);
            preview.onSample(s);
        });
        preview.finish(clock.now());
        EXPECT_EQ(preview.error(), "");
        // 3 s at 5 frames per second of capture time: 15 handed over (the first sample comes
        // ~0.2 s in, so 14 or 15); each is rendered or, when the renderer was busy (it may not
        // even have started: the simulation runs far faster than real time), skipped; the last
        // one is always drawn.
        EXPECT_GE(preview.framesRendered() + preview.framesSkipped(), 14u);
        ASSERT_GE(preview.framesRendered(), 1u);
        std::size_t files = 0;
        for (const auto& e : std::filesystem::directory_iterator(dir)) {
            files += e.path().extension() == ".png";
        }
        EXPECT_EQ(files, preview.framesRendered());
    }
}

}  // namespace

namespace {

// The records the stages hand the recorder, kept for a test: the poses' not-measured masks.
class PoseLog final : public firmware::RecordSink {
public:
    void orientation(int, Timestamp, const Eigen::Quaternionf&) override {}
    void pose(Timestamp t, const Eigen::Vector3f&, std::span<const Eigen::Quaternionf> joints,
              std::uint32_t notMeasured) override {
        poses.emplace_back(t, notMeasured);
        rotations.emplace_back(joints.begin(), joints.end());
    }
    void event(Timestamp, firmware::cap::EventKind, int, int, std::string_view) override {}
    void metadata(Timestamp, std::string_view) override {}
    void marker(Timestamp, std::string_view) override {}
    std::vector<std::pair<Timestamp, std::uint32_t>> poses;
    std::vector<std::vector<Eigen::Quaternionf>> rotations;
};

// The whole lifecycle through the bus worker, fusion and body: a sensor whose data-ready line
// sticks for a second goes silent, its segment is flagged as not measured in every pose while it
// is out (before the fix it was frozen without a word), its filter is reset, and once the line
// works again the sensor comes back online and its segment is measured again.
TEST(BodyStage, ASilentSensorsSegmentIsFlaggedInThePosesUntilItIsBack) {
    const board::Board b = *board::loadBoardFile(kSource / "board" / "sim-suit.toml").board;
    SimulatedClock clock(Timestamp{1s});
    bs::VirtualChips chips;
    auto suit = bs::buildVirtualSuit(b, clock, nullptr, &chips);
    ASSERT_TRUE(suit) << suit.error().message;
    PoseLog log;
    firmware::FusionStage fusion(b, &log);
    firmware::BodyStage bodyStage(b, fusion, &log, clock, firmware::BodyStage::Options{});
    firmware::SteppedCapture capture(*suit, clock);
    std::vector<firmware::RuntimeEvent> events;
    const auto run = [&](Duration d) {
        capture.runUntil(
            clock.now() + d,
            [&](const firmware::SensorSample& s) {
                fusion.onSample(s);
                bodyStage.onSample(s);
            },
            [&](const firmware::RuntimeEvent& e) {
                events.push_back(e);
                fusion.onEvent(e);
                bodyStage.onEvent(e);
            });
    };
    constexpr int kSensor = 5;
    const auto bitOf = body::bit(b.sensors[kSensor].segment);
    // The first pose waits for every sensor's first sample: measured whole from the start.
    run(1s);
    ASSERT_FALSE(log.poses.empty());
    EXPECT_EQ(log.poses.front().second, 0u);
    for (const auto& [t, m] : log.poses) {
        if (t > clock.now() - 400ms) {
            EXPECT_EQ(m, 0u);  // measured before the fault
        }
    }
    const std::size_t before = log.poses.size();
    chips.imu[kSensor]->setDataReadyStuck(true);
    const Timestamp stuck = clock.now();
    run(1500ms);
    chips.imu[kSensor]->setDataReadyStuck(false);
    const Timestamp released = clock.now();
    run(1500ms);

    bool silent = false;
    bool online = false;
    for (const auto& e : events) {
        if (e.sensor == kSensor && e.kind == firmware::RuntimeEvent::Kind::LineSilent) {
            silent = true;
        }
        if (e.sensor == kSensor && e.kind == firmware::RuntimeEvent::Kind::SensorOnline &&
            e.t > stuck) {
            online = true;
        }
    }
    ASSERT_TRUE(silent);
    ASSERT_TRUE(online);
    EXPECT_EQ(fusion.resets(kSensor), 1u);
    // Flagged from shortly after the line stuck (the silence takes 20 periods to tell) until it
    // is back; never flagged once it delivers again; the other segments always measured.
    int flagged = 0;
    for (std::size_t k = before; k < log.poses.size(); ++k) {
        const auto& [t, m] = log.poses[k];
        EXPECT_EQ(m & ~bitOf, 0u);
        if (t > stuck + 300ms && t < released) {
            EXPECT_NE(m & bitOf, 0u) << toSeconds(t - stuck);
        }
        if (t > released + 800ms) {
            EXPECT_EQ(m & bitOf, 0u) << toSeconds(t - released);
        }
        flagged += (m & bitOf) != 0;
    }
    EXPECT_GT(flagged, 40);  // at least ~0.7 s of 60 Hz poses
    // While flagged, the segment holds the rotation of the last pose that measured it.
    const auto j = static_cast<std::size_t>(b.sensors[kSensor].segment);
    for (std::size_t k = before + 1; k < log.poses.size(); ++k) {
        if ((log.poses[k].second & bitOf) != 0) {
            EXPECT_TRUE(log.rotations[k][j].isApprox(log.rotations[k - 1][j])) << k;
        }
    }
}

}  // namespace
