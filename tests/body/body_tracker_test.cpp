// The body tracker without the virtual suit: sensor orientations made from known poses and
// mountings go in at 100 Hz, and the poses it solves on its 60 Hz grid, its calibrations, heading
// resets and segment validity are checked against what made them.
#include "fusion/body/body_tracker.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numbers>
#include <optional>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "tests/body/test_poses.h"

namespace caphub::body {
namespace {

using namespace std::chrono_literals;
using S = Segment;
constexpr double kPi = std::numbers::pi;
constexpr double kDeg = kPi / 180;
// The tracker holds orientations as floats (the filters' type): a unit quaternion in float is
// good to ~1e-7, and slerp and the mounting products keep the angle error below 1e-5 rad; 1e-4
// rad (0.006 deg) leaves room and is still a thousand times below any error tested for.
constexpr double kTolRad = 1e-4;
const Duration kSample = 10ms;  // 100 Hz sensors

// The segments whose reference orientation differs between the T- and the N-pose.
bool isArm(Segment s) {
    return s == S::LUpperarm || s == S::LForearm || s == S::LHand || s == S::RUpperarm ||
           s == S::RForearm || s == S::RHand;
}

Skeleton skeleton() {
    return Skeleton(*dimensionsFromSubject(board::SubjectConfig{}));
}

// The 17 sensors of the full suit, in segment order, with nominal mountings that are arbitrary
// but fixed, and true (strapped) mountings off them by 15-25 deg: about the segment's left axis
// for the trunk and legs, about its forward axis for the arms. Neither turns a sensor's heading
// in the T- or the N-pose, so the calibrations' heading estimate is exact and the mountings
// they find can be compared with the truth to float precision.
struct Suit {
    std::vector<TrackedSensor> sensors;
    std::array<Quatd, kSegmentCount> trueMounting;
    std::vector<int> sensorOf = std::vector<int>(kSegmentCount, -1);

