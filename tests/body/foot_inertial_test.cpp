// A foot sensor's dead reckoning: still samples zero the velocity, motion integrates the world
// acceleration from the latest still instant, and the velocity is trusted only for a while.
#include "fusion/body/foot_inertial.h"

#include <cmath>
#include <numbers>
#include <vector>

#include <gtest/gtest.h>

namespace caphub::body {
namespace {

constexpr double kG = 9.81;
constexpr double kDt = 0.01;  // 100 Hz

// A sensor turned arbitrarily in ENU: the dead reckoning must not depend on how it sits.
const Quatd kTurned =
    Quatd(Eigen::AngleAxisd(0.7, Vec3d(0.3, -0.5, 0.8).normalized())).normalized();

// The specific force a sensor turned by q reads under the world acceleration a (ENU).
Vec3d forceFor(const Quatd& q, const Vec3d& a) {
    return q.conjugate() * (a + Vec3d(0, 0, kG));
}

void holdStill(FootInertial& f, int samples) {
    for (int k = 0; k < samples; ++k) {
        f.add(kTurned, forceFor(kTurned, Vec3d::Zero()), Vec3d(0.01, -0.02, 0.01), kDt);
    }
}

// Moving: a rate well above the still threshold and the world acceleration a.
void move(FootInertial& f, const Vec3d& a, int samples) {
    for (int k = 0; k < samples; ++k) {
        f.add(kTurned, forceFor(kTurned, a), Vec3d(2.0, 0.5, -1.0), kDt);
    }
}

TEST(FootInertial, IsNotValidBeforeTheFootWasFirstStill) {
    FootInertial f;
    move(f, Vec3d(1, 0, 0), 10);
    EXPECT_FALSE(f.valid());
    holdStill(f, 2);
    EXPECT_TRUE(f.still());
    EXPECT_TRUE(f.valid());
    EXPECT_EQ(f.velocityEnuMps(), Vec3d::Zero());
}

TEST(FootInertial, IntegratesTheWorldAccelerationFromTheLatestStillInstant) {
    FootInertial f;
    holdStill(f, 10);
    const Vec3d a(1.5, -0.8, 0.3);
    move(f, a, 30);
    EXPECT_FALSE(f.still());
    ASSERT_TRUE(f.valid());
    // Trapezoids: the first interval ramps from the still sample's zero to a.
    const Vec3d expected = a * (29.5 * kDt);
    EXPECT_LT((f.velocityEnuMps() - expected).norm(), 1e-9) << f.velocityEnuMps().transpose();
    // The rate comes out in ENU.
    EXPECT_LT((f.rateEnuRadS() - kTurned * Vec3d(2.0, 0.5, -1.0)).norm(), 1e-12);
    // Still again: a zero-velocity update.
    holdStill(f, 2);
    EXPECT_EQ(f.velocityEnuMps(), Vec3d::Zero());
}

// The sensor's heading turned mid-stride (a correction from its joints): the velocity integrated
// so far turns with it and the integration goes on in the new frame, from the same still
// instant.
TEST(FootInertial, ATurnCarriesTheVelocityIntoTheTurnedFrame) {
    FootInertial f;
    holdStill(f, 10);
    const Vec3d a(1.5, -0.8, 0.3);
    move(f, a, 20);
    const Vec3d before = f.velocityEnuMps();
    const Quatd turn(Eigen::AngleAxisd(0.2, Vec3d::UnitZ()));
    f.turn(turn);
    EXPECT_TRUE(f.valid()) << "not restarted";
    EXPECT_LT((f.velocityEnuMps() - turn * before).norm(), 1e-12);
    // The sensor's orientations come turned from now on: so does the acceleration they give.
    const Quatd q = turn * kTurned;
    for (int k = 0; k < 10; ++k) {
        f.add(q, q.conjugate() * (turn * a + Vec3d(0, 0, kG)), Vec3d(2.0, 0.5, -1.0), kDt);
    }
    EXPECT_LT((f.velocityEnuMps() - turn * (a * (29.5 * kDt))).norm(), 1e-9);
    FootStateHistory history;
    history.push({Timestamp{}, true, true, false, before, Vec3d(0, 0, 1)});
    history.turn(turn);
    ASSERT_TRUE(history.at(Timestamp{}).has_value());
    EXPECT_LT((history.at(Timestamp{})->velocityEnuMps - turn * before).norm(), 1e-12);
}

TEST(FootInertial, OneQuietSampleInMotionIsNotAStillInstant) {
    // A swinging foot passes through low rates and about 1 g at its turning points; a single
    // such sample (10 ms at 100 Hz) must not zero the velocity.
    FootInertial f;
    holdStill(f, 5);
    move(f, Vec3d(1, 0, 0), 20);
    const Vec3d before = f.velocityEnuMps();
    holdStill(f, 1);
    EXPECT_FALSE(f.still());
    EXPECT_GT(f.velocityEnuMps().x(), before.x());  // integrated on: the ramp down to zero
    holdStill(f, 1);
    EXPECT_TRUE(f.still());
}

TEST(FootInertial, AFootLongOffTheFloorIsNotTrusted) {
    FootInertialOptions o;
    FootInertial f(o);
    holdStill(f, 5);
    const int within = static_cast<int>(o.maxSpanS / kDt) - 1;
    move(f, Vec3d(0, 1, 0), within);
    EXPECT_TRUE(f.valid());
    move(f, Vec3d(0, 1, 0), 3);
    EXPECT_FALSE(f.valid());
    holdStill(f, 2);
    EXPECT_TRUE(f.valid());
}

TEST(FootInertial, ASwingIsToldForLongerThanASlipIsMeasured) {
    // A swing down a stair outlasts the span a slip is integrated over; whether the foot swings
    // or stands is still told from its velocity, for maxKnownSpanS.
    FootInertialOptions o;
    ASSERT_GT(o.maxKnownSpanS, o.maxSpanS);
    FootInertial f(o);
    holdStill(f, 5);
    move(f, Vec3d(0, 1, 0), static_cast<int>(o.maxSpanS / kDt) + 3);
    EXPECT_FALSE(f.valid());
    EXPECT_TRUE(f.known());
    move(f, Vec3d(0, 1, 0), static_cast<int>((o.maxKnownSpanS - o.maxSpanS) / kDt));
    EXPECT_FALSE(f.known());
    holdStill(f, 2);
    EXPECT_TRUE(f.known());
    EXPECT_TRUE(f.valid());
}

TEST(FootInertial, AResetForgetsTheMotion) {
    FootInertial f;
    holdStill(f, 5);
    move(f, Vec3d(1, 0, 0), 5);
    f.reset();
    EXPECT_FALSE(f.valid());
    EXPECT_FALSE(f.known());
    EXPECT_EQ(f.velocityEnuMps(), Vec3d::Zero());
}

// A stride's dead reckoning: still, then a swing whose true velocity rises and falls back to
// zero, read with an accelerometer error `bias` (world frame), then still again.
void stride(FootInertial& f, const Vec3d& bias, std::vector<Vec3d>* velocities = nullptr) {
    holdStill(f, 3);
    for (int k = 0; k < 80; ++k) {
        const double s = std::sin(2 * std::numbers::pi * k / 80.0);
        move(f, Vec3d(3 * s, 0, 1.5 * s) + bias, 1);
        if (velocities != nullptr) {
            velocities->push_back(f.velocityEnuMps());
        }
    }
    holdStill(f, 3);
}

// Offline: a pass records what each stretch ended with, the next takes it off along the
// stretch. With a constant accelerometer error the corrected velocity is the error-free one.
TEST(FootInertial, AStretchsRecordedErrorIsTakenOffAlongItInTheNextPass) {
    const Vec3d bias(0.3, -0.2, 0.1);
    std::vector<Vec3d> truth;
    {
        FootInertial clean;
        stride(clean, Vec3d::Zero(), &truth);
        stride(clean, Vec3d::Zero());
    }
    FootStretchLog log;
    FootInertial record;
    record.useStretchLog(&log, FootStretchUse::Record);
    std::vector<Vec3d> raw;
    stride(record, bias, &raw);
    stride(record, bias);
    ASSERT_EQ(log.stretches.size(), 2u);
    // 80 samples in motion: the error of 80 intervals (half of one at each end, where the
    // acceleration ramps from and to a still sample's), over 82 (the two quiet samples that make
    // the still instant).
    EXPECT_LT((log.stretches[0].endVelocityMps - bias * (80 * kDt)).norm(), 1e-9)
        << log.stretches[0].endVelocityMps.transpose();
    EXPECT_NEAR(log.stretches[0].durationS, 82 * kDt, 1e-12);
    EXPECT_GT((raw[60] - truth[60]).norm(), 0.15);  // what is to be corrected

    FootInertial corrected;
    corrected.useStretchLog(&log, FootStretchUse::Correct);
    std::vector<Vec3d> fixed;
    stride(corrected, bias, &fixed);
    ASSERT_EQ(fixed.size(), truth.size());
    for (std::size_t k = 0; k < fixed.size(); ++k) {
        // The error taken off grows evenly over the 82 intervals, the error itself over 80: off
        // by at most two intervals' worth (the raw velocity is off by up to 80).
        EXPECT_LT((fixed[k] - truth[k]).norm(), 2 * bias.norm() * kDt) << k;
    }
    EXPECT_TRUE(corrected.stretchLogMatched());
    EXPECT_EQ(corrected.velocityEnuMps(), Vec3d::Zero());  // still
}

// Samples that are not the recorded ones (another stride length) stop the corrections instead
// of taking a stranger's error off.
TEST(FootInertial, AStretchLogOfOtherSamplesIsNotApplied) {
    FootStretchLog log;
    FootInertial record;
    record.useStretchLog(&log, FootStretchUse::Record);
    holdStill(record, 3);
    move(record, Vec3d(1, 0, 0), 50);
    holdStill(record, 3);
    move(record, Vec3d(1, 0, 0), 50);
    holdStill(record, 3);
    ASSERT_EQ(log.stretches.size(), 2u);

    FootInertial other;
    other.useStretchLog(&log, FootStretchUse::Correct);
    holdStill(other, 3);
    move(other, Vec3d(1, 0, 0), 30);  // shorter than the first recorded stretch
    holdStill(other, 3);
    EXPECT_FALSE(other.stretchLogMatched());
    move(other, Vec3d(1, 0, 0), 50);
    // Uncorrected: the plain integration (49.5 intervals of 1 m/s^2).
    EXPECT_NEAR(other.velocityEnuMps().x(), 49.5 * kDt, 1e-9);
}

// A short stretch ending faster than the dead reckoning could err (the foot still turning on its
// sole at the instant called still) is real motion: not taken off.
TEST(FootInertial, AnEndVelocityNoErrorCouldMakeIsNotTakenOff) {
    FootInertialOptions o;
    FootStretchLog log;
    FootInertial record(o);
    record.useStretchLog(&log, FootStretchUse::Record);
    holdStill(record, 3);
    move(record, Vec3d(4, 0, 0), 5);  // 0.07 s ending at about 0.2 m/s
    holdStill(record, 3);
    ASSERT_EQ(log.stretches.size(), 1u);
    const FootStretchLog::Stretch& st = log.stretches[0];
    ASSERT_GT(st.endVelocityMps.norm(), o.maxErrorAccelerationMps2 * st.durationS);

    FootInertial replayed(o);
    replayed.useStretchLog(&log, FootStretchUse::Correct);
    holdStill(replayed, 3);
    move(replayed, Vec3d(4, 0, 0), 4);
    EXPECT_NEAR(replayed.velocityEnuMps().x(), 4 * 3.5 * kDt, 1e-9);  // as integrated
    EXPECT_TRUE(replayed.stretchLogMatched());
}

FootSample stateAt(int ms, double vx, bool still = false) {
    FootSample s;
    s.t = Timestamp{std::chrono::milliseconds(ms)};
    s.valid = true;
    s.known = true;
    s.still = still;
    s.velocityEnuMps = Vec3d(vx, 0, 0);
    s.rateEnuRadS = Vec3d(0, 0, 2 * vx);
    return s;
}

TEST(FootStateHistory, TakesTheFootAtATimeBetweenItsSamples) {
    // A pose at the watermark is solved up to a sample interval after its grid time: the foot
    // must be taken at the grid time, not as its newest sample left it.
    FootStateHistory h;
    EXPECT_FALSE(h.at(Timestamp{}).has_value());
    h.push(stateAt(0, 0.0));
    h.push(stateAt(10, 1.0));
    h.push(stateAt(20, 3.0));
    const auto mid = h.at(Timestamp{std::chrono::milliseconds(15)});
    ASSERT_TRUE(mid.has_value());
    EXPECT_NEAR(mid->velocityEnuMps.x(), 2.0, 1e-12);
    EXPECT_NEAR(mid->rateEnuRadS.z(), 4.0, 1e-12);
    EXPECT_EQ(mid->t, Timestamp{std::chrono::milliseconds(15)});
    EXPECT_NEAR(h.at(Timestamp{std::chrono::milliseconds(10)})->velocityEnuMps.x(), 1.0, 1e-12);
    // After the newest: the newest; before the oldest held: the oldest.
    EXPECT_NEAR(h.at(Timestamp{std::chrono::milliseconds(40)})->velocityEnuMps.x(), 3.0, 1e-12);
    EXPECT_NEAR(h.at(Timestamp{std::chrono::milliseconds(-5)})->velocityEnuMps.x(), 0.0, 1e-12);
}

TEST(FootStateHistory, AStillSampleIsAStepNotARamp) {
    FootStateHistory h;
    h.push(stateAt(0, 2.0));
    h.push(stateAt(10, 0.0, true));  // a zero-velocity update
    const auto s = h.at(Timestamp{std::chrono::milliseconds(5)});
    ASSERT_TRUE(s.has_value());
    EXPECT_FALSE(s->still);
    EXPECT_NEAR(s->velocityEnuMps.x(), 2.0, 1e-12);
    EXPECT_TRUE(h.at(Timestamp{std::chrono::milliseconds(10)})->still);
}

TEST(FootStateHistory, KeepsTheLatestEightAndForgetsOnClear) {
    FootStateHistory h;
    for (int k = 0; k < 12; ++k) {
        h.push(stateAt(10 * k, k));
    }
    // Samples 4..11 are held: before 40 ms the oldest held (4) answers.
    EXPECT_NEAR(h.at(Timestamp{std::chrono::milliseconds(0)})->velocityEnuMps.x(), 4.0, 1e-12);
    EXPECT_NEAR(h.at(Timestamp{std::chrono::milliseconds(55)})->velocityEnuMps.x(), 5.5, 1e-12);
    h.clear();
    EXPECT_FALSE(h.at(Timestamp{std::chrono::milliseconds(55)}).has_value());
}

}  // namespace
}  // namespace caphub::body
