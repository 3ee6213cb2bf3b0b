// Root translation: the stance foot stays where it touched the floor, standing still does not
// drift, and a jump has a flight phase that ends on the floor.
#include "fusion/body/root_tracker.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <optional>
#include <vector>

#include <gtest/gtest.h>

#include "fusion/body/body_solver.h"
#include "tests/body/test_poses.h"

namespace caphub::body {
namespace {

using S = Segment;
constexpr double kDeg = std::numbers::pi / 180;

Dimensions dims() {
    board::SubjectConfig s;
    s.heightM = 1.75;
    return *dimensionsFromSubject(s);
}

// Sensor frames with identity mountings and heading 0 for a pose given by joint rotations.
SensorFrame frameOf(Pose p) {
    worldFromLocal(p);
    std::array<Quatd, kSegmentCount> m;
    m.fill(Quatd::Identity());
    return testing::sensorsFor(p, m, testing::kFullSuit);
}

// Both legs bent a (hips -a, knees 2a, ankles -a: the feet flat under the hips), the trunk
// turned leanRad about the lateral axis at the lumbar joint.
Pose crouchPose(double a, double leanRad) {
    Pose p;
    p.qLocal[idx(S::L5)] = Quatd(Eigen::AngleAxisd(leanRad, Vec3d::UnitX()));
    for (S t : {S::LThigh, S::RThigh}) {
        p.qLocal[idx(t)] = Quatd(Eigen::AngleAxisd(-a, Vec3d::UnitX()));
    }
    for (S c : {S::LCalf, S::RCalf}) {
        p.qLocal[idx(c)] = Quatd(Eigen::AngleAxisd(2 * a, Vec3d::UnitX()));
    }
    for (S f : {S::LHindfoot, S::RHindfoot}) {
        p.qLocal[idx(f)] = Quatd(Eigen::AngleAxisd(-a, Vec3d::UnitX()));
    }
    return p;
}

BodySolver makeSolver(const Dimensions& d) {
    BodySolver s(Skeleton(d), testing::kFullSuit);
    BodyCalibration cal;
    cal.mask = testing::kFullSuit;
    s.setCalibration(cal);
    return s;
}

TEST(RootTracker, StandingStillKeepsTheRootInPlace) {
    const Dimensions d = dims();
    BodySolver s = makeSolver(d);
    s.resetRoot(0.5, -1.0);
    for (int k = 0; k < 200; ++k) {
        s.solve(frameOf(Pose{}), 0.01);
    }
    const Vec3d r = s.pose().positionM[0];
    EXPECT_NEAR(r.x(), 0.5, 1e-12);
    EXPECT_NEAR(r.z(), -1.0, 1e-12);
    // Feet flat on the floor: the root at hip height 0.530 H.
    EXPECT_NEAR(r.y(), 0.530 * 1.75, 1e-12);
}

TEST(RootTracker, TheStanceFootStaysWhereItTouchedTheFloor) {
    const Dimensions d = dims();
    BodySolver s = makeSolver(d);
    Vec3d start = Vec3d::Zero();
    for (int k = 0; k <= 50; ++k) {
        // The left leg straight and rolling from 20 deg forward to 20 deg back (the body passes
        // over it); the right leg lifted with a bent knee, its foot flat.
        const double phi = (-20.0 + 40.0 * k / 50) * kDeg;
        Pose p;
        p.qLocal[idx(S::LThigh)] = Quatd(Eigen::AngleAxisd(phi, Vec3d::UnitX()));
        p.qLocal[idx(S::LHindfoot)] = Quatd(Eigen::AngleAxisd(-phi, Vec3d::UnitX()));
        p.qLocal[idx(S::RThigh)] = Quatd(Eigen::AngleAxisd(-30 * kDeg, Vec3d::UnitX()));
        p.qLocal[idx(S::RCalf)] = Quatd(Eigen::AngleAxisd(60 * kDeg, Vec3d::UnitX()));
        p.qLocal[idx(S::RHindfoot)] = Quatd(Eigen::AngleAxisd(-30 * kDeg, Vec3d::UnitX()));
        s.solve(frameOf(p), 0.02);
        const Vec3d heel = pointOnSegment(s.pose(), idx(S::LHindfoot), d.leftFootPointM[0]);
        if (k == 0) {
            start = heel;
            EXPECT_EQ(s.rootTracker().phase(), ContactPhase::LeftStance);
        }
        // Rigid kinematics with a fixed anchor: only rounding moves it.
        EXPECT_LT((heel - start).norm(), 1e-9) << "frame " << k;
    }
    // The body passed over the foot: the root moved forward by 2 L sin(20 deg), L the leg
    // length from hip to ankle (0.491 H).
    const double leg = (0.245 + 0.246) * 1.75;
    EXPECT_NEAR(s.pose().positionM[0].z(), 2 * leg * std::sin(20 * kDeg), 1e-9);
}

TEST(RootTracker, AMovingFootDoesNotTakeOverFromTheStillOneEvenWhenLower) {
    // The push-off case: the left foot is planted flat while the right foot, pitched toes-down so
    // that its toe tip is the lowest foot point, moves forward. The still left foot must keep
    // carrying the body; anchoring the lowest point instead would drag the root with the right
    // foot.
    const Dimensions d = dims();
    BodySolver s = makeSolver(d);
    auto pose = [](double phi, double plantarRad) {
        Pose p;
        p.qLocal[idx(S::LThigh)] = Quatd(Eigen::AngleAxisd(phi, Vec3d::UnitX()));
        p.qLocal[idx(S::LHindfoot)] = Quatd(Eigen::AngleAxisd(-phi, Vec3d::UnitX()));
        p.qLocal[idx(S::RThigh)] = Quatd(Eigen::AngleAxisd(-phi, Vec3d::UnitX()));
        p.qLocal[idx(S::RHindfoot)] = Quatd(Eigen::AngleAxisd(phi + plantarRad, Vec3d::UnitX()));
        return p;
    };
    // Standing (the left heel is the first of the equally low points: the anchor), then the
    // right foot tips toes-down by 5 deg, then the body rolls over the left leg (0 to 20 deg,
    // easing in) while the right leg swings forward by as much.
    s.solve(frameOf(pose(0, 0)), 0.02);
    const Vec3d start = pointOnSegment(s.pose(), idx(S::LHindfoot), d.leftFootPointM[0]);
    const double plantar = 5 * kDeg;
    for (int k = 1; k <= 20; ++k) {
        s.solve(frameOf(pose(0, plantar * k / 20)), 0.02);
    }
    int rightToeLowest = 0;
    for (int k = 1; k <= 50; ++k) {
        const double phi = 20 * kDeg * (1 - std::cos(std::numbers::pi * k / 50)) / 2;
        s.solve(frameOf(pose(phi, plantar)), 0.02);
        const auto& y = s.feet().pointM;
        double lowest = 1e9;
        int at = 0;
        for (int q = 0; q < 6; ++q) {
            if (y[static_cast<std::size_t>(q)].y() < lowest) {
                lowest = y[static_cast<std::size_t>(q)].y();
                at = q;
            }
        }
        rightToeLowest += at == 5 ? 1 : 0;
        const Vec3d heel = pointOnSegment(s.pose(), idx(S::LHindfoot), d.leftFootPointM[0]);
        // Rigid kinematics with the left foot held: only rounding moves its heel horizontally
        // (vertically the body stands on its lowest point, the right toe, 1.8 cm lower).
        EXPECT_LT(std::hypot(heel.x() - start.x(), heel.z() - start.z()), 1e-9) << "frame " << k;
    }
    // The case is the intended one: the right toe tip was the lowest point throughout.
    EXPECT_EQ(rightToeLowest, 50);
    EXPECT_GT(s.pose().positionM[0].z(), 0.1);  // and the body did move forward
}

TEST(RootTracker, APlantedFootThatSlipsCarriesTheRootWithIt) {
    // Standing, the left heel anchored. The left foot's sensor reports the foot sliding forward
    // at 0.1 m/s and turning about the vertical at 0.5 rad/s: the anchored heel moves with the
    // foot (the sensor's velocity plus the rate crossed with the lever to the heel), and the
    // root with it. Still or not valid, the report moves nothing.
    const Dimensions d = dims();
    const Vec3d onFoot(0.0, 0.03, 0.06);  // the sensor on the hindfoot, segment frame
    const Vec3d velocity(0.0, 0.0, 0.1);
    const Vec3d rate(0.0, 0.5, 0.0);
    auto run = [&](bool valid, bool still) {
        BodySolver s = makeSolver(d);
        FootSensorMotion feet;
        feet.valid = {valid, false};
        feet.known = feet.valid;
        feet.still = {still, false};
        feet.velocityMps[0] = velocity;
        feet.rateRadS[0] = rate;
        feet.onFootM[0] = onFoot;
        s.solve(frameOf(Pose{}), 0.01, std::nullopt, &feet);
        const Vec3d start = s.pose().positionM[0];
        EXPECT_EQ(s.rootTracker().contactPoint(), 0);  // the left heel
        for (int k = 0; k < 100; ++k) {
            s.solve(frameOf(Pose{}), 0.01, std::nullopt, &feet);
        }
        return Vec3d(s.pose().positionM[0] - start);
    };
    const Pose reference = [&] {
        BodySolver s = makeSolver(d);
        s.solve(frameOf(Pose{}), 0.01);
        return s.pose();
    }();
    const Vec3d lever = pointOnSegment(reference, idx(S::LHindfoot), d.leftFootPointM[0]) -
                        pointOnSegment(reference, idx(S::LHindfoot), onFoot);
    const Vec3d slip = velocity + rate.cross(lever);    // m/s, held for 1 s
    ASSERT_GT(std::abs(rate.cross(lever).x()), 0.005);  // the lever's share is visible
    const Vec3d moved = run(true, false);
    EXPECT_NEAR(moved.x(), slip.x(), 1e-9);
    EXPECT_NEAR(moved.z(), slip.z(), 1e-9);
    EXPECT_NEAR(moved.y(), 0.0, 1e-12);  // along the floor only
    EXPECT_LT(run(true, true).norm(), 1e-12);
    EXPECT_LT(run(false, false).norm(), 1e-12);
}

TEST(RootTracker, AFootSlidingAfterItsSlipSpanCarriesTheRootOnlyAlongTheFloorAndFast) {
    // Standing, the left heel anchored, its foot's dead reckoning known but past the slip's
    // span (valid false): a turn on the spot whose pivot foot slides late. Sliding across at
    // 1 m/s along the floor, the heel moves with it (3 frames of 0.01 s: 3 cm); not when the
    // dead reckoning says the foot also moves up (its error shows), not at a speed its error
    // could have (below swingMps), not when it is no longer known.
    const Dimensions d = dims();
    auto run = [&](bool known, const Vec3d& velocity) {
        BodySolver s = makeSolver(d);
        FootSensorMotion feet;
        feet.valid = {false, false};
        feet.known = {known, false};
        feet.still = {false, false};
        feet.onFootM[0] = Vec3d(0.0, 0.03, 0.06);
        s.solve(frameOf(Pose{}), 0.01);
        const Vec3d start = s.pose().positionM[0];
        EXPECT_EQ(s.rootTracker().contactPoint(), 0);  // the left heel
        feet.velocityMps[0] = velocity;
        for (int k = 0; k < 3; ++k) {
            s.solve(frameOf(Pose{}), 0.01, std::nullopt, &feet);
        }
        return Vec3d(s.pose().positionM[0] - start);
    };
    const Vec3d moved = run(true, Vec3d(0.0, 0.0, 1.0));
    EXPECT_NEAR(moved.z(), 0.03, 1e-9);
    EXPECT_NEAR(moved.x(), 0.0, 1e-12);
    EXPECT_NEAR(moved.y(), 0.0, 1e-12);
    EXPECT_LT(run(true, Vec3d(0.0, 0.5, 1.0)).norm(), 1e-12);
    EXPECT_LT(run(true, Vec3d(0.0, 0.0, 0.4)).norm(), 1e-12);
    EXPECT_LT(run(false, Vec3d(0.0, 0.0, 1.0)).norm(), 1e-12);
}

TEST(RootTracker, ASkeletonWhosePointsAreNotFiniteNeverIndexesANonePoint) {
    // A clip whose offsets are 1e200 m: the feet's points come out infinite or NaN, no point
    // qualifies, and the least moving one was "none" (-1), then used as an index (a SIGBUS in
    // evaluate). The held point stays; the solve goes on.
    Dimensions d = dims();
    d.offsetM[idx(S::LCalf)] *= 1e200;
    d.offsetM[idx(S::RCalf)] *= 1e200;
    BodySolver s = makeSolver(d);
    for (int k = 0; k < 20; ++k) {
        s.solve(frameOf(crouchPose(0.1 * k, 0.0)), 0.01);
        EXPECT_GE(s.rootTracker().contactPoint(), 0);
    }
}

// Sitting: thighs forward (hips -90 deg), shanks at kneeDeg from the thighs, the feet flat
// with the shanks vertical; the trunk upright.
Pose sitPose(double kneeDeg) {
    Pose p;
    for (S t : {S::LThigh, S::RThigh}) {
        p.qLocal[idx(t)] = Quatd(Eigen::AngleAxisd(-90 * kDeg, Vec3d::UnitX()));
    }
    for (S c : {S::LCalf, S::RCalf}) {
        p.qLocal[idx(c)] = Quatd(Eigen::AngleAxisd(kneeDeg * kDeg, Vec3d::UnitX()));
    }
    return p;
}

double lowestFootPoint(const BodySolver& s) {
    double lowest = 1e9;
    for (const Vec3d& p : s.feet().pointM) {
        lowest = std::min(lowest, p.y());
    }
    return lowest + s.pose().positionM[0].y();
}

TEST(RootTracker, SeatedTheSeatCarriesTheBodyWhileTheFeetLift) {
    // Sitting with the feet on the floor, the centre of mass over the seat, well behind the
    // feet: after 0.1 s the seat carries the body. The legs then stretch out (the knees from
    // 90 to 30 deg), lifting the feet off the floor: the root must stay where it is. Held on
    // the lowest foot point, as before the seat, it would sink with the feet as they rise.
    const Dimensions d = dims();
    BodySolver s = makeSolver(d);
    for (int k = 0; k < 20; ++k) {
        s.solve(frameOf(sitPose(90)), 0.01);
    }
    ASSERT_EQ(s.rootTracker().phase(), ContactPhase::Seated);
    EXPECT_EQ(s.rootTracker().contactPoint(), 6);
    const Vec3d seated = s.pose().positionM[0];
    for (int k = 1; k <= 50; ++k) {
        s.solve(frameOf(sitPose(90 - 60.0 * k / 50)), 0.01);
        EXPECT_EQ(s.rootTracker().phase(), ContactPhase::Seated) << "frame " << k;
        EXPECT_LT((s.pose().positionM[0] - seated).norm(), 1e-9) << "frame " << k;
    }
    EXPECT_GT(lowestFootPoint(s), 0.1);  // the feet are well off the floor
    // The feet back on the floor, then drawn back under the hips (into a 60 deg crouch): once
    // the centre of mass is over them they carry the body again, on the floor.
    for (int k = 1; k <= 50; ++k) {
        s.solve(frameOf(sitPose(30 + 60.0 * k / 50)), 0.01);
    }
    EXPECT_NEAR(lowestFootPoint(s), 0, 1e-9);
    bool released = false;
    for (int k = 1; k <= 50; ++k) {
        const double u = k / 50.0;
        Pose p;
        for (S t : {S::LThigh, S::RThigh}) {
            p.qLocal[idx(t)] = Quatd(Eigen::AngleAxisd((-90 + 30 * u) * kDeg, Vec3d::UnitX()));
        }
        for (S c : {S::LCalf, S::RCalf}) {
            p.qLocal[idx(c)] = Quatd(Eigen::AngleAxisd((90 + 30 * u) * kDeg, Vec3d::UnitX()));
        }
        for (S f : {S::LHindfoot, S::RHindfoot}) {
            p.qLocal[idx(f)] = Quatd(Eigen::AngleAxisd(-60 * u * kDeg, Vec3d::UnitX()));
        }
        s.solve(frameOf(p), 0.01);
        released = released || s.rootTracker().phase() != ContactPhase::Seated;
        if (released) {
            EXPECT_NE(s.rootTracker().phase(), ContactPhase::Seated) << "frame " << k;
            EXPECT_NEAR(lowestFootPoint(s), 0, 1e-9) << "frame " << k;
        }
    }
    EXPECT_TRUE(released);
}

TEST(RootTracker, AFootPlantedOnATreadCarriesTheBodyWhileTheOtherSwingsUp) {
    // A stair: the left foot on a tread (the left leg bent 35 deg at the hip, 70 at the knee:
    // its sole about 0.16 m above the right one's), the right foot on the floor carrying the
    // body. The trailing right foot then swings up (its knee bending to 90 deg in 0.2 s), while
    // the feet's sensors say the left one stands still and the right one moves at 1.2 m/s: the
    // left foot takes the body on a level of its own, at its height when it came to rest, and
    // the root no longer follows the lifting right foot down. Neither foot's sensor is still
    // for the 0.1 s a foot at rest needs (a loaded foot on a real stair hardly ever is).
    const Dimensions d = dims();
    auto stair = [](double rightKneeDeg) {
        Pose p;
        p.qLocal[idx(S::LThigh)] = Quatd(Eigen::AngleAxisd(-35 * kDeg, Vec3d::UnitX()));
        p.qLocal[idx(S::LCalf)] = Quatd(Eigen::AngleAxisd(70 * kDeg, Vec3d::UnitX()));
        p.qLocal[idx(S::LHindfoot)] = Quatd(Eigen::AngleAxisd(-35 * kDeg, Vec3d::UnitX()));
        p.qLocal[idx(S::RCalf)] = Quatd(Eigen::AngleAxisd(rightKneeDeg * kDeg, Vec3d::UnitX()));
        return p;
    };
    for (const bool sensed : {true, false}) {
        BodySolverOptions o;
        if (!sensed) {
            o.contact.plantedMps = 0;  // as before: no foot is ever taken for standing still
        }
        BodySolver s(Skeleton(d), testing::kFullSuit, o);
        BodyCalibration cal;
        cal.mask = testing::kFullSuit;
        s.setCalibration(cal);
        FootSensorMotion feet;
        feet.valid = {true, true};
        feet.known = feet.valid;
        for (int k = 0; k < 20; ++k) {
            s.solve(frameOf(stair(0)), 0.01, Vec3d(0, 9.81, 0), &feet);
        }
        ASSERT_EQ(s.rootTracker().phase(), ContactPhase::RightStance);
        const double rootY = s.pose().positionM[0].y();
        const double tread = pointOnSegment(s.pose(), idx(S::LHindfoot), d.leftFootPointM[0]).y();
        ASSERT_GT(tread, 0.14);
        feet.velocityMps[1] = Vec3d(0, 1.0, 0.6);  // the right foot lifts off
        for (int k = 1; k <= 20; ++k) {
            s.solve(frameOf(stair(90.0 * k / 20)), 0.01, Vec3d(0, 9.81, 0), &feet);
        }
        const double sunk = rootY - s.pose().positionM[0].y();
        if (sensed) {
            EXPECT_EQ(s.rootTracker().phase(), ContactPhase::LeftStance);
            EXPECT_LT(std::abs(sunk), 0.005);
            EXPECT_NEAR(pointOnSegment(s.pose(), idx(S::LHindfoot), d.leftFootPointM[0]).y(), tread,
                        0.005);
        } else {
            EXPECT_GT(sunk, 0.05);  // held on the lifting right foot
        }
    }
}

TEST(RootTracker, ABounceOnTheSeatIsNotAFlight) {
    // Seated with the feet off the floor (on a stool's rung), the pelvis accelerometer reads
    // free fall for a few frames: the body shifting on the seat. The seat still carries it:
    // no flight (which would land the body, feet first, on the level of the seat).
    const Dimensions d = dims();
    BodySolver s = makeSolver(d);
    for (int k = 0; k < 20; ++k) {
        s.solve(frameOf(sitPose(90)), 0.01, Vec3d(0, 9.81, 0));
    }
    for (int k = 1; k <= 30; ++k) {
        s.solve(frameOf(sitPose(90 - 60.0 * k / 30)), 0.01, Vec3d(0, 9.81, 0));
    }
    ASSERT_EQ(s.rootTracker().phase(), ContactPhase::Seated);
    const Vec3d seated = s.pose().positionM[0];
    for (int k = 0; k < 5; ++k) {
        s.solve(frameOf(sitPose(30)), 0.01, Vec3d(0, 0.5, 0));
        EXPECT_EQ(s.rootTracker().phase(), ContactPhase::Seated) << "frame " << k;
    }
    for (int k = 0; k < 20; ++k) {
        s.solve(frameOf(sitPose(30)), 0.01, Vec3d(0, 9.81, 0));
    }
    EXPECT_EQ(s.rootTracker().phase(), ContactPhase::Seated);
    EXPECT_LT((s.pose().positionM[0] - seated).norm(), 1e-9);
}

// Both legs turned sideways at the hips by a (rad), the feet turned back level.
Pose legsTurnedSideways(double a) {
    Pose p;
    for (S t : {S::LThigh, S::RThigh}) {
        p.qLocal[idx(t)] = Quatd(Eigen::AngleAxisd(a, Vec3d::UnitZ()));
    }
    for (S f : {S::LHindfoot, S::RHindfoot}) {
        p.qLocal[idx(f)] = Quatd(Eigen::AngleAxisd(-a, Vec3d::UnitZ()));
    }
    return p;
}

TEST(RootTracker, LegsThatJumpInOneFrameDoNotThrowTheRootWhenThePelvisFeltNothing) {
    // Standing; for one frame both legs turn 5 deg sideways at the hips (as a gyroscope that
    // clipped, or a capture that flips a leg, makes them), then back. Held on a foot point the
    // root would move 7.5 cm across and back in 10 ms; the pelvis accelerometer reads 1 g and
    // nothing else, so the root moves by no more than contactStepMps allows in a frame, and
    // stays near where it stood. Without the accelerometer it follows the contacts as before.
    const Dimensions d = dims();
    const Vec3d oneG(0, 9.81, 0);
    for (const bool felt : {true, false}) {
        BodySolver s = makeSolver(d);
        const std::optional<Vec3d> force = felt ? std::optional<Vec3d>(oneG) : std::nullopt;
        for (int k = 0; k < 30; ++k) {
            s.solve(frameOf(legsTurnedSideways(0)), 0.01, force);
        }
        const Vec3d start = s.pose().positionM[0];
        s.solve(frameOf(legsTurnedSideways(5 * kDeg)), 0.01, force);
        const double jumpM = std::hypot(s.pose().positionM[0].x() - start.x(),
                                        s.pose().positionM[0].z() - start.z());
        for (int k = 0; k < 30; ++k) {
            s.solve(frameOf(legsTurnedSideways(0)), 0.01, force);
        }
        const double afterM = std::hypot(s.pose().positionM[0].x() - start.x(),
                                         s.pose().positionM[0].z() - start.z());
        if (felt) {
            EXPECT_LE(jumpM, ContactOptions{}.contactStepMps * 0.01 + 1e-9);
            EXPECT_LT(afterM, 0.015);
        } else {
            EXPECT_GT(jumpM, 0.07);
            EXPECT_LT(afterM, 1e-9);
        }
    }
}

TEST(RootTracker, WhileThePelvisReadsFreeFallTheFeetDoNotMoveTheRootAcross) {
    // Standing, then for one frame both legs turn 2 deg sideways at the hips (the feet sliding
    // apart as they leave the floor at the end of a push-off) while the pelvis reads free fall:
    // the feet carry nothing, so the root keeps the velocity the accelerometer predicts (here
    // none) whatever foot point is held. Read at 1 g the same frame moves it by what
    // contactStepMps lets through.
    const Dimensions d = dims();
    for (const double upMps2 : {1.0, 9.81}) {
        BodySolver s = makeSolver(d);
        for (int k = 0; k < 30; ++k) {
            s.solve(frameOf(legsTurnedSideways(0)), 0.01, Vec3d(0, 9.81, 0));
        }
        const Vec3d start = s.pose().positionM[0];
        s.solve(frameOf(legsTurnedSideways(2 * kDeg)), 0.01, Vec3d(0, upMps2, 0));
        EXPECT_NE(s.rootTracker().phase(), ContactPhase::Flight);  // one frame: not yet a flight
        const double acrossM = std::hypot(s.pose().positionM[0].x() - start.x(),
                                          s.pose().positionM[0].z() - start.z());
        if (upMps2 < ContactOptions{}.freeFallMps2) {
            EXPECT_LT(acrossM, 1e-9);
        } else {
            EXPECT_GT(acrossM, 0.5 * ContactOptions{}.contactStepMps * 0.01);
            EXPECT_LE(acrossM, ContactOptions{}.contactStepMps * 0.01 + 1e-9);
        }
    }
}

TEST(RootTracker, ACrouchOverTheFeetIsNotASeat) {
    // Both thighs as far from the vertical as sitting, but the centre of mass over the feet: a
    // squat is carried by the feet, whose lowest point stays on the floor all the way down and
    // up again.
    const Dimensions d = dims();
    BodySolver s = makeSolver(d);
    for (int k = 0; k <= 100; ++k) {
        const double a = 75 * std::sin(std::numbers::pi * k / 100);
        s.solve(frameOf(crouchPose(a * kDeg, 0)), 0.01);
        EXPECT_NE(s.rootTracker().phase(), ContactPhase::Seated) << "frame " << k;
        EXPECT_NEAR(lowestFootPoint(s), 0, 1e-9) << "frame " << k;
    }
}

// Kneeling upright on both knees: thighs vertical, the trunk leaning leanDeg at the lumbar
// joint, the knees bent kneeDeg (past 90: the lower legs rise behind), the feet at right angles
// to the lower legs.
Pose kneelPose(double kneeDeg, double leanDeg) {
    Pose p;
    p.qLocal[idx(S::L5)] = Quatd(Eigen::AngleAxisd(leanDeg * kDeg, Vec3d::UnitX()));
    for (S c : {S::LCalf, S::RCalf}) {
        p.qLocal[idx(c)] = Quatd(Eigen::AngleAxisd(kneeDeg * kDeg, Vec3d::UnitX()));
    }
    return p;
}

double kneeContactY(const BodySolver& s, S calf) {
    return pointOnSegment(s.pose(), idx(calf), ContactOptions{}.kneeFrontM).y();
}

TEST(RootTracker, KneelingWithTheFeetUpTheKneesCarryTheBody) {
    // On both knees with the lower legs raised behind (the knees bent 115-135 deg, the feet in
    // the air), the trunk leaning forward and back: the knees stay on the floor and the root
    // keeps its height over them. Held on the lowest foot point, as before the knees were
    // contacts, the root sank until a foot touched the floor: 5-21 cm too low.
    const Dimensions d = dims();
    BodySolver s = makeSolver(d);
    for (int k = 0; k < 20; ++k) {
        s.solve(frameOf(kneelPose(125, 0)), 0.01);
    }
    const int held = s.rootTracker().contactPoint();
    EXPECT_TRUE(held == 7 || held == 8) << held;
    const Vec3d start =
        pointOnSegment(s.pose(), idx(held == 7 ? S::LCalf : S::RCalf), ContactOptions{}.kneeFrontM);
    EXPECT_NEAR(start.y(), 0, 1e-9);
    double lowestFoot = 1e9;
    double highestFoot = -1e9;
    for (int k = 1; k <= 100; ++k) {
        const double u = std::sin(2 * std::numbers::pi * k / 100);
        s.solve(frameOf(kneelPose(125 + 10 * u, 25 * u)), 0.01);
        EXPECT_NEAR(kneeContactY(s, S::LCalf), 0, 1e-9) << "frame " << k;
        EXPECT_NEAR(kneeContactY(s, S::RCalf), 0, 1e-9) << "frame " << k;
        const Vec3d knee = pointOnSegment(s.pose(), idx(held == 7 ? S::LCalf : S::RCalf),
                                          ContactOptions{}.kneeFrontM);
        EXPECT_LT((knee - start).norm(), 1e-9) << "frame " << k;
        lowestFoot = std::min(lowestFoot, lowestFootPoint(s));
        highestFoot = std::max(highestFoot, lowestFootPoint(s));
    }
    // The feet in the air all along: never near enough the floor to carry the body.
    EXPECT_GT(lowestFoot, ContactOptions{}.heightM);
    std::printf("lowest foot point %.3f-%.3f m above the floor\n", lowestFoot, highestFoot);
}

TEST(RootTracker, OnOneKneeTheFlatFootCarriesTheBody) {
    // A half-kneel (cmu_131_01 goes down on its left knee): the right foot flat in front, the
    // left knee just above the floor behind. The knee is no lower than the foot's sole, so the
    // foot carries the body, as it did before the knees were contacts.
    const Dimensions d = dims();
    BodySolver s = makeSolver(d);
    Pose p;
    p.qLocal[idx(S::LCalf)] = Quatd(Eigen::AngleAxisd(90 * kDeg, Vec3d::UnitX()));
    p.qLocal[idx(S::LHindfoot)] = Quatd(Eigen::AngleAxisd(80 * kDeg, Vec3d::UnitX()));
    p.qLocal[idx(S::RThigh)] = Quatd(Eigen::AngleAxisd(-90 * kDeg, Vec3d::UnitX()));
    p.qLocal[idx(S::RCalf)] = Quatd(Eigen::AngleAxisd(90 * kDeg, Vec3d::UnitX()));
    for (int k = 0; k < 30; ++k) {
        s.solve(frameOf(p), 0.01);
        EXPECT_GE(s.rootTracker().contactPoint(), 3) << "frame " << k;
        EXPECT_LE(s.rootTracker().contactPoint(), 5) << "frame " << k;
    }
    EXPECT_NEAR(lowestFootPoint(s), 0, 1e-9);
    const double knee = kneeContactY(s, S::LCalf);
    EXPECT_GT(knee, 0.0);
    EXPECT_LT(knee, ContactOptions{}.heightM);
    std::printf("the knee %.4f m above the floor\n", knee);
}

TEST(RootTracker, AJumpFliesAndLandsOnTheFloor) {
    const Dimensions d = dims();
    BodySolver s = makeSolver(d);
    auto crouch = [](double a) { return crouchPose(a, 0); };
    // Push-off: from a 60 deg crouch to 20 deg in 0.2 s, feet on the floor (1 g). The hips rise
    // at 2 L sin(a) da/dt, about 1 m/s at the end.
    for (int k = 0; k <= 20; ++k) {
        s.solve(frameOf(crouch((60 - 40 * k / 20.0) * kDeg)), 0.01, Vec3d(0, 9.81, 0));
    }
    EXPECT_NE(s.rootTracker().phase(), ContactPhase::Flight);
    const double takeoffY = s.pose().positionM[0].y();
    EXPECT_GT(s.rootTracker().rootVelocityMps().y(), 0.5);
    // Free fall (the pelvis accelerometer reads ~0), the legs held.
    bool flew = false;
    double top = 0;
    for (int k = 0; k < 100; ++k) {
        s.solve(frameOf(crouch(20 * kDeg)), 0.01, Vec3d(0, 0.2, 0));
        flew = flew || s.rootTracker().phase() == ContactPhase::Flight;
        top = std::max(top, s.pose().positionM[0].y());
    }
    EXPECT_TRUE(flew);
    EXPECT_GT(top, takeoffY + 0.02);
    // Back on the floor in stance, the lowest foot point at y = 0 (rounding only).
    EXPECT_NE(s.rootTracker().phase(), ContactPhase::Flight);
    double lowest = 1e9;
    for (const Vec3d& p : s.feet().pointM) {
        lowest = std::min(lowest, p.y());
    }
    EXPECT_NEAR(lowest + s.pose().positionM[0].y(), 0, 1e-9);
}

// In the air the whole body's centre of mass flies: horizontally at a constant velocity, however
// the body bends; the root moves about it. The pelvis reads a sideways specific force in the air
// (it turns about the centre of mass), which must not keep the flight from being seen.
TEST(RootTracker, InFlightTheCentreOfMassKeepsItsVelocityAndTheRootMovesAboutIt) {
    const Dimensions d = dims();
    BodySolver s = makeSolver(d);
    const auto& crouch = crouchPose;
    for (int k = 0; k <= 20; ++k) {
        s.solve(frameOf(crouch((60 - 40 * k / 20.0) * kDeg, 0)), 0.01, Vec3d(0, 9.81, 0));
    }
    ASSERT_NE(s.rootTracker().phase(), ContactPhase::Flight);
    auto com = [&] {
        const Vec3d c = s.pose().positionM[0] + centreOfMassOffsetM(d, s.pose());
        return Vec3d(c.x(), 0, c.z());
    };
    // In the air the trunk leans 30 deg: the centre of mass moves within the body, so the root
    // must move the other way for it to keep its path.
    std::vector<Vec3d> comPath;
    std::vector<Vec3d> rootPath;
    std::vector<double> comHeight;
    for (int k = 1; k <= 15; ++k) {
        s.solve(frameOf(crouch(20 * kDeg, 2.0 * k * kDeg)), 0.01, Vec3d(3.0, 0.2, -2.0));
        if (s.rootTracker().phase() == ContactPhase::Flight) {
            comPath.push_back(com());
            comHeight.push_back(s.pose().positionM[0].y() + centreOfMassOffsetM(d, s.pose()).y());
            const Vec3d& r = s.pose().positionM[0];
            rootPath.emplace_back(r.x(), 0, r.z());
        }
    }
    ASSERT_GE(comPath.size(), 10U);
    // Up it falls freely: its height's second difference is -g dt^2 in every frame.
    for (std::size_t k = 2; k < comHeight.size(); ++k) {
        EXPECT_NEAR(comHeight[k] - 2 * comHeight[k - 1] + comHeight[k - 2], -9.81 * 0.01 * 0.01,
                    1e-9)
            << "frame " << k;
    }
    const Vec3d v = (comPath[1] - comPath[0]) / 0.01;
    for (std::size_t k = 2; k < comPath.size(); ++k) {
        const Vec3d expected = comPath[0] + v * (0.01 * static_cast<double>(k));
        EXPECT_NEAR((comPath[k] - expected).norm(), 0, 1e-9) << "frame " << k;
    }
    // The root did not keep a constant velocity: it moved against the trunk's lean.
    const Vec3d rootMoved = rootPath.back() - rootPath.front();
    const Vec3d comMoved = comPath.back() - comPath.front();
    EXPECT_GT((rootMoved - comMoved).norm(), 0.02);
}

// In the air the feet's own sensors, while their dead reckoning holds, carry the root across: each
// foot sensor moves in the world as it reports, whatever the body's shape does meanwhile (the legs
// swing forward, which moves the feet relative to the root). With no valid foot, the centre of
// mass flies as before.
TEST(RootTracker, InFlightTheFeetSensorsCarryTheRootAcross) {
    const Dimensions d = dims();
    const Vec3d onFoot(0.0, 0.03, 0.06);
    const Vec3d feetVelocity(0.4, -1.0, 0.3);  // world; the vertical is not used across
    auto flight = [&](bool valid) {
        BodySolver s = makeSolver(d);
        FootSensorMotion feet;
        feet.onFootM = {onFoot, onFoot};
        for (int k = 0; k <= 20; ++k) {
            s.solve(frameOf(crouchPose((60 - 40 * k / 20.0) * kDeg, 0)), 0.01, Vec3d(0, 9.81, 0),
                    &feet);
        }
        feet.valid = {valid, valid};
        feet.known = feet.valid;
        feet.velocityMps = {feetVelocity, feetVelocity};
        std::vector<Vec3d> sensorPath;  // the left foot's sensor in the world, across
        std::vector<Vec3d> rootPath;
        for (int k = 1; k <= 15; ++k) {
            Pose swing = crouchPose(20 * kDeg, 0);
            for (S t : {S::LThigh, S::RThigh}) {
                swing.qLocal[idx(t)] =
                    Quatd(Eigen::AngleAxisd(-(20 + 2.0 * k) * kDeg, Vec3d::UnitX()));
            }
            s.solve(frameOf(swing), 0.01, Vec3d(3.0, 0.2, -2.0), &feet);
            if (s.rootTracker().phase() == ContactPhase::Flight) {
                const Vec3d p = pointOnSegment(s.pose(), idx(S::LHindfoot), onFoot);
                sensorPath.emplace_back(p.x(), 0, p.z());
                const Vec3d& r = s.pose().positionM[0];
                rootPath.emplace_back(r.x(), 0, r.z());
            }
        }
        return std::pair{sensorPath, rootPath};
    };
    const auto [sensorPath, rootPath] = flight(true);
    ASSERT_GE(sensorPath.size(), 10U);
    const Vec3d across(feetVelocity.x(), 0, feetVelocity.z());
    for (std::size_t k = 1; k < sensorPath.size(); ++k) {
        EXPECT_NEAR((sensorPath[k] - sensorPath[k - 1] - across * 0.01).norm(), 0, 1e-9)
            << "frame " << k;
    }
    // The root did not move at the feet's velocity: the swing moved the feet about it.
    const Vec3d rootMoved = rootPath.back() - rootPath.front();
    const Vec3d sensorMoved = sensorPath.back() - sensorPath.front();
    EXPECT_GT((rootMoved - sensorMoved).norm(), 0.01);
    // Not valid: the feet's report moves nothing, the centre of mass flies from the push-off
    // (straight up here).
    const auto [sensorPathNone, rootPathNone] = flight(false);
    ASSERT_GE(rootPathNone.size(), 10U);
    EXPECT_GT((sensorPathNone.back() - sensorPathNone.front() -
               across * (0.01 * static_cast<double>(sensorPathNone.size() - 1)))
                  .norm(),
              0.02);
}

}  // namespace
}  // namespace caphub::body
