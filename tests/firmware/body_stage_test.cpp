// The body stage on the virtual suit: the subject stands in the T-pose while the filters settle,
// the stage calibrates the mountings from it (finding the sensors' true, strapped mountings far
// better than the board's nominal ones), then solves a pose per frame at the output rate; the
// preview renders those poses on its own thread.
#include "firmware/runtime/body_stage.h"

#include <array>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <vector>

#include <gtest/gtest.h>
#include <unistd.h>

#include "board/loader.h"
#include "board/sim/virtual_suit.h"
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

TEST(PreviewStage, RendersTheBodysPosesIntoTheSinksWithoutHoldingThePipeline) {
    const board::Board b = *board::loadBoardFile(kSource / "board" / "sim-upper10.toml").board;
    SimulatedClock clock(Timestamp{1s});
    bs::ClipOptions o;
    o.bvh = kSource / "tests" / "data" / "bvh" / "cmu_12_01_walk.bvh";
    o.profile = bs::ErrorProfile::Ideal;
    auto clip = bs::clipSources(o, clock.now());
    auto suit = bs::buildVirtualSuit(b, clock, clip->sources);
    ASSERT_TRUE(suit) << suit.error().message;

    const std::filesystem::path dir = std::filesystem::path(::testing::TempDir()) /
                                      ("caphub-preview-" + std::to_string(getpid()));
    std::filesystem::remove_all(dir);
    firmware::FusionStage fusion(b, nullptr);
    firmware::BodyStage bodyStage(b, fusion, nullptr, clock, firmware::BodyStage::Options{});
    render::SinkSet sinks;
    sinks.add(render::makePngFolderSink(dir));
    auto skin = render::loadDefaultSkin();
    ASSERT_TRUE(skin) << skin.error().message;
    firmware::PreviewStage::Options po;
    po.fps = 5;
    {
        firmware::PreviewStage preview(b, bodyStage, std::move(*skin), std::move(sinks), po);
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
