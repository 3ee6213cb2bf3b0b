// Segment trajectories: the spline passes through the mocap frames, its rates are the true
// derivatives of its pose, angular velocity and linear acceleration are continuous across
// frames, and the reference pose, units and clip ends behave as documented.
#include "board/sim/motion.h"

#include <cmath>
#include <filesystem>
#include <numbers>
#include <random>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace caphub::board::sim {
namespace {

using board::Segment;
using ::testing::HasSubstr;

const std::filesystem::path kData = std::filesystem::path(CAPHUB_TEST_DATA_DIR) / "bvh";
const std::filesystem::path kShared =
    std::filesystem::path(CAPHUB_SOURCE_DIR) / ".." / "shared" / "data" / "bvh";

constexpr double kRad = std::numbers::pi / 180.0;

BvhClip load(const std::filesystem::path& path) {
    auto r = loadBvh(path);
    EXPECT_TRUE(r.ok()) << r.error().message;
    return r.ok() ? std::move(r).value() : BvhClip{};
}

const BvhClip& walkClip() {
    static const BvhClip clip = load(kData / "cmu_12_01_walk.bvh");
    return clip;
}

Motion walk(const MotionOptions& options) {
    auto m = Motion::fromClip(walkClip(), *findBuiltInJointMap("cmu-motionbuilder"), options);
    EXPECT_TRUE(m.ok()) << m.error().message;
    return std::move(m).value();
}

// The walk with default options, built once: fitting is the slow part of these tests.
const Motion& walk() {
    static const Motion m = walk(MotionOptions{});
    return m;
}

std::int64_t frameNs(const Motion& m, double frame) {
    return static_cast<std::int64_t>(std::llround(frame * m.frameTimeS() * 1e9));
}

SegmentState at(const Motion& m, Segment s, std::int64_t tNs) {
    SegmentState st;
    m.evaluate(s, tNs, st);
    return st;
}

// Instants inside frame intervals, away from the knots, where the spline's third derivative
// jumps and finite differences straddling a knot would not converge.
std::vector<std::int64_t> interiorInstants(const Motion& m, int count) {
    std::mt19937_64 rng(7);
    std::uniform_int_distribution<int> frame(0, m.frameCount() - 2);
    std::uniform_real_distribution<double> u(0.05, 0.95);
    std::vector<std::int64_t> t;
    for (int i = 0; i < count; ++i) {
        t.push_back(frameNs(m, frame(rng) + u(rng)));
    }
    return t;
}

// A one-joint clip turning about Y by degPerFrame each frame at 100 frames/s.
BvhClip turningClip(double degPerFrame, int frames) {
    std::string text =
        "HIERARCHY\nROOT R\n{\nOFFSET 0 0 0\nCHANNELS 4 Xposition Yposition Zposition Yrotation\n"
        "End Site\n{\nOFFSET 1 0 0\n}\n}\nMOTION\nFrames: " +
        std::to_string(frames) + "\nFrame Time: 0.01\n";
    for (int f = 0; f < frames; ++f) {
        text += "0 1 0 " + std::to_string(degPerFrame * f) + "\n";
    }
    auto r = parseBvh(text, "turning");
    EXPECT_TRUE(r.ok()) << r.error().message;
    return std::move(r).value();
}

JointMap rootOnlyMap() {
    JointMap map;
    map.name = "root-only";
    map.unitM = 1.0;
    map.joints[static_cast<std::size_t>(Segment::Pelvis)] = {"R"};
    return map;
}

TEST(Motion, SplinePassesThroughEveryMocapFrame) {
    const Motion& m = walk();
    double worstRad = 0;
    double worstM = 0;
    for (int f = 0; f < m.frameCount(); ++f) {
        for (const auto& s : board::kSegments) {
            const SegmentState st = at(m, s.id, frameNs(m, f));
            worstRad =
                std::max(worstRad, angleBetween(st.qWorldSegment, m.keyOrientation(s.id, f)));
            worstM = std::max(worstM, (st.positionM - m.keyPositionM(s.id, f)).norm());
        }
    }
    // The control-point solve stops at 1e-12 rad / 1e-12 m knot residual; frame instants are
    // rounded to whole nanoseconds, which moves a segment by at most ~10 rad/s * 0.5 ns.
    EXPECT_LT(worstRad, 1e-8);
    EXPECT_LT(worstM, 1e-8);
    EXPECT_LT(m.fitResidualRad(), 1e-12);
}

TEST(Motion, WithoutSmoothingTheSplinePassesThroughTheRawFrames) {
    MotionOptions o;
    o.smoothingHz = 0;
    const Motion m = walk(o);
    const BvhClip& clip = walkClip();
    double worst = 0;
    for (int f = 0; f < m.frameCount(); ++f) {
        // The pelvis is the root joint; its reference (frame 0) rotation is the identity.
        Vec3d t;
        Quatd root;
        clip.localPose(0, clip.frame(f + m.firstFrame()), t, root);
        worst = std::max(worst,
                         angleBetween(at(m, Segment::Pelvis, frameNs(m, f)).qWorldSegment, root));
    }
    EXPECT_LT(worst, 1e-8);  // as SplinePassesThroughEveryMocapFrame
}

TEST(Motion, SmoothingIsAGaussianLowPassWithTheGivenHalfPowerFrequency) {
    // A clip swinging about Y at f Hz, 120 frames/s; the swing rate's amplitude after smoothing,
    // relative to the unsmoothed 2 pi f A, is the smoother's gain at f.
    auto gain = [](double hz) {
        constexpr double kAmpDeg = 10;
        constexpr int kFrames = 480;
        std::string text =
            "HIERARCHY\nROOT R\n{\nOFFSET 0 0 0\nCHANNELS 1 Yrotation\n}\nMOTION\nFrames: " +
            std::to_string(kFrames) + "\nFrame Time: " + std::to_string(1.0 / 120) + "\n";
        for (int f = 0; f < kFrames; ++f) {
            text += std::to_string(kAmpDeg * std::sin(2 * std::numbers::pi * hz * f / 120)) + "\n";
        }
        const auto clip = parseBvh(text, "swing");
        EXPECT_TRUE(clip.ok()) << clip.error().message;
        const auto m = Motion::fromClip(*clip, rootOnlyMap());  // default smoothing: 10 Hz
        EXPECT_TRUE(m.ok()) << m.error().message;
        double peak = 0;
        for (std::int64_t t = 1'000'000'000; t < 3'000'000'000; t += 1'000'000) {
            peak = std::max(peak, std::abs(at(*m, Segment::Pelvis, t).omegaRadS.y()));
        }
        return peak / (2 * std::numbers::pi * hz * kAmpDeg * kRad);
    };
    // exp(-2 pi^2 sigma^2 f^2) with sigma = 0.1325 / 10 Hz; 2 % covers the frame-rate
    // quantisation of the kernel and of the peak search (1 ms steps).
    for (double hz : {2.0, 10.0, 30.0}) {
        const double sigma = 0.1325 / 10;
        const double expected = std::exp(-2 * std::pow(std::numbers::pi * sigma * hz, 2));
        EXPECT_NEAR(gain(hz), expected, 0.02) << hz << " Hz";
    }
}

TEST(Motion, SmoothingKeepsTheWalksAccelerationsHuman) {
    MotionOptions raw;
    raw.smoothingHz = 0;
    double smoothPeak = 0;
    double rawPeak = 0;
    const Motion rawWalk = walk(raw);
    for (std::int64_t t = 0; t < walk().durationNs(); t += 1'000'000) {
        smoothPeak = std::max(smoothPeak, at(walk(), Segment::Pelvis, t).accelerationMps2.norm());
        rawPeak = std::max(rawPeak, at(rawWalk, Segment::Pelvis, t).accelerationMps2.norm());
    }
    // Walking moves the pelvis with peaks of a few m/s^2; the clip's frame-to-frame jitter,
    // interpolated as is, reaches tens of g.
    EXPECT_LT(smoothPeak, 9.81);
    EXPECT_GT(rawPeak, 5 * smoothPeak);
}

TEST(Motion, WalkClipMotionStartsAfterItsTPoseFrame) {
    const Motion& m = walk();
    EXPECT_EQ(m.firstFrame(), 1);
    EXPECT_EQ(m.frameCount(), 523);
    EXPECT_EQ(m.reference().kind, ReferencePose::Kind::Frame);
    EXPECT_EQ(m.reference().frame, 0);
}

TEST(Motion, ReferenceFrameMakesEverySegmentIdentity) {
    MotionOptions o;
    o.firstFrame = 0;  // start the motion at the reference, the clip's T-pose frame
    o.smoothingHz = 0;
    const Motion m = walk(o);
    for (const auto& s : board::kSegments) {
        EXPECT_LT(angleBetween(at(m, s.id, 0).qWorldSegment, Quatd::Identity()), 1e-12) << s.name;
    }
}

TEST(Motion, ReferenceFrameIsSelectable) {
    MotionOptions o;
    o.reference = ReferencePose{ReferencePose::Kind::Frame, 100};
    o.smoothingHz = 0;  // the raw frame 100, not its smoothed neighbourhood
    const Motion m = walk(o);
    for (const auto& s : board::kSegments) {
        // File frame 100 is motion frame 99: the motion starts at file frame 1.
        EXPECT_LT(angleBetween(at(m, s.id, frameNs(m, 100 - m.firstFrame())).qWorldSegment,
                               Quatd::Identity()),
                  1e-8)
            << s.name;
    }
}

TEST(Motion, ReferenceFrameOutsideTheClipIsAnError) {
    const BvhClip clip = load(kData / "cmu_12_01_walk.bvh");
    MotionOptions o;
    o.reference = ReferencePose{ReferencePose::Kind::Frame, 524};
    const auto m = Motion::fromClip(clip, *findBuiltInJointMap("cmu-motionbuilder"), o);
    ASSERT_FALSE(m.ok());
    EXPECT_THAT(m.error().message, HasSubstr("reference frame 524 is outside the clip (frames 0 "
                                             "to 523)"));
}

TEST(Motion, PositionsAreInMetresOfTheMapsUnit) {
    MotionOptions o;
    o.firstFrame = 0;
    o.smoothingHz = 0;
    const Motion m = walk(o);
    // CMU: the root is 16.2134 units above the floor in frame 0, 1 unit = 0.056444 m.
    EXPECT_NEAR(at(m, Segment::Pelvis, 0).positionM.y(), 16.2134 * 0.056444, 1e-9);
    o.unitM = 0.1;
    EXPECT_NEAR(at(walk(o), Segment::Pelvis, 0).positionM.y(), 1.62134, 1e-9);
}

// In metres the clip must be a body: an OFFSET of 1e50 (or a unit of 1e300 m) made every figure
// of an evaluation nan or inf; a unit that makes a bone longer than 2 m is the wrong one.
TEST(Motion, AClipThatIsNotABodyInMetresIsAnError) {
    MotionOptions o;
    o.unitM = 1.0;  // the CMU walk in its own units: a femur of 7.6 m
    const auto giant = Motion::fromClip(walkClip(), *findBuiltInJointMap("cmu-motionbuilder"), o);
    ASSERT_FALSE(giant.ok());
    EXPECT_THAT(giant.error().message, HasSubstr("more than a body's bone (2 m)"));
    const std::string far =
        "HIERARCHY\nROOT R\n{\nOFFSET 0 0 0\nCHANNELS 3 Xposition Yposition Zposition\n"
        "End Site\n{\nOFFSET 1e50 0 0\n}\n}\nMOTION\nFrames: 1\nFrame Time: 0.01\n0 1 0\n";
    const auto bone = Motion::fromClip(*parseBvh(far, "far"), rootOnlyMap());
    ASSERT_FALSE(bone.ok());
    EXPECT_THAT(bone.error().message,
                HasSubstr("line 2: joint 'R': its End Site OFFSET is 1e+50 m"));
    const std::string away =
        "HIERARCHY\nROOT R\n{\nOFFSET 0 0 0\nCHANNELS 3 Xposition Yposition Zposition\n"
        "End Site\n{\nOFFSET 0.1 0 0\n}\n}\nMOTION\nFrames: 2\nFrame Time: 0.01\n0 1 0\n"
        "0 1 1e300\n";
    const auto position = Motion::fromClip(*parseBvh(away, "away"), rootOnlyMap());
    ASSERT_FALSE(position.ok());
    EXPECT_THAT(position.error().message, HasSubstr("frame 1: joint 'R': a position of 1e+300 m"));
}

TEST(Motion, AClipWithoutAUnitIsAnError) {
    JointMap map = rootOnlyMap();
    map.unitM.reset();
    const auto m = Motion::fromClip(turningClip(1, 5), map);
    ASSERT_FALSE(m.ok());
    EXPECT_THAT(m.error().message, HasSubstr("no length unit"));
}

TEST(Motion, ConstantRateRotationHasConstantAngularVelocity) {
    const auto m = Motion::fromClip(turningClip(1.0, 50), rootOnlyMap());
    ASSERT_TRUE(m.ok()) << m.error().message;
    const Vec3d expected(0, 100 * kRad, 0);  // 1 degree per 10 ms frame
    for (double f = 0; f < 49; f += 0.37) {
        const SegmentState st = at(*m, Segment::Pelvis, frameNs(*m, f));
        // Equal steps make the cumulative B-spline an exact constant-rate rotation.
        EXPECT_LT((st.omegaRadS - expected).norm(), 1e-9) << f;
        EXPECT_LT(st.alphaRadS2.norm(), 1e-7) << f;
    }
}

TEST(Motion, AngularVelocityIsTheDerivativeOfOrientation) {
    const Motion& m = walk();
    constexpr std::int64_t kH = 10'000;  // 10 us
    double worst = 0;
    for (std::int64_t t : interiorInstants(m, 300)) {
        for (const auto& s : board::kSegments) {
            const SegmentState a = at(m, s.id, t - kH);
            const SegmentState b = at(m, s.id, t + kH);
            const Vec3d fd =
                toRotationVector<double>(a.qWorldSegment.conjugate() * b.qWorldSegment) /
                (2 * static_cast<double>(kH) * 1e-9);
            worst = std::max(worst, (fd - at(m, s.id, t).omegaRadS).norm());
        }
    }
    // Central-difference truncation is h^2/6 times the third derivative, under 1e-6 rad/s for
    // h = 10 us and mocap jerk below 1e4 rad/s^3; double rounding adds ~1e-16 / 2e-5 s.
    EXPECT_LT(worst, 1e-5);
}

TEST(Motion, AngularAccelerationIsTheDerivativeOfAngularVelocity) {
    const Motion& m = walk();
    constexpr std::int64_t kH = 10'000;
    double worst = 0;
    for (std::int64_t t : interiorInstants(m, 300)) {
        for (const auto& s : board::kSegments) {
            const Vec3d fd = (at(m, s.id, t + kH).omegaRadS - at(m, s.id, t - kH).omegaRadS) /
                             (2 * static_cast<double>(kH) * 1e-9);
            worst = std::max(worst, (fd - at(m, s.id, t).alphaRadS2).norm());
        }
    }
    // Body-frame omega differentiates to body-frame alpha; same truncation argument as above,
    // one derivative higher (snap inside a cubic segment is bounded, ~1e7 rad/s^4 at most).
    EXPECT_LT(worst, 1e-3);
}

TEST(Motion, VelocityAndAccelerationAreDerivativesOfPosition) {
    const Motion& m = walk();
    constexpr std::int64_t kH = 10'000;
    double worstV = 0;
    double worstA = 0;
    for (std::int64_t t : interiorInstants(m, 300)) {
        for (const auto& s : board::kSegments) {
            const SegmentState a = at(m, s.id, t - kH);
            const SegmentState b = at(m, s.id, t + kH);
            const SegmentState c = at(m, s.id, t);
            worstV = std::max(
                worstV,
                ((b.positionM - a.positionM) / (2 * static_cast<double>(kH) * 1e-9) - c.velocityMps)
                    .norm());
            worstA = std::max(
                worstA, ((b.velocityMps - a.velocityMps) / (2 * static_cast<double>(kH) * 1e-9) -
                         c.accelerationMps2)
                            .norm());
        }
    }
    // Positions are cubic polynomials inside a frame interval: the central difference of a cubic
    // is exact up to h^2/6 times its constant third derivative, and of its derivative exactly.
    EXPECT_LT(worstV, 1e-6);
    EXPECT_LT(worstA, 1e-4);
}

TEST(Motion, AngularVelocityAndLinearAccelerationAreContinuousAcrossFrames) {
    const Motion& m = walk();
    double worstOmegaJump = 0;
    double worstAlphaJump = 0;
    double worstAccelJump = 0;
    double largestAlpha = 0;
    for (int f = 1; f < m.frameCount() - 1; ++f) {
        const std::int64_t t = frameNs(m, f);
        for (const auto& s : board::kSegments) {
            // Just before and at the knot: evaluated on the two neighbouring spline pieces.
            const SegmentState a = at(m, s.id, t - 1);
            const SegmentState b = at(m, s.id, t);
            worstOmegaJump = std::max(worstOmegaJump, (b.omegaRadS - a.omegaRadS).norm());
            worstAlphaJump = std::max(worstAlphaJump, (b.alphaRadS2 - a.alphaRadS2).norm());
            worstAccelJump =
                std::max(worstAccelJump, (b.accelerationMps2 - a.accelerationMps2).norm());
            largestAlpha = std::max(largestAlpha, b.alphaRadS2.norm());
        }
    }
    // In 1 ns the spline's own rates move by at most |jerk| * 1e-9 (jerk < 1e5 rad/s^3 and
    // m/s^3 here); a piecewise interpolation that is only C1 (Catmull-Rom, SQUAD) would jump by
    // a sizeable fraction of the largest alpha instead.
    EXPECT_LT(worstOmegaJump, 1e-6);
    EXPECT_LT(worstAlphaJump, 1e-3);
    EXPECT_LT(worstAccelJump, 1e-3);
    EXPECT_GT(largestAlpha, 10.0);  // the walk does move: the bounds above are not vacuous
}

TEST(Motion, OutsideTheClipThePoseIsHeldAndStill) {
    const Motion& m = walk();
    const SegmentState before = at(m, Segment::LForearm, -1'000'000'000);
    const SegmentState after = at(m, Segment::LForearm, m.durationNs() + 1'000'000'000);
    EXPECT_LT(angleBetween(before.qWorldSegment, m.keyOrientation(Segment::LForearm, 0)), 1e-12);
    EXPECT_LT(
        angleBetween(after.qWorldSegment, m.keyOrientation(Segment::LForearm, m.frameCount() - 1)),
        1e-12);
    EXPECT_EQ(after.omegaRadS, Vec3d::Zero());
    EXPECT_EQ(after.accelerationMps2, Vec3d::Zero());
}

TEST(Motion, ApproximatingSplineMissesFramesByASixthOfTheirSecondDifference) {
    MotionOptions o;
    o.interpolate = false;
    const Motion m = walk(o);
    double worst = 0;
    double bound = 0;
    for (int f = 1; f < m.frameCount() - 1; ++f) {
        for (const auto& s : board::kSegments) {
            worst = std::max(worst, angleBetween(at(m, s.id, frameNs(m, f)).qWorldSegment,
                                                 m.keyOrientation(s.id, f)));
            const Quatd a = m.keyOrientation(s.id, f - 1);
            const Quatd b = m.keyOrientation(s.id, f);
            const Quatd c = m.keyOrientation(s.id, f + 1);
            const Vec3d second = toRotationVector<double>(b.conjugate() * c) -
                                 toRotationVector<double>(a.conjugate() * b);
            bound = std::max(bound, second.norm() / 6);
        }
    }
    // With the frames as control points the value at a knot is (c[k-1] + 4 c[k] + c[k+1]) / 6,
    // off c[k] by a sixth of the second difference; 10 % covers the group (non-vector) form.
    EXPECT_LT(worst, bound * 1.1);
    EXPECT_GT(worst, bound * 0.5);  // and it does smooth: the frames are not interpolated
}

TEST(Motion, UserRigSegmentsAreIdentityInItsRestPose) {
    const BvhClip clip = load(kData / "unity_rig.bvh");
    const auto map = loadJointMap(kData / "unity_rig.toml");
    ASSERT_TRUE(map.ok()) << map.error().message;
    const auto m = Motion::fromClip(clip, *map);
    ASSERT_TRUE(m.ok()) << m.error().message;
    for (const auto& s : board::kSegments) {
        // Frame 0 of the rig is its rest pose (all rotations zero).
        EXPECT_LT(angleBetween(at(*m, s.id, 0).qWorldSegment, Quatd::Identity()), 1e-12) << s.name;
    }
    // Frame 3: the twist bone turned 60 degrees about the arm, the arm itself -30 about Z; the
    // upper arm segment carries both (most distal joint's orientation).
    const Quatd expected = Quatd(Eigen::AngleAxisd(15 * kRad, Vec3d::UnitY())) *
                           Quatd(Eigen::AngleAxisd(-30 * kRad, Vec3d::UnitZ())) *
                           Quatd(Eigen::AngleAxisd(60 * kRad, Vec3d::UnitX()));
    EXPECT_LT(angleBetween(at(*m, Segment::LUpperarm, frameNs(*m, 3)).qWorldSegment, expected),
              1e-9);
    // Its position is the first joint's, UpperArm_L: 95+8+12+14+10 = 139 cm up, 18 cm left.
    EXPECT_LT((at(*m, Segment::LUpperarm, 0).positionM - Vec3d(0.18, 1.39, 0)).norm(), 1e-12);
    // r_middistal is not in the rig: it moves with r_hindfoot.
    EXPECT_FALSE(m->mapped(Segment::RMiddistal));
    EXPECT_LT(angleBetween(at(*m, Segment::RMiddistal, frameNs(*m, 2)).qWorldSegment,
                           at(*m, Segment::RHindfoot, frameNs(*m, 2)).qWorldSegment),
              1e-15);
}

TEST(Motion, SyntheticTPoseMatchesARestPoseThatIsATPose) {
    const BvhClip clip = load(kData / "unity_rig.bvh");
    const auto map = loadJointMap(kData / "unity_rig.toml");
    ASSERT_TRUE(map.ok());
    MotionOptions o;
    o.reference = ReferencePose{ReferencePose::Kind::TPose, 0};
    const auto m = Motion::fromClip(clip, *map, o);
    ASSERT_TRUE(m.ok()) << m.error().message;
    for (const auto& s : board::kSegments) {
        const double angle = angleBetween(at(*m, s.id, 0).qWorldSegment, Quatd::Identity());
        if (s.id == Segment::LHindfoot) {
            // The rig's feet point down (ankle to toes (0, -7, 12), to the right foot's End Site
            // (0, -7, 18)): the synthetic T-pose lays them flat.
            EXPECT_NEAR(angle, std::atan2(7.0, 12.0), 1e-9) << s.name;
        } else if (s.id == Segment::RHindfoot || s.id == Segment::RMiddistal) {
            EXPECT_NEAR(angle, std::atan2(7.0, 18.0), 1e-9) << s.name;
        } else {
            // Everything else is already along its T-pose direction in the rest pose.
            EXPECT_LT(angle, 1e-9) << s.name;
        }
    }
}

TEST(Motion, StartOfThe3dsMaxClipHasArmsDownAndLegsVertical) {
    const auto path = kShared / "cmu_131_01_start_walk_stop.bvh";
    if (!std::filesystem::exists(path)) {
        GTEST_SKIP() << "shared data absent: " << path;
    }
    const BvhClip clip = load(path);
    const auto m = Motion::fromClip(clip, *detectJointMap(clip));  // synthetic T-pose reference
    ASSERT_TRUE(m.ok()) << m.error().message;
    EXPECT_EQ(m->reference().kind, ReferencePose::Kind::TPose);
    // The subject stands at the start: upper arms hang (T-pose +X/-X now points down), thighs
    // and shanks point down. 35 degrees allows for a natural standing posture.
    const double cosTol = std::cos(35 * kRad);
    const auto down = -Vec3d::UnitY();
    EXPECT_GT((at(*m, Segment::LUpperarm, 0).qWorldSegment * Vec3d::UnitX()).dot(down), cosTol);
    EXPECT_GT((at(*m, Segment::RUpperarm, 0).qWorldSegment * -Vec3d::UnitX()).dot(down), cosTol);
    for (Segment s : {Segment::LThigh, Segment::RThigh, Segment::LCalf, Segment::RCalf}) {
        EXPECT_GT((at(*m, s, 0).qWorldSegment * down).dot(down), cosTol) << board::segmentName(s);
    }
    for (Segment s : {Segment::L5, Segment::T12, Segment::C7, Segment::Skull}) {
        EXPECT_GT((at(*m, s, 0).qWorldSegment * Vec3d::UnitY()).dot(Vec3d::UnitY()), cosTol)
            << board::segmentName(s);
    }
}

}  // namespace
}  // namespace caphub::board::sim