    Suit() {
        trueMounting.fill(Quatd::Identity());
        std::mt19937 rng(7);
        for (int i = 0; i < kSegmentCount; ++i) {
            if (!has(testing::kFullSuit, i)) {
                continue;
            }
            const auto u = static_cast<std::size_t>(i);
            const auto s = static_cast<Segment>(i);
            TrackedSensor t;
            t.segment = s;
            t.nominalMounting = testing::randomRotation(rng, kPi);
            t.positionM = Vec3d(0, 0.02, 0.05);
            const Vec3d axis = isArm(s) ? Vec3d::UnitZ() : Vec3d::UnitX();
            const double off = (15.0 + 10.0 * (i % 3) / 2.0) * kDeg;
            trueMounting[u] = (fromAxisAngle<double>(axis, off) * t.nominalMounting).normalized();
            sensorOf[u] = static_cast<int>(sensors.size());
            sensors.push_back(t);
        }
    }
    int sensor(Segment s) const { return sensorOf[static_cast<std::size_t>(idx(s))]; }
    std::array<Quatd, kSegmentCount> nominal() const {
        std::array<Quatd, kSegmentCount> m;
        m.fill(Quatd::Identity());
        for (const auto& t : sensors) {
            m[static_cast<std::size_t>(idx(t.segment))] = t.nominalMounting;
        }
        return m;
    }
};

Timestamp at(Duration d) {
    return Timestamp{d};
}

// Every sensor's update for the subject in `pose`, facing headingRad, with the given mountings;
// each sensor turning at rateRadS in its own frame.
void feed(BodyTracker& tracker, const Suit& suit, Timestamp t, const Pose& pose, double headingRad,
          const std::array<Quatd, kSegmentCount>& mounting, std::vector<TrackerEvents>* events,
          int skip = -1) {
    const SensorFrame f = testing::sensorsFor(pose, mounting, testing::kFullSuit, headingRad);
    for (std::size_t i = 0; i < suit.sensors.size(); ++i) {
        if (static_cast<int>(i) == skip) {
            continue;
        }
        SensorUpdate u;
        u.sensor = static_cast<int>(i);
        u.t = t;
        u.qEnuSensor =
            f.qEnuSensor[static_cast<std::size_t>(idx(suit.sensors[i].segment))].cast<float>();
        u.specificForceMps2 = (u.qEnuSensor.conjugate() * Eigen::Vector3f(0, 0, 9.81f));
        TrackerEvents e = tracker.update(u);
        if (events != nullptr) {
            events->push_back(e);
        }
    }
}

// Solves every grid time that is due through t; returns how many.
int solveDue(BodyTracker& tracker, Timestamp t) {
    int n = 0;
    while (auto g = tracker.due(t)) {
        tracker.solveAt(*g);
        ++n;
    }
    return n;
}

// The largest angle between the solved and the true world orientations of the sensored segments.
double worstSegmentError(const Pose& solved, const Pose& truth) {
    double worst = 0;
    for (int i = 0; i < kSegmentCount; ++i) {
        if (has(testing::kFullSuit, i)) {
            const auto u = static_cast<std::size_t>(i);
            worst = std::max(worst, solved.qWorld[u].angularDistance(truth.qWorld[u]));
        }
    }
    return worst;
}

double worstMountingError(const BodyCalibration& cal, const Suit& suit) {
    double worst = 0;
    for (const auto& s : suit.sensors) {
        const auto u = static_cast<std::size_t>(idx(s.segment));
        worst = std::max(worst, cal.mounting[u].angularDistance(suit.trueMounting[u]));
    }
    return worst;
}

// The pelvis' heading in the solved pose: its forward axis' angle about up from +Z.
// Every joint of the full suit (a segment and its parent both measured) as in `expected`.
void expectSameJoints(const Pose& solved, const Pose& expected) {
    for (int i = 1; i < kSegmentCount; ++i) {
        if (has(testing::kFullSuit, i) && has(testing::kFullSuit, parentOf(i))) {
            const auto u = static_cast<std::size_t>(i);
            EXPECT_LT(solved.qLocal[u].angularDistance(expected.qLocal[u]), kTolRad)
                << board::segmentName(static_cast<Segment>(i));
        }
    }
}

double pelvisHeading(const Pose& p) {
    const Vec3d z = p.world(S::Pelvis) * Vec3d::UnitZ();
    return std::atan2(z.x(), z.z());
}

TEST(BodyTracker, SolvesTheKnownPoseTheSensorOrientationsCameFrom) {
    const Suit suit;
    BodyTracker tracker(skeleton(), suit.sensors);
    std::mt19937 rng(3);
    const Pose truth = testing::randomPose(rng, 60 * kDeg);
    // Not calibrated in a pose: the nominal mountings, the subject facing north.
    for (int k = 0; k < 20; ++k) {
        const Timestamp t = at(kSample * k);
        feed(tracker, suit, t, truth, 0, suit.nominal(), nullptr);
        solveDue(tracker, t);
    }
    ASSERT_GT(tracker.poses(), 5U);
    EXPECT_LT(worstSegmentError(tracker.pose(), truth), kTolRad);
    // The joint rotations of the joints between two sensored segments follow.
    for (S s : {S::LForearm, S::RCalf, S::LHand, S::LUpperarm}) {
        EXPECT_LT(tracker.pose().qLocal[static_cast<std::size_t>(idx(s))].angularDistance(
                      truth.qLocal[static_cast<std::size_t>(idx(s))]),
                  kTolRad)
            << board::segmentName(s);
    }
    // Every segment rests on reporting sensors.
    EXPECT_EQ(tracker.latest().valid, testing::kAll);
}

TEST(BodyTracker, SolvesEachGridTimeBetweenTheSensorsSamples) {
    // One sensor on the pelvis turning at 2 rad/s about an axis of its own frame: its
    // orientation at any time is known exactly. 60 Hz poses from 100 Hz samples fall between
    // samples (and past the newest one); each must show the pelvis at its own grid time, not at
    // its newest sample's (which would be up to 10 ms = 0.02 rad off).
    TrackedSensor pelvis;
    pelvis.segment = S::Pelvis;
    BodyTracker tracker(skeleton(), {pelvis});
    const Vec3d axis = Vec3d(0.3, -0.5, 0.8).normalized();
    constexpr double kRateRadS = 2.0;
    const Quatd q0 = fromAxisAngle<double>(Vec3d(1, 1, 0).normalized(), 0.4);
    const auto orientation = [&](Timestamp t) {
        return (q0 * fromAxisAngle<double>(axis, kRateRadS * toSeconds(t.time_since_epoch())))
            .normalized();
    };
    const Quatd qWorldEnu = enuFromSkeletonWorld().conjugate();
    int checked = 0;
    int between = 0;
    for (int k = 0; k < 60; ++k) {
        const Timestamp t = at(kSample * k);
        SensorUpdate u;
        u.t = t;
        u.qEnuSensor = orientation(t).cast<float>();
        u.rateRadS = (axis * kRateRadS).cast<float>();
        (void)tracker.update(u);
        while (auto g = tracker.due(t)) {
            const TrackedPose& p = tracker.solveAt(*g);
            EXPECT_EQ(p.t, *g);
            const Quatd expected = qWorldEnu * orientation(*g);
            if (k >= 1) {  // the first sample has no interval to interpolate over
                EXPECT_LT(p.pose->world(S::Pelvis).angularDistance(expected), kTolRad)
                    << "grid time " << toNs(*g) << " ns, newest sample " << toNs(t) << " ns";
                ++checked;
                between += *g != t ? 1 : 0;
            }
        }
    }
    // Past the newest sample (590 ms) the orientation is carried on at the sensor's rate.
    const TrackedPose& ahead = tracker.solveAt(at(595ms));
    EXPECT_LT(ahead.pose->world(S::Pelvis).angularDistance(qWorldEnu * orientation(at(595ms))),
              kTolRad);
    // 0.59 s of samples: the grid's 36 points (less the first), two in three off the samples.
    EXPECT_GE(checked, 34);
    EXPECT_GE(between, 20);
    // The grid is the output rate's, from the first sample.
    EXPECT_EQ(tracker.period(), periodFromHz(60));
    EXPECT_EQ(tracker.latest().t, at(595ms));
}

TEST(BodyTracker, CalibratesInTheTPoseLaterInTheCaptureAndSolvesRelativeToIt) {
    // The subject stands 3 s in any pose, then holds the T-pose facing 30 deg west of north;
    // calibration is asked for at 4 s, averaging from then for 1 s. Before it the nominal
    // mountings (15-25 deg off the true ones) tilt every segment; after it the T-pose is solved
    // as the reference pose, facing +Z, and a new pose as itself.
    const Suit suit;
    BodyTracker tracker(skeleton(), suit.sensors);
    std::mt19937 rng(5);
    const Pose wander = testing::randomPose(rng, 40 * kDeg);
    const Pose tpose = testing::referencePose(ReferencePoseKind::T);
    const Pose after = testing::randomPose(rng, 60 * kDeg);
    const double heading = 30 * kDeg;
    std::vector<TrackerEvents> events;
    std::optional<Timestamp> calibratedAt;
    for (int k = 0; k < 800; ++k) {
        const Timestamp t = at(kSample * k);
        const Pose& pose = t < at(3s) ? wander : t < at(6s) ? tpose : after;
        if (t == at(4s)) {
            EXPECT_EQ(tracker.calibrationStatus().state, CalibrationStatus::State::NotStarted);
            tracker.startCalibration(ReferencePoseKind::T, t);
        }
        if (t == at(3900ms)) {
            // Still on the nominal mountings: the T-pose is solved 15-25 deg off.
            EXPECT_GT(worstSegmentError(tracker.pose(), tpose), 10 * kDeg);
        }
        if (t == at(4500ms)) {
            const CalibrationStatus s = tracker.calibrationStatus();
            EXPECT_EQ(s.state, CalibrationStatus::State::Averaging);
            EXPECT_NEAR(s.progress, 0.5, 0.02);
        }
        events.clear();
        feed(tracker, suit, t, pose, heading, suit.trueMounting, &events);
        for (const auto& e : events) {
            if (e.calibrated) {
                EXPECT_FALSE(calibratedAt) << "calibrated twice";
                calibratedAt = t;
            }
        }
        solveDue(tracker, t);
        if (t == at(5900ms)) {
            // Calibrated at 5 s: the T-pose (held until 6 s) is now the reference pose.
            EXPECT_LT(worstSegmentError(tracker.pose(), tpose), kTolRad);
        }
    }
    ASSERT_TRUE(calibratedAt);
    EXPECT_EQ(*calibratedAt, at(5s));  // the first update past the window
    EXPECT_EQ(tracker.calibration().tNs, toNs(at(5s)));
    EXPECT_EQ(tracker.calibration().method, CalibrationMethod::TPose);
    EXPECT_EQ(tracker.calibrationStatus().state, CalibrationStatus::State::Done);
    EXPECT_NEAR(tracker.calibration().headingRad, heading, kTolRad);
    EXPECT_LT(worstMountingError(tracker.calibration(), suit), kTolRad);
    EXPECT_LT(worstSegmentError(tracker.pose(), after), kTolRad);
}

TEST(BodyTracker, CalibratesTPlusNFromTwoMoments) {
    // The T-pose held from 1 s, the N-pose from 3 s; asked for at the start. The arms' mountings
    // come from gravity in the two poses (TRIAD), the rest from both poses.
    const Suit suit;
    BodyTrackerOptions o;
    o.solveUncalibrated = false;
    BodyTracker tracker(skeleton(), suit.sensors, o);
    tracker.startTwoPoseCalibration(at(1s), at(3s));
    const Pose tpose = testing::referencePose(ReferencePoseKind::T);
    const Pose npose = testing::referencePose(ReferencePoseKind::N);
    std::mt19937 rng(9);
    const Pose after = testing::randomPose(rng, 60 * kDeg);
    const double heading = -50 * kDeg;
    std::vector<TrackerEvents> events;
    for (int k = 0; k < 600; ++k) {
        const Timestamp t = at(kSample * k);
        const Pose& pose = t < at(2500ms) ? tpose : t < at(4500ms) ? npose : after;
        feed(tracker, suit, t, pose, heading, suit.trueMounting, &events);
        if (t < at(4s)) {
            EXPECT_EQ(solveDue(tracker, t), 0) << "a pose before the calibration";
        } else {
            solveDue(tracker, t);
        }
    }
    int calibrated = 0;
    for (const auto& e : events) {
        calibrated += e.calibrated ? 1 : 0;
        EXPECT_FALSE(e.calibrationFailed) << e.message;
    }
    EXPECT_EQ(calibrated, 1);
    EXPECT_EQ(tracker.calibration().method, CalibrationMethod::TPlusN);
    EXPECT_EQ(tracker.calibration().tNs, toNs(at(4s)));
    EXPECT_LT(worstMountingError(tracker.calibration(), suit), kTolRad);
    EXPECT_LT(worstSegmentError(tracker.pose(), after), kTolRad);
}

TEST(BodyTracker, HeadingResetTurnsTheWorldSoThatThePelvisFacesForward) {
    const Suit suit;
    BodyTracker tracker(skeleton(), suit.sensors);
    std::mt19937 rng(11);
    Pose turned = testing::randomPose(rng, 30 * kDeg);
    // The whole body turned 70 deg about up from where the capture world faces.
    turned.qLocal[0] = fromAxisAngle<double>(Vec3d::UnitY(), 70 * kDeg) * turned.qLocal[0];
    worldFromLocal(turned);
    const double before = pelvisHeading(turned);
    ASSERT_GT(std::abs(before), 30 * kDeg);
    EXPECT_EQ(tracker.headingResetStatus().state, HeadingResetStatus::State::NotAsked);
    tracker.headingResetAt(at(1s));
    EXPECT_EQ(tracker.headingResetStatus().state, HeadingResetStatus::State::Pending);
    std::vector<TrackerEvents> events;
    for (int k = 0; k < 150; ++k) {
        const Timestamp t = at(kSample * k);
        feed(tracker, suit, t, turned, 0, suit.nominal(), &events);
        solveDue(tracker, t);
        if (t == at(990ms)) {
            EXPECT_NEAR(pelvisHeading(tracker.pose()), before, kTolRad);
        }
    }
    int resets = 0;
    for (const auto& e : events) {
        resets += e.headingReset ? 1 : 0;
        EXPECT_FALSE(e.headingResetFailed) << e.message;
    }
    EXPECT_EQ(resets, 1);
    EXPECT_NEAR(tracker.calibration().headingRad, before, kTolRad);
    EXPECT_NEAR(pelvisHeading(tracker.pose()), 0, kTolRad);
    // The joints are as they were: the body turned as a whole.
    expectSameJoints(tracker.pose(), turned);
    // What a control page shows: done, and the heading it set.
    EXPECT_EQ(tracker.headingResetStatus().state, HeadingResetStatus::State::Done);
    EXPECT_NEAR(tracker.headingResetStatus().headingDeg * kDeg, before, kTolRad);
}

TEST(BodyTracker, AHeadingResetWithNoCalibrationFailsAndSaysWhy) {
    // No pose is solved before a calibration (solveUncalibrated off): there is no calibration
    // for the reset to turn, and the status says so instead of staying pending.
    const Suit suit;
    BodyTrackerOptions options;
    options.solveUncalibrated = false;
    BodyTracker tracker(skeleton(), suit.sensors, options);
    tracker.headingResetAt(at(100ms));
    std::vector<TrackerEvents> events;
    for (int k = 0; k < 30; ++k) {
        feed(tracker, suit, at(kSample * k), Pose{}, 0, suit.nominal(), &events);
    }
    int failed = 0;
    for (const auto& e : events) {
        failed += e.headingResetFailed ? 1 : 0;
        EXPECT_FALSE(e.headingReset);
    }
    EXPECT_EQ(failed, 1);
    EXPECT_EQ(tracker.headingResetStatus().state, HeadingResetStatus::State::Failed);
    EXPECT_NE(tracker.headingResetStatus().message.find("no body calibration"), std::string::npos)
        << tracker.headingResetStatus().message;
}

TEST(BodyTracker, ASensorOfflineMakesItsSegmentsInvalidUntilItReportsAgain) {
    // The chest sensor goes offline at 1 s: the chest is not measured, and nor are the two spine
    // segments that share its rotation (l5 between pelvis and chest, c7 between chest and
    // skull). Its late updates are ignored. Back at 2 s with the chest bent 40 deg (its filter
    // restarted), the chest is valid again and shows the new orientation, not the old one.
    const Suit suit;
    BodyTracker tracker(skeleton(), suit.sensors);
    const Pose upright;
    Pose bent;
    bent.qLocal[static_cast<std::size_t>(idx(S::T12))] =
        fromAxisAngle<double>(Vec3d::UnitX(), 40 * kDeg);
    worldFromLocal(bent);
    const int chest = suit.sensor(S::T12);
    const SegmentMask out = bit(S::T12) | bit(S::L5) | bit(S::C7);
    for (int k = 0; k < 300; ++k) {
        const Timestamp t = at(kSample * k);
        if (t == at(1s)) {
            tracker.setSensorOnline(chest, false);
        }
        if (t == at(2s)) {
            tracker.setSensorOnline(chest, true);
            // Back with nothing held: the orientation from before it went out is forgotten.
            EXPECT_FALSE(tracker.latestUpdate(chest));
        }
        const bool offline = t >= at(1s) && t < at(2s);
        // Offline, the chest still sends the bent pose (late samples): the tracker ignores them.
        feed(tracker, suit, t, offline || t >= at(2s) ? bent : upright, 0, suit.nominal(), nullptr);
        while (auto g = tracker.due(t)) {
            const TrackedPose& p = tracker.solveAt(*g);
            if (offline && *g >= at(1s)) {
                EXPECT_EQ(p.valid & out, 0U) << "at " << toNs(*g) << " ns";
                EXPECT_EQ(p.valid | out, testing::kAll);
            } else if (*g >= at(1s)) {
                EXPECT_EQ(p.valid, testing::kAll) << "at " << toNs(*g) << " ns";
            }
        }
        if (t == at(1500ms)) {
            EXPECT_FALSE(tracker.latestUpdate(chest));
        }
    }
    EXPECT_EQ(tracker.latestUpdate(chest), at(kSample * 299));
    EXPECT_LT(tracker.pose().world(S::T12).angularDistance(bent.world(S::T12)), kTolRad);
}

TEST(BodyTracker, ASensorThatStopsReportingIsInvalidOnceStale) {
    // Never declared offline, the left forearm's sensor falls silent at 1 s: after staleAfter
    // (0.25 s) its segment is not valid; the hand, with its own sensor, stays valid.
    const Suit suit;
    BodyTracker tracker(skeleton(), suit.sensors);
    const Pose upright;
    const int forearm = suit.sensor(S::LForearm);
    SegmentMask lastValid = 0;
    for (int k = 0; k < 200; ++k) {
        const Timestamp t = at(kSample * k);
        feed(tracker, suit, t, upright, 0, suit.nominal(), nullptr, t >= at(1s) ? forearm : -1);
        while (auto g = tracker.due(t)) {
            const TrackedPose& p = tracker.solveAt(*g);
            if (*g < at(1200ms)) {
                EXPECT_EQ(p.valid, testing::kAll) << "at " << toNs(*g) << " ns";
            }
            lastValid = p.valid;
        }
    }
    EXPECT_EQ(lastValid, testing::kAll & ~bit(S::LForearm));
}

TEST(BodyTracker, TheWatermarkIsTheLeastLiveSensorsTimeLeavingOutALateOne) {
    // The sensors on two "buses": the left forearm's reports 8 ms behind the others. The
    // watermark is its time while it keeps up; when it stops (its bus stalls) it is declared
    // late after 2.5 of its intervals, and the watermark moves on with the others.
    const Suit suit;
    BodyTracker tracker(skeleton(), suit.sensors);
    const Pose upright;
    const int forearm = suit.sensor(S::LForearm);
    EXPECT_FALSE(tracker.watermark(at(0ms)).has_value());
    const auto one = [&](int sensor, Timestamp t) {
        const SensorFrame f = testing::sensorsFor(upright, suit.nominal(), testing::kFullSuit, 0);
        SensorUpdate u;
        u.sensor = sensor;
        u.t = t;
        u.qEnuSensor = f.qEnuSensor[static_cast<std::size_t>(idx(
                                        suit.sensors[static_cast<std::size_t>(sensor)].segment))]
                           .cast<float>();
        u.specificForceMps2 = u.qEnuSensor.conjugate() * Eigen::Vector3f(0, 0, 9.81f);
        tracker.update(u);
    };
    for (int k = 0; k < 10; ++k) {
        feed(tracker, suit, at(kSample * k), upright, 0, suit.nominal(), nullptr, forearm);
        if (k > 0) {
            one(forearm, at(kSample * k - 8ms));
        }
        if (k > 1) {
            ASSERT_TRUE(tracker.watermark(at(kSample * k)).has_value());
            EXPECT_EQ(*tracker.watermark(at(kSample * k)), at(kSample * k - 8ms)) << k;
        }
    }
    // The forearm's latest is at 82 ms; at 100 ms it is 18 ms behind (< 25 ms): still waited
    // for. At 110 ms (28 ms behind) it is late: the others' 110 ms is the watermark.
    feed(tracker, suit, at(100ms), upright, 0, suit.nominal(), nullptr, forearm);
    EXPECT_EQ(*tracker.watermark(at(100ms)), at(82ms));
    feed(tracker, suit, at(110ms), upright, 0, suit.nominal(), nullptr, forearm);
    EXPECT_EQ(*tracker.watermark(at(110ms)), at(110ms));
    // Offline sensors are not waited for either; back and reporting, it is again.
    tracker.setSensorOnline(forearm, false);
    EXPECT_EQ(*tracker.watermark(at(110ms)), at(110ms));
    tracker.setSensorOnline(forearm, true);
    one(forearm, at(105ms));
    EXPECT_EQ(*tracker.watermark(at(110ms)), at(105ms));
}

TEST(BodyTracker, TheFirstPoseWaitsForEverySensorsFirstSample) {
    // At the start the sensors' first samples come a few ms apart (their buses start one after
    // the other). The first pose used to be solved after the first sensor's first sample, the
    // others not measured and drawn at an orientation nobody measured (a body lying on the
    // floor in the preview and the streams' first frame).
    const Suit suit;
    BodyTracker tracker(skeleton(), suit.sensors);
    const Pose upright;
    const int forearm = suit.sensor(S::LForearm);
    feed(tracker, suit, at(0ms), upright, 0, suit.nominal(), nullptr, forearm);
    EXPECT_FALSE(tracker.watermark(at(0ms)).has_value());  // nothing can be due yet
    feed(tracker, suit, at(10ms), upright, 0, suit.nominal(), nullptr, forearm);
    EXPECT_FALSE(tracker.watermark(at(10ms)).has_value());
    std::vector<TrackerEvents> events;
    feed(tracker, suit, at(14ms), upright, 0, suit.nominal(), &events);  // all, the forearm's first
    const auto through = tracker.watermark(at(14ms));
    ASSERT_TRUE(through.has_value());
    const auto g = tracker.due(*through);
    ASSERT_TRUE(g.has_value());
    EXPECT_EQ(tracker.solveAt(*g).valid, testing::kAll);

    // A sensor that never reports is waited for kStartWait, then left out.
    BodyTracker silent(skeleton(), suit.sensors);
    Timestamp t = at(0ms);
    for (; t <= at(0ms) + BodyTracker::kStartWait; t += kSample) {
        feed(silent, suit, t, upright, 0, suit.nominal(), nullptr, forearm);
        EXPECT_FALSE(silent.watermark(t).has_value()) << toNs(t);
    }
    feed(silent, suit, t, upright, 0, suit.nominal(), nullptr, forearm);
    ASSERT_TRUE(silent.watermark(t).has_value());
    EXPECT_EQ(*silent.watermark(t), t);
}

TEST(BodyTracker, AFailedCalibrationSaysWhyAndKeepsTheOneInUse) {
    // A calibration whose window passes before any sensor reported has nothing to average.
    const Suit suit;
    BodyTracker tracker(skeleton(), suit.sensors);
    tracker.startCalibration(ReferencePoseKind::T, at(0s));
    std::vector<TrackerEvents> events;
    feed(tracker, suit, at(2s), Pose{}, 0, suit.nominal(), &events);
    ASSERT_FALSE(events.empty());
    EXPECT_TRUE(events[0].calibrationFailed);
    EXPECT_FALSE(events[0].message.empty());
    const CalibrationStatus s = tracker.calibrationStatus();
    EXPECT_EQ(s.state, CalibrationStatus::State::Failed);
    EXPECT_EQ(s.message, events[0].message);
    EXPECT_TRUE(tracker.calibrated());  // still on the nominal mountings
    EXPECT_EQ(tracker.calibration().method, CalibrationMethod::None);
}

// Sensors whose headings are free (gyroscope-only, each off north by an angle of its own):
// every update's orientation is Rz(-offset) times the true one, about ENU up, until the sensor's
// heading is realigned; from then on it is the true one.
struct FreeHeadings {
    std::vector<double> offsetRad;  // per tracked sensor
    std::vector<bool> free;
    std::vector<bool> unchecked;  // of the free ones: flagged unchecked (raw magnetic) instead

