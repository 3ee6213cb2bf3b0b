// Calibration to the body: T-pose, N-pose, T+N and the heading reset recover mountings from
// sensor orientations generated from known poses and mountings.
#include <numbers>
#include <random>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "fusion/body/body_calibration.h"
#include "fusion/body/pose_solver.h"
#include "tests/body/test_poses.h"

namespace caphub::body {
namespace {

using ::testing::HasSubstr;
using S = Segment;
constexpr double kPi = std::numbers::pi;
constexpr double kDeg = kPi / 180;

std::array<Quatd, kSegmentCount> randomMountings(std::mt19937& rng) {
    std::array<Quatd, kSegmentCount> m;
    for (auto& q : m) {
        q = testing::randomRotation(rng, kPi);
    }
    return m;
}

double worstError(const BodyCalibration& cal, const std::array<Quatd, kSegmentCount>& truth,
                  SegmentMask mask) {
    double worst = 0;
    for (int i = 0; i < kSegmentCount; ++i) {
        if (has(mask, i)) {
            worst = std::max(worst, angleBetween(cal.mounting[static_cast<std::size_t>(i)],
                                                 truth[static_cast<std::size_t>(i)]));
        }
    }
    return worst;
}

// A yaw error of one sensor's fused heading (as a magnetic disturbance near the body makes).
SensorFrame withHeadingError(SensorFrame f, Segment s, double rad) {
    const Quatd turn(Eigen::AngleAxisd(rad, Vec3d::UnitZ()));  // about ENU up
    f.qEnuSensor[idx(s)] = turn * f.qEnuSensor[idx(s)];
    return f;
}

TEST(TPoseCalibration, RecoversRandomMountingsWithinOneDegree) {
    std::mt19937 rng(3);
    std::uniform_real_distribution<double> heading(-kPi, kPi);
    for (int trial = 0; trial < 10; ++trial) {
        const auto truth = randomMountings(rng);
        const double h = heading(rng);
        const SensorFrame f = testing::sensorsFor(testing::referencePose(ReferencePoseKind::T),
                                                  truth, testing::kAll, h);
        CalibrationOptions o;
        o.headingRad = h;
        auto cal = calibrateOnePose(ReferencePoseKind::T, f, o);
        ASSERT_TRUE(cal.ok()) << cal.error().message;
        // Ideal orientations: the only error left is rounding; 1 deg is the target.
        EXPECT_LT(worstError(*cal, truth, testing::kAll), 1 * kDeg);
        EXPECT_EQ(cal->method, CalibrationMethod::TPose);
    }
}

TEST(TPoseCalibration, EstimatesTheSubjectsHeadingThroughNominalMountings) {
    std::mt19937 rng(5);
    const auto truth = randomMountings(rng);
    const double h = 2.1;  // rad from north
    const SensorFrame f = testing::sensorsFor(testing::referencePose(ReferencePoseKind::T), truth,
                                              testing::kFullSuit, h);
    CalibrationOptions o;
    o.nominalMounting = truth;  // the board file is right
    auto cal = calibrateOnePose(ReferencePoseKind::T, f, o);
    ASSERT_TRUE(cal.ok());
    EXPECT_NEAR(cal->headingRad, h, 1e-9);
    EXPECT_LT(worstError(*cal, truth, testing::kFullSuit), 1e-6);
}

TEST(NPoseCalibration, RecoversRandomMountingsWithinOneDegree) {
    std::mt19937 rng(9);
    const auto truth = randomMountings(rng);
    const SensorFrame f = testing::sensorsFor(testing::referencePose(ReferencePoseKind::N), truth,
                                              testing::kAll, 0.4);
    CalibrationOptions o;
    o.headingRad = 0.4;
    auto cal = calibrateOnePose(ReferencePoseKind::N, f, o);
    ASSERT_TRUE(cal.ok());
    EXPECT_LT(worstError(*cal, truth, testing::kAll), 1 * kDeg);
}

TEST(TwoPoseCalibration, RecoversRandomMountingsWithinOneDegree) {
    std::mt19937 rng(13);
    const auto truth = randomMountings(rng);
    CalibrationOptions o;
    o.headingRad = -1.0;
    auto cal = calibrateTwoPose(testing::sensorsFor(testing::referencePose(ReferencePoseKind::T),
                                                    truth, testing::kAll, -1.0),
                                testing::sensorsFor(testing::referencePose(ReferencePoseKind::N),
                                                    truth, testing::kAll, -1.0),
                                o);
    ASSERT_TRUE(cal.ok()) << cal.error().message;
    EXPECT_LT(worstError(*cal, truth, testing::kAll), 1 * kDeg);
    EXPECT_EQ(cal->method, CalibrationMethod::TPlusN);
}

// In the N-pose the forearm's long axis is vertical, so the rotation of its sensor about that
// axis comes only from the sensor's heading; a 20 deg heading error becomes a 20 deg error about
// the long axis. The T-pose's gravity direction fixes that rotation in T+N.
TEST(TwoPoseCalibration, FixesALongAxisMountingErrorThatOnePoseCannot) {
    std::mt19937 rng(17);
    const auto truth = randomMountings(rng);
    CalibrationOptions o;
    o.headingRad = 0;
    const SensorFrame t =
        testing::sensorsFor(testing::referencePose(ReferencePoseKind::T), truth, testing::kAll);
    const SensorFrame n = withHeadingError(
        testing::sensorsFor(testing::referencePose(ReferencePoseKind::N), truth, testing::kAll),
        S::LForearm, 20 * kDeg);
    auto single = calibrateOnePose(ReferencePoseKind::N, n, o);
    ASSERT_TRUE(single.ok());
    const Quatd errN = truth[idx(S::LForearm)] * single->mounting[idx(S::LForearm)].conjugate();
    EXPECT_NEAR(angleBetween(errN, Quatd::Identity()), 20 * kDeg, 1e-9);
    // ... about the forearm's long axis (segment X).
    EXPECT_NEAR(std::abs(toAxisAngle(errN).axis.x()), 1.0, 1e-9);

    auto both = calibrateTwoPose(withHeadingError(t, S::LForearm, -35 * kDeg), n, o);
    ASSERT_TRUE(both.ok());
    EXPECT_LT(angleBetween(both->mounting[idx(S::LForearm)], truth[idx(S::LForearm)]), 1 * kDeg);
}

// The T-pose alone takes the rotation of an arm sensor about the vertical from its heading (or
// from the subject holding the arm exactly sideways); T+N uses gravity in both poses only.
TEST(TwoPoseCalibration, FixesArmHeldForwardInTheTPose) {
    std::mt19937 rng(19);
    const auto truth = randomMountings(rng);
    Pose tActual = testing::referencePose(ReferencePoseKind::T);
    for (S s : {S::RUpperarm, S::RForearm, S::RHand}) {
        // The right arm (along -X) turned 15 deg about up towards +Z: forward.
        tActual.qWorld[idx(s)] = Quatd(Eigen::AngleAxisd(15 * kDeg, Vec3d::UnitY()));
    }
    CalibrationOptions o;
    o.headingRad = 0;
    const SensorFrame t = testing::sensorsFor(tActual, truth, testing::kAll);
    const SensorFrame n =
        testing::sensorsFor(testing::referencePose(ReferencePoseKind::N), truth, testing::kAll);
    auto single = calibrateOnePose(ReferencePoseKind::T, t, o);
    ASSERT_TRUE(single.ok());
    EXPECT_NEAR(angleBetween(single->mounting[idx(S::RUpperarm)], truth[idx(S::RUpperarm)]),
                15 * kDeg, 1e-9);
    auto both = calibrateTwoPose(t, n, o);
    ASSERT_TRUE(both.ok());
    EXPECT_LT(angleBetween(both->mounting[idx(S::RUpperarm)], truth[idx(S::RUpperarm)]), 1 * kDeg);
}

TEST(TwoPoseCalibration, RefusesPosesWhereTheArmsDidNotMove) {
    const std::array<Quatd, kSegmentCount> truth = [] {
        std::array<Quatd, kSegmentCount> m;
        m.fill(Quatd::Identity());
        return m;
    }();
    const SensorFrame t =
        testing::sensorsFor(testing::referencePose(ReferencePoseKind::T), truth, testing::kAll);
    auto r = calibrateTwoPose(t, t, CalibrationOptions{});
    ASSERT_FALSE(r.ok());
    EXPECT_THAT(r.error().message, HasSubstr("l_upperarm"));
}

TEST(HeadingReset, TurnsTheWorldSoThePelvisFacesForward) {
    std::mt19937 rng(23);
    const auto truth = randomMountings(rng);
    CalibrationOptions o;
    o.headingRad = 0;
    auto cal = calibrateOnePose(
        ReferencePoseKind::T,
        testing::sensorsFor(testing::referencePose(ReferencePoseKind::T), truth, testing::kAll), o);
    ASSERT_TRUE(cal.ok());
    // Later the subject has turned 70 deg and bends a little; no pose is needed.
    Pose later = testing::randomPose(rng, 0.3);
    later.qLocal[0] = Quatd(Eigen::AngleAxisd(70 * kDeg, Vec3d::UnitY())) * later.qLocal[0];
    worldFromLocal(later);
    PoseSolver solver(testing::kAll);
    solver.setCalibration(*cal);
    const SensorFrame f = testing::sensorsFor(later, truth, testing::kAll);
    Pose solved;
    solver.solve(f, solved);
    BodyCalibration reset = *cal;
    headingReset(reset, solved);
    solver.setCalibration(reset);
    solver.solve(f, solved);
    const Vec3d z = solved.qWorld[0] * Vec3d::UnitZ();
    EXPECT_NEAR(std::atan2(z.x(), z.z()), 0, 1e-9);
    // Joint rotations are untouched by a heading change.
    for (int i = 1; i < kSegmentCount; ++i) {
        EXPECT_LT(angleBetween(solved.qLocal[static_cast<std::size_t>(i)],
                               later.qLocal[static_cast<std::size_t>(i)]),
                  1e-9);
    }
}

TEST(CalibrationText, RoundTrips) {
    std::mt19937 rng(29);
    BodyCalibration c;
    c.method = CalibrationMethod::TPlusN;
    c.tNs = 123456789;
    c.headingRad = 0.25;
    c.mask = testing::kFullSuit;
    for (int i = 0; i < kSegmentCount; ++i) {
        c.mounting[static_cast<std::size_t>(i)] =
            has(c.mask, i) ? testing::randomRotation(rng, kPi) : Quatd::Identity();
    }
    auto back = parseBodyCalibration(toText(c), "cal.txt");
    ASSERT_TRUE(back.ok()) << back.error().message;
    EXPECT_EQ(back->method, c.method);
    EXPECT_EQ(back->tNs, c.tNs);
    EXPECT_EQ(back->mask, c.mask);
    EXPECT_EQ(back->headingRad, c.headingRad);
    for (int i = 0; i < kSegmentCount; ++i) {
        EXPECT_EQ(back->mounting[static_cast<std::size_t>(i)].coeffs(),
                  c.mounting[static_cast<std::size_t>(i)].coeffs());
    }
}

TEST(CalibrationText, BadLineIsReportedWithItsNumber) {
    auto r = parseBodyCalibration("method tpose\nmounting l_elbow 1 0 0 0\n", "rec.cap");
    ASSERT_FALSE(r.ok());
    EXPECT_THAT(r.error().message, HasSubstr("rec.cap:2:"));
    EXPECT_THAT(r.error().message, HasSubstr("unknown segment 'l_elbow'"));
    r = parseBodyCalibration("method tpose\nheading_rad north\n", "rec.cap");
    ASSERT_FALSE(r.ok());
    EXPECT_THAT(r.error().message, HasSubstr("rec.cap:2: heading_rad: expected a number"));
}

TEST(Calibration, RejectsANonUnitQuaternionNamingTheSegment) {
    SensorFrame f;
    f.mask = bit(S::LCalf);
    f.qEnuSensor[idx(S::LCalf)] = Quatd(0, 0, 0, 0);
    auto r = calibrateOnePose(ReferencePoseKind::T, f, CalibrationOptions{});
    ASSERT_FALSE(r.ok());
    EXPECT_THAT(r.error().message, HasSubstr("l_calf"));
    EXPECT_THAT(r.error().message, HasSubstr("expected a finite unit quaternion"));
}

TEST(Calibration, RejectsAFrameWithoutSensors) {
    auto r = calibrateOnePose(ReferencePoseKind::T, SensorFrame{}, CalibrationOptions{});
    ASSERT_FALSE(r.ok());
    EXPECT_THAT(r.error().message, HasSubstr("expected at least one"));
}

}  // namespace
}  // namespace caphub::body
