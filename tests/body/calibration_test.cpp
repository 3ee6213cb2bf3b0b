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

// Each nominal mounting turned about a random axis by up to maxRad: straps as worn.
std::array<Quatd, kSegmentCount> strapped(std::mt19937& rng,
                                          const std::array<Quatd, kSegmentCount>& nominal,
                                          double maxRad) {
    std::array<Quatd, kSegmentCount> m;
    for (std::size_t i = 0; i < m.size(); ++i) {
        m[i] = (testing::randomRotation(rng, maxRad) * nominal[i]).normalized();
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

// What a free heading's mounting must be: of the rotations R_v(psi) * truth (the sensor turned
// about the world vertical, v in the segment's frame), the one closest to the nominal mounting:
// the error truth * nominal^-1 with its twist about v taken out (E = twist * swing, swing's axis
// perpendicular to v), on the nominal: the vertical-axis component the nominal's, the other two
// the truth's (gravity's).
Quatd nominalHeadingMounting(const Quatd& truth, const Quatd& nominal, const Vec3d& v) {
    const Quatd e = truth * nominal.conjugate();
    const double a = e.vec().dot(v);
    const Quatd twist = Quatd(e.w(), a * v.x(), a * v.y(), a * v.z()).normalized();
    return (twist.conjugate() * e * nominal).normalized();
}

// The segment frame's vertical in a reference pose.
Vec3d segmentUp(ReferencePoseKind pose, Segment s) {
    return referenceOrientation(pose, s).conjugate() * Vec3d::UnitY();
}

// A free (gyroscope-only) heading: the sensor's orientation off by an arbitrary turn about up.
// Its mounting takes the nominal heading about the vertical and the rest from gravity, exactly;
// the turn kept for it is the one that makes its orientations consistent with that mounting. A
// magnetic sensor beside it gets the mounting it gets without any free one.
void freeHeadingGetsTheNominalHeading(ReferencePoseKind pose) {
    std::mt19937 rng(31);
    std::uniform_real_distribution<double> anyTurn(-kPi, kPi);
    std::array<Quatd, kSegmentCount> nominal = randomMountings(rng);
    // Straps off by up to 20 deg about any axis (their vertical components included).
    const std::array<Quatd, kSegmentCount> truth = strapped(rng, nominal, 20 * kDeg);
    const double heading = 0.7;
    const SensorFrame magnetic =
        testing::sensorsFor(testing::referencePose(pose), truth, testing::kFullSuit, heading);
    SensorFrame f = magnetic;
    const SegmentMask free = bit(S::Pelvis) | bit(S::LForearm) | bit(S::RHand) | bit(S::LCalf) |
                             bit(S::Skull) | bit(S::RUpperarm);
    std::array<double, kSegmentCount> offset{};
    for (int i = 0; i < kSegmentCount; ++i) {
        if (has(free, i)) {
            offset[static_cast<std::size_t>(i)] = anyTurn(rng);
            f = withHeadingError(f, static_cast<Segment>(i), offset[static_cast<std::size_t>(i)]);
        }
    }
    CalibrationOptions o;
    o.nominalMounting = nominal;
    o.headingFrom = ~free;
    CalibrationOptions allMagnetic = o;
    o.freeHeading = free;
    auto cal = calibrateOnePose(pose, f, o);
    auto plain = calibrateOnePose(pose, f, allMagnetic);
    ASSERT_TRUE(cal.ok()) << cal.error().message;
    ASSERT_TRUE(plain.ok());
    EXPECT_EQ(cal->freeHeading, free);
    EXPECT_EQ(cal->nominalHeading, free);
    EXPECT_EQ(cal->headingRad, plain->headingRad);
    for (int i = 0; i < kSegmentCount; ++i) {
        if (!has(testing::kFullSuit, i)) {
            continue;
        }
        const auto u = static_cast<std::size_t>(i);
        const auto s = static_cast<Segment>(i);
        const Quatd& m = cal->mounting[u];
        if (!has(free, i)) {
            // Untouched: the same numbers to the last digit.
            EXPECT_EQ(m.coeffs(), plain->mounting[u].coeffs()) << board::segmentName(s);
            EXPECT_EQ(cal->headingTurnRad[u], 0.0);
            continue;
        }
        const Vec3d v = segmentUp(pose, s);
        EXPECT_LT(angleBetween(m, nominalHeadingMounting(truth[u], nominal[u], v)), 1e-9)
            << board::segmentName(s);
        // Gravity's part: the vertical seen from the sensor is the true one.
        EXPECT_LT((m.conjugate() * v - truth[u].conjugate() * v).norm(), 1e-9);
        // The vertical-axis part: no twist about v left between it and the nominal mounting.
        EXPECT_NEAR((m * nominal[u].conjugate()).vec().dot(v), 0.0, 1e-9);
        // The turn makes the sensor's orientation the one that mounting implies in the capture
        // world (the subject in the pose, facing the estimated heading).
        const Quatd turned =
            Quatd(Eigen::AngleAxisd(cal->headingTurnRad[u], Vec3d::UnitZ())) * f.qEnuSensor[u];
        EXPECT_LT(angleBetween(turned, cal->qEnuWorld() * referenceOrientation(pose, s) * m), 1e-9);
        EXPECT_GT(std::abs(cal->headingTurnRad[u]), 0.0);
        EXPECT_LE(std::abs(cal->headingTurnRad[u]), kPi);
    }
}

TEST(FreeHeadingCalibration, TPoseTakesTheNominalHeadingAndGravityExactly) {
    freeHeadingGetsTheNominalHeading(ReferencePoseKind::T);
}

TEST(FreeHeadingCalibration, NPoseTakesTheNominalHeadingAndGravityExactly) {
    freeHeadingGetsTheNominalHeading(ReferencePoseKind::N);
}

// A strap off by a tilt alone (no vertical component): the free sensor's mounting is the true one
// and its turn undoes its heading offset exactly (the capture heading known).
TEST(FreeHeadingCalibration, ATiltedStrapGivesTheTrueMountingAndUndoesTheOffset) {
    std::mt19937 rng(37);
    std::array<Quatd, kSegmentCount> nominal = randomMountings(rng);
    std::array<Quatd, kSegmentCount> truth = nominal;
    const double offset = 2.5;  // rad: the free heading's
    truth[idx(S::LThigh)] =
        (fromAxisAngle<double>(Vec3d::UnitX(), 12 * kDeg) * nominal[idx(S::LThigh)]).normalized();
    SensorFrame f =
        withHeadingError(testing::sensorsFor(testing::referencePose(ReferencePoseKind::T), truth,
                                             testing::kFullSuit, -0.3),
                         S::LThigh, offset);
    CalibrationOptions o;
    o.nominalMounting = nominal;
    o.headingRad = -0.3;
    o.freeHeading = bit(S::LThigh);
    auto cal = calibrateOnePose(ReferencePoseKind::T, f, o);
    ASSERT_TRUE(cal.ok());
    EXPECT_LT(angleBetween(cal->mounting[idx(S::LThigh)], truth[idx(S::LThigh)]), 1e-9);
    EXPECT_NEAR(std::remainder(cal->headingTurnRad[idx(S::LThigh)] + offset, 2 * kPi), 0.0, 1e-9);
}

// An unchecked (raw) heading is checked against the strap: one turned 60 deg off is wrong and
// taken as free (the nominal heading, its turn kept); one right with a strap turned 10 deg about
// the vertical keeps its measured mounting exactly. The capture heading is known, as when it
// comes from the corrected sensors.
TEST(FreeHeadingCalibration, AnUncheckedHeadingNoStrapExplainsIsTakenAsFree) {
    std::mt19937 rng(43);
    std::array<Quatd, kSegmentCount> nominal = randomMountings(rng);
    std::array<Quatd, kSegmentCount> truth = nominal;
    const Vec3d up = segmentUp(ReferencePoseKind::T, S::LThigh);
    // Both straps turned 10 deg about the segment's vertical (and a little tilt for the wrong one).
    truth[idx(S::LThigh)] =
        (fromAxisAngle<double>(up, 10 * kDeg) * nominal[idx(S::LThigh)]).normalized();
    truth[idx(S::RCalf)] =
        (fromAxisAngle<double>(Vec3d(0.3, 1, 0).normalized(), 10 * kDeg) * nominal[idx(S::RCalf)])
            .normalized();
    const double heading = -0.4;
    const SensorFrame magnetic = testing::sensorsFor(testing::referencePose(ReferencePoseKind::T),
                                                     truth, testing::kFullSuit, heading);
    const SensorFrame f = withHeadingError(magnetic, S::RCalf, 60 * kDeg);
    CalibrationOptions o;
    o.nominalMounting = nominal;
    o.headingRad = heading;
    const CalibrationOptions plainOptions = o;
    o.checkHeading = bit(S::LThigh) | bit(S::RCalf);
    auto cal = calibrateOnePose(ReferencePoseKind::T, f, o);
    auto plain = calibrateOnePose(ReferencePoseKind::T, f, plainOptions);
    ASSERT_TRUE(cal.ok()) << cal.error().message;
    ASSERT_TRUE(plain.ok());
    EXPECT_EQ(cal->freeHeading, bit(S::RCalf));
    EXPECT_EQ(cal->nominalHeading, bit(S::RCalf));
    // The right one: measured, the same numbers as with no check, the true mounting, no turn.
    EXPECT_EQ(cal->mounting[idx(S::LThigh)].coeffs(), plain->mounting[idx(S::LThigh)].coeffs());
    EXPECT_LT(angleBetween(cal->mounting[idx(S::LThigh)], truth[idx(S::LThigh)]), 1e-9);
    EXPECT_EQ(cal->headingTurnRad[idx(S::LThigh)], 0.0);
    // The wrong one: as a free heading (the nominal heading about the vertical, gravity's rest),
    // its turn undoing the 60 deg less the strap's own turn about the vertical.
    const Quatd& m = cal->mounting[idx(S::RCalf)];
    EXPECT_LT(angleBetween(m, nominalHeadingMounting(truth[idx(S::RCalf)], nominal[idx(S::RCalf)],
                                                     segmentUp(ReferencePoseKind::T, S::RCalf))),
              1e-9);
    EXPECT_GT(angleBetween(plain->mounting[idx(S::RCalf)], truth[idx(S::RCalf)]), 50 * kDeg);
    EXPECT_NEAR(cal->headingTurnRad[idx(S::RCalf)], -60 * kDeg, 11 * kDeg);
    // Past the bound the same right heading is not plausible any more.
    o.plausibleTurnRad = 5 * kDeg;
    auto strict = calibrateOnePose(ReferencePoseKind::T, f, o);
    ASSERT_TRUE(strict.ok());
    EXPECT_EQ(strict->freeHeading, bit(S::LThigh) | bit(S::RCalf));
}

// T+N measures an arm's mounting whole from two gravity directions: a free heading changes
// nothing of it (mode measured), and its turn is fitted to it; the trunk's free sensors take
// the nominal heading.
TEST(FreeHeadingCalibration, TwoPoseArmsAreMeasuredAndTheirTurnFitted) {
    std::mt19937 rng(41);
    std::array<Quatd, kSegmentCount> nominal = randomMountings(rng);
    const std::array<Quatd, kSegmentCount> truth = strapped(rng, nominal, 20 * kDeg);
    const SegmentMask free = bit(S::LForearm) | bit(S::RUpperarm) | bit(S::Pelvis);
    const double heading = 1.2;
    SensorFrame t = testing::sensorsFor(testing::referencePose(ReferencePoseKind::T), truth,
                                        testing::kFullSuit, heading);
    SensorFrame n = testing::sensorsFor(testing::referencePose(ReferencePoseKind::N), truth,
                                        testing::kFullSuit, heading);
    std::array<double, kSegmentCount> offset{};
    offset[idx(S::LForearm)] = 1.9;
    offset[idx(S::RUpperarm)] = -2.8;
    offset[idx(S::Pelvis)] = 0.6;
    for (Segment s : {S::LForearm, S::RUpperarm, S::Pelvis}) {
        t = withHeadingError(t, s, offset[idx(s)]);
        n = withHeadingError(n, s, offset[idx(s)]);
    }
    CalibrationOptions o;
    o.nominalMounting = nominal;
    o.headingRad = heading;
    o.freeHeading = free;
    auto cal = calibrateTwoPose(t, n, o);
    ASSERT_TRUE(cal.ok()) << cal.error().message;
    EXPECT_EQ(cal->freeHeading, free);
    EXPECT_EQ(cal->nominalHeading, bit(S::Pelvis));
    for (Segment s : {S::LForearm, S::RUpperarm}) {
        EXPECT_LT(angleBetween(cal->mounting[idx(s)], truth[idx(s)]), 1e-6)
            << board::segmentName(s);
        EXPECT_NEAR(std::remainder(cal->headingTurnRad[idx(s)] + offset[idx(s)], 2 * kPi), 0.0,
                    1e-6);
    }
    const Vec3d up = Vec3d::UnitY();
    EXPECT_LT(
        (cal->mounting[idx(S::Pelvis)].conjugate() * up - truth[idx(S::Pelvis)].conjugate() * up)
            .norm(),
        1e-9);
}

TEST(CalibrationText, FreeHeadingsRoundTripAndOldTextsReadAsMeasured) {
    BodyCalibration c;
    c.method = CalibrationMethod::TPose;
    c.mask = bit(S::Pelvis) | bit(S::LHand) | bit(S::RHand);
    c.freeHeading = bit(S::LHand) | bit(S::RHand);
    c.nominalHeading = bit(S::LHand);
    c.headingTurnRad[idx(S::LHand)] = -2.75;
    c.headingTurnRad[idx(S::RHand)] = 0.125;
    const std::string text = toText(c);
    EXPECT_THAT(text, HasSubstr("heading_free l_hand -2.75 nominal-heading\n"));
    EXPECT_THAT(text, HasSubstr("heading_free r_hand 0.125 measured\n"));
    auto back = parseBodyCalibration(text, "cal.txt");
    ASSERT_TRUE(back.ok()) << back.error().message;
    EXPECT_EQ(back->freeHeading, c.freeHeading);
    EXPECT_EQ(back->nominalHeading, c.nominalHeading);
    EXPECT_EQ(back->headingTurnRad, c.headingTurnRad);
    // A calibration without a free heading writes what it always did; such a text reads with
    // none.
    c.freeHeading = 0;
    EXPECT_THAT(toText(c), ::testing::Not(HasSubstr("heading_free")));
    auto old = parseBodyCalibration(
        "method tpose\ntime_ns 5\nheading_rad 0.5\nmounting pelvis 1 0 0 0\n", "old.cap");
    ASSERT_TRUE(old.ok()) << old.error().message;
    EXPECT_EQ(old->freeHeading, 0U);
    EXPECT_EQ(old->nominalHeading, 0U);
    // Bad lines, with their numbers.
    auto r = parseBodyCalibration("method tpose\nheading_free pelvis 0.5 guessed\n", "rec.cap");
    ASSERT_FALSE(r.ok());
    EXPECT_THAT(r.error().message, HasSubstr("rec.cap:2: heading_free: expected nominal-heading"));
    r = parseBodyCalibration(
        "method tpose\nmounting pelvis 1 0 0 0\nheading_free l_hand 0.5 "
        "measured\n",
        "rec.cap");
    ASSERT_FALSE(r.ok());
    EXPECT_THAT(r.error().message,
                HasSubstr("rec.cap:3: heading_free l_hand: expected a mounting"));
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