    void feed(BodyTracker& tracker, const Suit& suit, Timestamp t, const Pose& pose,
              double headingRad, std::vector<TrackerEvents>& events) const {
        const SensorFrame f =
            testing::sensorsFor(pose, suit.trueMounting, testing::kFullSuit, headingRad);
        for (std::size_t i = 0; i < suit.sensors.size(); ++i) {
            const Quatd truth =
                f.qEnuSensor[static_cast<std::size_t>(idx(suit.sensors[i].segment))];
            const Quatd q =
                free[i] ? fromAxisAngle<double>(Vec3d::UnitZ(), -offsetRad[i]) * truth : truth;
            SensorUpdate u;
            u.sensor = static_cast<int>(i);
            u.t = t;
            u.qEnuSensor = q.normalized().cast<float>();
            u.specificForceMps2 = u.qEnuSensor.conjugate() * Eigen::Vector3f(0, 0, 9.81f);
            u.headingUnchecked = free[i] && i < unchecked.size() && unchecked[i];
            u.headingFree = free[i] && !u.headingUnchecked;
            events.push_back(tracker.update(u));
        }
    }
};

// A T-pose calibration taken while every sensor's heading was free (a first run without a
// magnetometer calibration): each mounting takes the nominal heading about the vertical, the
// rest from gravity; this suit's straps are tilted only, so the mountings are the true ones and
// the joints are right before any heading is measured (the body as a whole faces the capture
// heading estimated from the free headings). Each sensor's realignment (its measured offset,
// later, in another pose) re-expresses the calibration as if that heading had been magnetic in
// the T-pose: once all are realigned the mountings, the capture heading and the solved pose are
// the ones a magnetic calibration finds.
TEST(BodyTracker, RealigningFreeHeadingsReExpressesTheCalibration) {
    const Suit suit;
    BodyTrackerOptions o;
    o.solveUncalibrated = false;
    BodyTracker tracker(skeleton(), suit.sensors, o);
    FreeHeadings h;
    for (std::size_t i = 0; i < suit.sensors.size(); ++i) {
        h.offsetRad.push_back((std::fmod(83.0 * static_cast<double>(i) + 40.0, 360.0) - 180.0) *
                              kDeg);
        h.free.push_back(true);
    }
    const double heading = 25 * kDeg;
    const Pose tpose = testing::referencePose(ReferencePoseKind::T);
    std::mt19937 rng(13);
    const Pose after = testing::randomPose(rng, 60 * kDeg);
    tracker.startCalibration(ReferencePoseKind::T, at(500ms));
    std::vector<TrackerEvents> events;
    int reexpressed = 0;
    double worstBefore = 0;
    for (int k = 0; k < 500; ++k) {
        const Timestamp t = at(kSample * k);
        if (k >= 300 && k < 300 + static_cast<int>(suit.sensors.size())) {
            // From 3 s one sensor a sample has its offset measured.
            const auto i = static_cast<std::size_t>(k - 300);
            if (i == 0) {
                EXPECT_EQ(tracker.freeAtCalibration(), testing::kFullSuit);
                EXPECT_EQ(tracker.calibration().nominalHeading, testing::kFullSuit);
                worstBefore = worstMountingError(tracker.calibration(), suit);
                for (int j = 1; j < kSegmentCount; ++j) {
                    if (has(testing::kFullSuit, j) && has(testing::kFullSuit, parentOf(j))) {
                        const auto u = static_cast<std::size_t>(j);
                        EXPECT_LT(tracker.pose().qLocal[u].angularDistance(after.qLocal[u]),
                                  kTolRad)
                            << board::segmentName(static_cast<Segment>(j));
                    }
                }
            }
            const TrackerEvents e = tracker.realignHeading(static_cast<int>(i), h.offsetRad[i]);
            reexpressed += e.reexpressed ? 1 : 0;
            h.free[i] = false;
        }
        h.feed(tracker, suit, t, t < at(2500ms) ? tpose : after, heading, events);
        solveDue(tracker, t);
    }
    EXPECT_LT(worstBefore, kTolRad);
    EXPECT_EQ(reexpressed, static_cast<int>(suit.sensors.size()));
    EXPECT_EQ(tracker.freeAtCalibration(), 0U);
    EXPECT_EQ(tracker.calibration().freeHeading, 0U);
    EXPECT_EQ(tracker.calibration().nominalHeading, 0U);
    EXPECT_EQ(tracker.calibration().method, CalibrationMethod::TPose);
    EXPECT_EQ(tracker.calibration().tNs, toNs(at(1500ms)));
    EXPECT_NEAR(tracker.calibration().headingRad, heading, kTolRad);
    EXPECT_LT(worstMountingError(tracker.calibration(), suit), kTolRad);
    EXPECT_LT(worstSegmentError(tracker.pose(), after), kTolRad);
    // A heading that is magnetic already: its step (drift corrected) leaves the calibration.
    const BodyCalibration before = tracker.calibration();
    const TrackerEvents again = tracker.realignHeading(0, 2 * kDeg);
    EXPECT_FALSE(again.reexpressed);
    EXPECT_EQ(tracker.calibration().mounting[0].coeffs(), before.mounting[0].coeffs());
}

// Only three sensors free at the calibration: the capture heading comes from the magnetic ones
// alone, so their mountings are right from the start and the free ones' realignment leaves them
// as they are. Two free ones' straps are also off by 8 deg about the segment's vertical: their
// nominal-heading mountings miss that part only (gravity gives the rest) until the realignment
// measures it, and their segments move with the body meanwhile (off by that much, not by their
// free angles). T+N measures the arms' whole. A heading reset done before the realignment is
// kept.
void realignSomeFree(bool twoPose) {
    Suit suit;
    BodyTrackerOptions o;
    o.solveUncalibrated = false;
    BodyTracker tracker(skeleton(), suit.sensors, o);
    FreeHeadings h;
    const std::vector<int> freeOnes = {suit.sensor(S::RHand), suit.sensor(S::LCalf),
                                       suit.sensor(S::Skull)};
    h.offsetRad.assign(suit.sensors.size(), 0);
    h.free.assign(suit.sensors.size(), false);
    // The straps' vertical components cancel in the capture heading estimated from all 17 (each
    // sensor's contribution turns by its strap's yaw): it is the same before and after.
    const std::array<double, 3> strapYaw = {0, 8 * kDeg, -8 * kDeg};
    std::vector<double> yawOf(suit.sensors.size(), 0.0);
    for (std::size_t k = 0; k < freeOnes.size(); ++k) {
        const auto i = static_cast<std::size_t>(freeOnes[k]);
        yawOf[i] = strapYaw[k];
        h.offsetRad[i] = (120.0 - 110.0 * static_cast<double>(k)) * kDeg;
        h.free[i] = true;
        const auto u = static_cast<std::size_t>(idx(suit.sensors[i].segment));
        suit.trueMounting[u] =
            (fromAxisAngle<double>(Vec3d::UnitY(), strapYaw[k]) * suit.trueMounting[u])
                .normalized();
    }
    const double heading = -40 * kDeg;
    const Pose tpose = testing::referencePose(ReferencePoseKind::T);
    const Pose npose = testing::referencePose(ReferencePoseKind::N);
    std::mt19937 rng(17);
    Pose after = testing::randomPose(rng, 40 * kDeg);
    if (twoPose) {
        tracker.startTwoPoseCalibration(at(500ms), at(2s));
    } else {
        tracker.startCalibration(ReferencePoseKind::T, at(500ms));
    }
    const Timestamp done = twoPose ? at(3s) : at(1500ms);
    std::vector<TrackerEvents> events;
    std::array<Quatd, kSegmentCount> magneticMountings{};
    for (int k = 0; k < 700; ++k) {
        const Timestamp t = at(kSample * k);
        if (t == at(4s)) {
            EXPECT_EQ(tracker.calibration().tNs, toNs(done));
            EXPECT_NEAR(tracker.calibration().headingRad, heading, kTolRad);
            magneticMountings = tracker.calibration().mounting;
            for (const auto& s : suit.sensors) {
                const auto u = static_cast<std::size_t>(idx(s.segment));
                const int i = suit.sensor(s.segment);
                const double off = magneticMountings[u].angularDistance(suit.trueMounting[u]);
                const double pose = tracker.pose().qWorld[u].angularDistance(after.qWorld[u]);
                const bool nominal =
                    h.free[static_cast<std::size_t>(i)] && !(twoPose && isArm(s.segment));
                EXPECT_EQ(has(tracker.calibration().nominalHeading, idx(s.segment)), nominal);
                if (!nominal || yawOf[static_cast<std::size_t>(i)] == 0) {
                    // (T+N finds the arms' mountings from gravity alone: no heading in them.
                    // A strap tilted only: the nominal heading is its own.)
                    EXPECT_LT(off, kTolRad) << board::segmentName(s.segment);
                    EXPECT_LT(pose, kTolRad) << board::segmentName(s.segment);
                    continue;
                }
                EXPECT_GT(off, 4 * kDeg) << board::segmentName(s.segment);
                EXPECT_LT(off, 12 * kDeg) << board::segmentName(s.segment);
                EXPECT_LT(pose, 12 * kDeg) << board::segmentName(s.segment);
                // The sensor's vertical is the true one.
                const Vec3d up = Vec3d::UnitY();
                EXPECT_LT(
                    (magneticMountings[u].conjugate() * up - suit.trueMounting[u].conjugate() * up)
                        .norm(),
                    kTolRad)
                    << board::segmentName(s.segment);
            }
            const SegmentMask freeSegments = bit(S::RHand) | bit(S::LCalf) | bit(S::Skull);
            EXPECT_EQ(tracker.calibration().freeHeading, freeSegments);
            tracker.headingResetAt(t);
        }
        if (t == at(5s)) {
            for (int i : freeOnes) {
                EXPECT_TRUE(tracker.realignHeading(i, h.offsetRad[static_cast<std::size_t>(i)])
                                .reexpressed);
                h.free[static_cast<std::size_t>(i)] = false;
            }
        }
        const Pose& pose = t < (twoPose ? at(1800ms) : at(2500ms)) ? tpose
                           : twoPose && t < at(3500ms)             ? npose
                                                                   : after;
        h.feed(tracker, suit, t, pose, heading, events);
        solveDue(tracker, t);
    }
    int resets = 0;
    for (const auto& e : events) {
        resets += e.headingReset ? 1 : 0;
    }
    EXPECT_EQ(resets, 1);
    EXPECT_EQ(tracker.calibration().method,
              twoPose ? CalibrationMethod::TPlusN : CalibrationMethod::TPose);
    EXPECT_LT(worstMountingError(tracker.calibration(), suit), kTolRad);
    for (const auto& s : suit.sensors) {
        const auto u = static_cast<std::size_t>(idx(s.segment));
        if (std::find(freeOnes.begin(), freeOnes.end(), suit.sensor(s.segment)) == freeOnes.end()) {
            // The capture heading is estimated again from all 17 (float orientations): the same
            // to float precision.
            EXPECT_LT(tracker.calibration().mounting[u].angularDistance(magneticMountings[u]),
                      kTolRad)
                << "magnetic at the calibration, yet moved: " << board::segmentName(s.segment);
        }
    }
    // The reset turned the world so that the pelvis faced +Z at 4 s (in `after`): kept.
    EXPECT_NEAR(tracker.calibration().headingRad,
                std::remainder(heading + pelvisHeading(after), 2 * kPi), kTolRad);
    // The joints are the pose's (the world turned as a whole).
    expectSameJoints(tracker.pose(), after);
}

TEST(BodyTracker, RealigningSomeFreeHeadingsLeavesTheMagneticOnesMountings) {
    realignSomeFree(false);
}

TEST(BodyTracker, RealigningSomeFreeHeadingsReExpressesATPlusNCalibration) {
    realignSomeFree(true);
}

// A free sensor whose filter restarts after the calibration (a new free frame, unrelated to the
// one averaged): it keeps its nominal-heading mounting through a later re-expression, with no
// turn, and is never re-expressed itself.
TEST(BodyTracker, AFreeSensorRestartedKeepsItsNominalHeadingMountingWithoutATurn) {
    const Suit suit;
    BodyTrackerOptions o;
    o.solveUncalibrated = false;
    BodyTracker tracker(skeleton(), suit.sensors, o);
    FreeHeadings h;
    h.offsetRad.assign(suit.sensors.size(), 0);
    h.free.assign(suit.sensors.size(), false);
    const auto thigh = static_cast<std::size_t>(suit.sensor(S::LThigh));
    const auto hand = static_cast<std::size_t>(suit.sensor(S::RHand));
    h.offsetRad[thigh] = 100 * kDeg;
    h.offsetRad[hand] = -70 * kDeg;
    h.free[thigh] = true;
    h.free[hand] = true;
    tracker.startCalibration(ReferencePoseKind::T, at(0s));
    std::vector<TrackerEvents> events;
    const Pose tpose = testing::referencePose(ReferencePoseKind::T);
    const auto seg = static_cast<std::size_t>(idx(S::LThigh));
    Quatd mountingBefore;
    for (int k = 0; k < 400; ++k) {
        const Timestamp t = at(kSample * k);
        if (t == at(2s)) {
            ASSERT_TRUE(tracker.calibrated());
            EXPECT_NE(tracker.calibration().headingTurnRad[seg], 0.0);
            mountingBefore = tracker.calibration().mounting[seg];
            EXPECT_LT(mountingBefore.angularDistance(suit.trueMounting[seg]), kTolRad);
            tracker.resetSensor(static_cast<int>(thigh));
            h.offsetRad[thigh] = -20 * kDeg;  // its restarted filter's own free angle
        }
        if (t == at(3s)) {
            EXPECT_FALSE(tracker.realignHeading(static_cast<int>(thigh), 5 * kDeg).reexpressed);
            EXPECT_TRUE(
                tracker.realignHeading(static_cast<int>(hand), h.offsetRad[hand]).reexpressed);
            h.free[hand] = false;
            h.offsetRad[thigh] -= 5 * kDeg;
        }
        h.feed(tracker, suit, t, tpose, 30 * kDeg, events);
    }
    const BodyCalibration& cal = tracker.calibration();
    EXPECT_EQ(tracker.freeAtCalibration(), 0U);
    EXPECT_LT(cal.mounting[seg].angularDistance(mountingBefore), 1e-9);
    EXPECT_TRUE(has(cal.freeHeading, idx(S::LThigh)));
    EXPECT_TRUE(has(cal.nominalHeading, idx(S::LThigh)));
    EXPECT_EQ(cal.headingTurnRad[seg], 0.0);
    EXPECT_FALSE(has(cal.freeHeading, idx(S::RHand)));
    EXPECT_LT(worstMountingError(cal, suit), kTolRad);
}

// An unchecked heading (a magnetometer read raw, its offset unmeasured) 130 deg off is one no
// strap explains: as unknown at the calibration as a free one (the nominal heading and a turn),
// then a re-expression when the fusion stage measures and steps it.
TEST(BodyTracker, AWrongUncheckedHeadingIsTakenAsUnknownLikeAFreeOne) {
    const Suit suit;
    BodyTrackerOptions o;
    o.solveUncalibrated = false;
    BodyTracker tracker(skeleton(), suit.sensors, o);
    FreeHeadings h;
    h.offsetRad.assign(suit.sensors.size(), 0);
    h.free.assign(suit.sensors.size(), false);
    h.unchecked.assign(suit.sensors.size(), false);
    const auto calf = static_cast<std::size_t>(suit.sensor(S::RCalf));
    h.offsetRad[calf] = 130 * kDeg;
    h.free[calf] = true;
    h.unchecked[calf] = true;
    tracker.startCalibration(ReferencePoseKind::T, at(0s));
    std::vector<TrackerEvents> events;
    std::mt19937 rng(23);
    const Pose tpose = testing::referencePose(ReferencePoseKind::T);
    const Pose after = testing::randomPose(rng, 40 * kDeg);
    const auto seg = static_cast<std::size_t>(idx(S::RCalf));
    for (int k = 0; k < 400; ++k) {
        const Timestamp t = at(kSample * k);
        if (t == at(2500ms)) {
            EXPECT_EQ(tracker.freeAtCalibration(), bit(S::RCalf));
            EXPECT_TRUE(has(tracker.calibration().nominalHeading, idx(S::RCalf)));
            EXPECT_NEAR(
                std::remainder(tracker.calibration().headingTurnRad[seg] - 130 * kDeg, 2 * kPi),
                0.0, kTolRad);
            EXPECT_LT(worstSegmentError(tracker.pose(), after), kTolRad);
            EXPECT_TRUE(
                tracker.realignHeading(static_cast<int>(calf), h.offsetRad[calf]).reexpressed);
            h.free[calf] = false;
        }
        h.feed(tracker, suit, t, t < at(1500ms) ? tpose : after, -60 * kDeg, events);
        solveDue(tracker, t);
    }
    EXPECT_EQ(tracker.freeAtCalibration(), 0U);
    EXPECT_EQ(tracker.calibration().freeHeading, 0U);
    EXPECT_EQ(tracker.calibration().headingTurnRad[seg], 0.0);
    EXPECT_LT(worstMountingError(tracker.calibration(), suit), kTolRad);
    EXPECT_LT(worstSegmentError(tracker.pose(), after), kTolRad);
}

// An unchecked heading 12 deg off is one a strap could explain: taken as right, its mounting
// measured (and off by those 12 deg), no turn; when the fusion stage measures and steps it, the
// calibration is re-expressed for it as for a free one, and the mounting comes out true.
TEST(BodyTracker, APlausibleUncheckedHeadingIsMeasuredThenReexpressed) {
    const Suit suit;
    BodyTrackerOptions o;
    o.solveUncalibrated = false;
    BodyTracker tracker(skeleton(), suit.sensors, o);
    FreeHeadings h;
    h.offsetRad.assign(suit.sensors.size(), 0);
    h.free.assign(suit.sensors.size(), false);
    h.unchecked.assign(suit.sensors.size(), false);
    const auto calf = static_cast<std::size_t>(suit.sensor(S::RCalf));
    h.offsetRad[calf] = 12 * kDeg;
    h.free[calf] = true;
    h.unchecked[calf] = true;
    tracker.startCalibration(ReferencePoseKind::T, at(0s));
    std::vector<TrackerEvents> events;
    std::mt19937 rng(29);
    const Pose tpose = testing::referencePose(ReferencePoseKind::T);
    const Pose after = testing::randomPose(rng, 40 * kDeg);
    const auto seg = static_cast<std::size_t>(idx(S::RCalf));
    for (int k = 0; k < 400; ++k) {
        const Timestamp t = at(kSample * k);
        if (t == at(2500ms)) {
            EXPECT_EQ(tracker.freeAtCalibration(), bit(S::RCalf));
            EXPECT_EQ(tracker.calibration().freeHeading, 0U);
            EXPECT_EQ(tracker.calibration().headingTurnRad[seg], 0.0);
            EXPECT_GT(worstMountingError(tracker.calibration(), suit), 8 * kDeg);
            EXPECT_TRUE(
                tracker.realignHeading(static_cast<int>(calf), h.offsetRad[calf]).reexpressed);
            h.free[calf] = false;
        }
        h.feed(tracker, suit, t, t < at(1500ms) ? tpose : after, -60 * kDeg, events);
        solveDue(tracker, t);
    }
    EXPECT_EQ(tracker.freeAtCalibration(), 0U);
    EXPECT_EQ(tracker.calibration().freeHeading, 0U);
    EXPECT_LT(worstMountingError(tracker.calibration(), suit), kTolRad);
    EXPECT_LT(worstSegmentError(tracker.pose(), after), kTolRad);
}

// A heading realigned while the calibration is still averaging: the sums turn with it, and the
// calibration comes out as if the sensor had been magnetic throughout.
TEST(BodyTracker, RealigningDuringTheAverageTurnsWhatWasAveraged) {
    const Suit suit;
    BodyTrackerOptions o;
    o.solveUncalibrated = false;
    BodyTracker tracker(skeleton(), suit.sensors, o);
    FreeHeadings h;
    h.offsetRad.assign(suit.sensors.size(), 0);
    h.free.assign(suit.sensors.size(), false);
    const auto pelvis = static_cast<std::size_t>(suit.sensor(S::Pelvis));
    h.offsetRad[pelvis] = 150 * kDeg;
    h.free[pelvis] = true;
    tracker.startCalibration(ReferencePoseKind::T, at(0s));
    std::vector<TrackerEvents> events;
    const Pose tpose = testing::referencePose(ReferencePoseKind::T);
    for (int k = 0; k < 150; ++k) {
        const Timestamp t = at(kSample * k);
        if (t == at(400ms)) {
            EXPECT_FALSE(tracker.realignHeading(static_cast<int>(pelvis), h.offsetRad[pelvis])
                             .reexpressed);  // nothing calibrated yet
            h.free[pelvis] = false;
        }
        h.feed(tracker, suit, t, tpose, 10 * kDeg, events);
    }
    ASSERT_TRUE(tracker.calibrated());
    EXPECT_EQ(tracker.freeAtCalibration(), 0U);
    EXPECT_NEAR(tracker.calibration().headingRad, 10 * kDeg, kTolRad);
    EXPECT_LT(worstMountingError(tracker.calibration(), suit), kTolRad);
}

// The capture heading from the knees (fusion/body/knee_heading.h). Every sensor turned by the
// same 3 deg about its segment's long axis (a strap's turn about the vertical in the T-pose):
// the calibration's capture heading, from the nominal mountings, is off by as much. Then the
// legs walk in place (the thighs swinging 20 deg, the knees bending 0-60 deg at 1 Hz) for 3 s,
// the sensors' rates from their orientations' change.
struct KneeRun {
    double headingRad = 0;       // the subject's true heading
    double calibratedRad = 0;    // the calibration's capture heading
    std::optional<double> knee;  // kneeHeadingError() at the end
    int kneeEvents = 0;
    double eventRad = 0;
    double finalHeadingRad = 0;   // calibration().headingRad at the end
    double mountingErrorRad = 0;  // worst, at the end
};

KneeRun walkOnTheKnees(BodyTrackerOptions o) {
    Suit suit;
    const double strap = 3 * kDeg;
    for (auto& m : suit.trueMounting) {
        m = (fromAxisAngle<double>(Vec3d::UnitY(), strap) * m).normalized();
    }
    BodyTracker tracker(skeleton(), suit.sensors, o);
    KneeRun r;
    r.headingRad = 30 * kDeg;
    const Pose tpose = testing::referencePose(ReferencePoseKind::T);
    std::vector<Quatd> previous(suit.sensors.size(), Quatd::Identity());
    tracker.startCalibration(ReferencePoseKind::T, at(500ms));
    for (int k = 0; k < 500; ++k) {
        const Timestamp t = at(kSample * k);
        Pose pose = tpose;
        const double s = std::max(0.0, (k - 200) * 0.01);  // walking from 2 s
        if (s > 0) {
            const double phase = 2 * kPi * s;
            const double swing = 20 * kDeg * std::sin(phase);
            const double bend = 30 * kDeg * (1 - std::cos(phase));
            pose.qLocal[idx(S::LThigh)] = Quatd(Eigen::AngleAxisd(swing, Vec3d::UnitX()));
            pose.qLocal[idx(S::RThigh)] = Quatd(Eigen::AngleAxisd(-swing, Vec3d::UnitX()));
            pose.qLocal[idx(S::LCalf)] = Quatd(Eigen::AngleAxisd(bend, Vec3d::UnitX()));
            pose.qLocal[idx(S::RCalf)] =
                Quatd(Eigen::AngleAxisd(30 * kDeg * (1 + std::cos(phase)), Vec3d::UnitX()));
            worldFromLocal(pose);
        }
        const SensorFrame f =
            testing::sensorsFor(pose, suit.trueMounting, testing::kFullSuit, r.headingRad);
        for (std::size_t i = 0; i < suit.sensors.size(); ++i) {
            SensorUpdate u;
            u.sensor = static_cast<int>(i);
            u.t = t;
            const Quatd q = f.qEnuSensor[static_cast<std::size_t>(idx(suit.sensors[i].segment))];
            const Eigen::AngleAxisd step(previous[i].conjugate() * q);
            u.rateRadS =
                (k == 0 ? Vec3d::Zero() : Vec3d(step.axis() * step.angle() / toSeconds(kSample)))
                    .cast<float>();
            previous[i] = q;
            u.qEnuSensor = q.cast<float>();
            u.specificForceMps2 = u.qEnuSensor.conjugate() * Eigen::Vector3f(0, 0, 9.81f);
            const TrackerEvents e = tracker.update(u);
            if (e.calibrated) {
                r.calibratedRad = tracker.calibration().headingRad;
            }
            if (e.kneeHeading) {
                ++r.kneeEvents;
                r.eventRad = e.kneeHeadingRad;
            }
        }
        solveDue(tracker, t);
    }
    r.knee = tracker.kneeHeadingError();
    r.finalHeadingRad = tracker.calibration().headingRad;
    r.mountingErrorRad = worstMountingError(tracker.calibration(), suit);
    return r;
}

// The filters are told the body's acceleration from the root's velocity, which the foot
// contacts give; without a foot measured the contacts are held segments', and the filters are
// told no acceleration instead (a sparse suit without feet, or a foot's sensor out, was told the
// held legs' stepping).
TEST(BodyTracker, WithoutBothFeetMeasuredTheFiltersAreToldNoAcceleration) {
    const Suit suit;
    BodyTracker tracker(skeleton(), suit.sensors);
    tracker.startCalibration(ReferencePoseKind::T, at(500ms));
    const Pose tpose = testing::referencePose(ReferencePoseKind::T);
    const int foot = suit.sensor(S::LHindfoot);
    int aided = 0;
    int toldNone = 0;
    for (int k = 0; k < 700; ++k) {
        const Timestamp t = at(kSample * k);
        if (t == at(4s)) {
            tracker.setSensorOnline(foot, false);
        }
        Pose pose = tpose;
        const double s = std::max(0.0, (k - 200) * 0.01);  // stepping from 2 s
        if (s > 0) {
            const double phase = 2 * kPi * s;
            const double swing = 25 * kDeg * std::sin(phase);
            pose.qLocal[idx(S::LThigh)] = Quatd(Eigen::AngleAxisd(swing, Vec3d::UnitX()));
            pose.qLocal[idx(S::RThigh)] = Quatd(Eigen::AngleAxisd(-swing, Vec3d::UnitX()));
            worldFromLocal(pose);
        }
        feed(tracker, suit, t, pose, 0, suit.trueMounting, nullptr, t >= at(4s) ? foot : -1);
        while (auto g = tracker.due(t)) {
            const TrackedPose& p = tracker.solveAt(*g);
            if (!p.aidEnuMps2) {
                continue;
            }
            if (*g >= at(4s)) {
                EXPECT_EQ(*p.aidEnuMps2, Vec3d::Zero()) << "at " << toNs(*g) << " ns";
                ++toldNone;
            } else if (p.aidEnuMps2->norm() > 1e-3) {
                ++aided;
            }
        }
    }
    EXPECT_GT(aided, 10);
    EXPECT_GT(toldNone, 100);
}

TEST(BodyTracker, TheKneesAxesSayHowFarTheCaptureHeadingIsOff) {
    // Estimated only (the default): the calibration stays, and the error it reports is what the
    // straps' common turn put into the capture heading.
    const KneeRun r = walkOnTheKnees({});
    EXPECT_GT(std::abs(r.calibratedRad - r.headingRad), 2.5 * kDeg);
    ASSERT_TRUE(r.knee);
    EXPECT_NEAR(r.calibratedRad + *r.knee, r.headingRad, 0.05 * kDeg);
    EXPECT_EQ(r.kneeEvents, 0);
    EXPECT_EQ(r.finalHeadingRad, r.calibratedRad);
    EXPECT_GT(r.mountingErrorRad, 2.5 * kDeg);
}

TEST(BodyTracker, LiveTheKneesCorrectTheCaptureHeadingOnce) {
    // Corrected live: once both knees have bent enough, the capture heading and every mounting
    // turn by the error, once; the mountings are then the true ones.
    BodyTrackerOptions o;
    o.kneeHeading = KneeHeadingMode::Live;
    const KneeRun r = walkOnTheKnees(o);
    EXPECT_EQ(r.kneeEvents, 1);
    EXPECT_NEAR(r.finalHeadingRad, r.headingRad, 0.05 * kDeg);
    EXPECT_NEAR(r.calibratedRad + r.eventRad, r.headingRad, 0.05 * kDeg);
    EXPECT_LT(r.mountingErrorRad, 0.05 * kDeg);
}

TEST(BodyTracker, AKnownCaptureHeadingErrorIsCorrectedAtTheCalibration) {
    // Offline (reprocess --smooth): the error known from a pass over the whole take turns the
    // first calibration as it is made.
    const KneeRun estimated = walkOnTheKnees({});
    ASSERT_TRUE(estimated.knee);
    BodyTrackerOptions o;
    o.knownHeadingErrorRad = *estimated.knee;
    const KneeRun r = walkOnTheKnees(o);
    EXPECT_EQ(r.kneeEvents, 1);
    EXPECT_NEAR(r.calibratedRad, r.headingRad, 0.05 * kDeg);
    EXPECT_LT(r.mountingErrorRad, 0.05 * kDeg);
    EXPECT_FALSE(r.knee);  // nothing more to say once corrected
}

}  // namespace
}  // namespace caphub::body
