// Sensor calibration algorithms: gyroscope bias at rest, six-position accelerometer, the
// accelerometer and gyroscope axes from held positions and turns, magnetometer ellipsoid fit
// with its coverage check and quality figure.
#include <random>

#include <gtest/gtest.h>

#include "fusion/calibration/accel_six_position.h"
#include "fusion/calibration/ellipsoid_fit.h"
#include "fusion/calibration/gyro_bias.h"
#include "fusion/calibration/imu_axes.h"
#include "fusion/calibration/sensor_calibration.h"

namespace caphub::fusion {
namespace {

constexpr double kDeg = 0.017453292519943295;

std::vector<Vec3d> noisy(const Vec3d& mean, double sigma, int n, unsigned seed) {
    std::mt19937 rng(seed);
    std::normal_distribution<double> d(0.0, sigma);
    std::vector<Vec3d> out;
    for (int i = 0; i < n; ++i) {
        out.push_back(mean + Vec3d(d(rng), d(rng), d(rng)));
    }
    return out;
}

TEST(GyroBiasCalibration, IsTheMeanRateAtRest) {
    const Vec3d bias = Vec3d(0.7, -0.2, 1.5) * kDeg;
    const auto s = noisy(bias, 0.1 * kDeg, 2000, 3);
    auto r = estimateGyroBias(s);
    ASSERT_TRUE(r) << r.error().message;
    // Standard error of the mean: 0.1 deg/s / sqrt(2000) = 0.0022 deg/s; 0.01 is 4.5 sigma.
    EXPECT_LT((r->biasRadS - bias).cwiseAbs().maxCoeff() / kDeg, 0.01);
    EXPECT_NEAR(r->stdRadS.x() / kDeg, 0.1, 0.01);
}

TEST(GyroBiasCalibration, RefusesARecordingWithMotion) {
    auto s = noisy(Vec3d::Zero(), 0.05 * kDeg, 1000, 4);
    for (int i = 300; i < 400; ++i) {
        s[i].z() += 30.0 * kDeg;  // someone turned the sensor
    }
    auto r = estimateGyroBias(s);
    ASSERT_FALSE(r);
    EXPECT_NE(r.error().message.find("moved"), std::string::npos) << r.error().message;
}

TEST(AccelSixPosition, RecoversOffsetAndScalePerAxis) {
    const Vec3d offset(0.12, -0.08, 0.2);
    const Vec3d scale(1.01, 0.985, 1.02);
    std::array<Vec3d, 6> pos;
    const std::array<Vec3d, 6> dirs = {Vec3d::UnitZ(),  -Vec3d::UnitX(), Vec3d::UnitY(),
                                       -Vec3d::UnitZ(), Vec3d::UnitX(),  -Vec3d::UnitY()};
    for (int i = 0; i < 6; ++i) {
        pos[i] = (dirs[i] * 9.81).cwiseProduct(scale) + offset;
    }
    auto r = calibrateAccelSixPosition(pos);
    ASSERT_TRUE(r) << r.error().message;
    EXPECT_LT((r->offsetMps2 - offset).cwiseAbs().maxCoeff(), 1e-12);  // exact data, exact fit
    EXPECT_LT((r->scale - scale).cwiseAbs().maxCoeff(), 1e-12);
    EXPECT_LT(r->residualMps2, 1e-9);
}

TEST(AccelSixPosition, RefusesAnAxisThatPointsUpTwice) {
    std::array<Vec3d, 6> pos = {Vec3d(0, 0, 9.8),  Vec3d(0, 0, -9.8), Vec3d(9.8, 0, 0),
                                Vec3d(-9.8, 0, 0), Vec3d(0, 9.8, 0),  Vec3d(0.3, 0, 9.8)};
    auto r = calibrateAccelSixPosition(pos);
    ASSERT_FALSE(r);
    EXPECT_NE(r.error().message.find("+z up"), std::string::npos) << r.error().message;
}

// Field samples over the whole sphere of orientations, distorted by soft and hard iron.
std::vector<Vec3d> distortedSphere(const Eigen::Matrix3d& soft, const Vec3d& hard, double normUt,
                                   double noiseUt, int n, bool halfOnly) {
    std::mt19937 rng(7);
    std::normal_distribution<double> d(0.0, 1.0);
    std::vector<Vec3d> out;
    while (static_cast<int>(out.size()) < n) {
        Vec3d u(d(rng), d(rng), d(rng));
        u.normalize();
        if (halfOnly && u.z() < 0.3) {
            continue;
        }
        out.push_back(soft * (u * normUt) + hard + Vec3d(d(rng), d(rng), d(rng)) * noiseUt);
    }
    return out;
}

TEST(EllipsoidFit, RecoversSimulatedHardAndSoftIronWithin2Percent) {
    Eigen::Matrix3d soft;  // symmetric, stretches up to 20 % and couples axes
    soft << 1.15, 0.08, -0.05, 0.08, 0.9, 0.04, -0.05, 0.04, 1.05;
    const Vec3d hard(25.0, -12.0, 40.0);
    const double norm = 49.0;
    const auto m = distortedSphere(soft, hard, norm, 0.3, 2000, false);
    EllipsoidFitParams p;
    p.fieldNormUt = norm;
    auto r = fitEllipsoid(m, p);
    ASSERT_TRUE(r) << r.error().message;
    // The correction must undo the distortion: softIron * soft = I. 2 % of each (unit) entry.
    const Eigen::Matrix3d undo = r->softIron * soft;
    EXPECT_LT((undo - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff(), 0.02) << undo;
    EXPECT_LT((r->hardIronUt - hard).norm() / hard.norm(), 0.02) << r->hardIronUt.transpose();
    // Noise 0.3 uT on 49 uT is 0.6 %: the quality figure reports about that.
    EXPECT_LT(r->qualityPct, 1.0);
    EXPECT_GT(r->coverage, 0.99);
}

TEST(EllipsoidFit, RefusesSamplesThatCoverOnlyPartOfTheSphere) {
    const auto m =
        distortedSphere(Eigen::Matrix3d::Identity(), Vec3d(5, 5, 5), 49.0, 0.3, 500, true);
    auto r = fitEllipsoid(m);
    ASSERT_FALSE(r);
    EXPECT_NE(r.error().message.find("cover"), std::string::npos) << r.error().message;
}

TEST(EllipsoidFit, CoverageCountsTheDirectionsVisited) {
    const std::vector<Vec3d> six = {Vec3d::UnitX(),  -Vec3d::UnitX(), Vec3d::UnitY(),
                                    -Vec3d::UnitY(), Vec3d::UnitZ(),  -Vec3d::UnitZ()};
    EXPECT_DOUBLE_EQ(directionCoverage(six), 6.0 / 26.0);
}

TEST(SensorCalibration, AppliesEachPartToItsSensorOnly) {
    SensorCalibration c;
    c.hasGyro = true;
    c.gyroBiasRadS = Vec3d(0.01, 0.0, 0.0);
    c.hasMag = true;
    c.magHardIronUt = Vec3d(1, 2, 3);
    c.magSoftIron = Eigen::Vector3d(2, 2, 2).asDiagonal();
    ImuSample raw;
    raw.gyrRadS = Vec3d(0.01, 0.5, 0.0);
    raw.accMps2 = Vec3d(0, 0, 9.8);
    raw.magUt = Vec3d(2, 2, 2);
    const ImuSample s = c.apply(raw);
    EXPECT_EQ(s.gyrRadS, Vec3d(0.0, 0.5, 0.0));
    EXPECT_EQ(s.accMps2, raw.accMps2);  // no accelerometer calibration: unchanged
    EXPECT_EQ(s.magUt, Vec3d(2, 0, -2));
}

// A stream of the six positions in a shuffled order, each held `holdS` at 100 Hz, with turning
// (a rate of 60 deg/s, gravity swinging) between them.
struct SixPositionStream {
    std::vector<Vec3d> acc;
    std::vector<Vec3d> gyr;
};

SixPositionStream sixPositionStream(double holdS, const Vec3d& offset, const Vec3d& scale) {
    const Vec3d up[6] = {Vec3d::UnitY(),  -Vec3d::UnitZ(), Vec3d::UnitX(),
                         -Vec3d::UnitY(), Vec3d::UnitZ(),  -Vec3d::UnitX()};
    SixPositionStream s;
    std::mt19937 rng(11);
    std::normal_distribution<double> noise(0.0, 0.02);
    for (int k = 0; k < 6; ++k) {
        for (int i = 0; i < static_cast<int>(holdS * 100); ++i) {
            const Vec3d g = 9.81 * up[k];
            s.acc.push_back(g.cwiseProduct(scale) + offset + Vec3d(noise(rng), noise(rng), 0));
            s.gyr.push_back(Vec3d(noise(rng), noise(rng), noise(rng)) * 0.01);
        }
        for (int i = 0; i < 100; ++i) {  // one second of turning
            const double a = i * 0.0628;
            s.acc.push_back(9.81 * Vec3d(std::sin(a), std::cos(a), 0.3) + offset);
            s.gyr.push_back(Vec3d(0, 0, 60 * kDeg));
        }
    }
    return s;
}

TEST(AccelSixPositions, AreFoundInAStreamAndCalibrate) {
    const Vec3d offset(0.3, -0.2, 0.5);
    const Vec3d scale(1.01, 0.99, 1.005);
    const auto s = sixPositionStream(3.0, offset, scale);
    auto means = findSixPositions(s.acc, s.gyr, 100.0);
    ASSERT_TRUE(means) << means.error().message;
    auto r = calibrateAccelSixPosition(*means);
    ASSERT_TRUE(r) << r.error().message;
    // Means of >= 250 samples of 0.02 m/s^2 noise: standard error 0.0013 m/s^2; 0.01 is 7 sigma.
    EXPECT_LT((r->offsetMps2 - offset).cwiseAbs().maxCoeff(), 0.01);
    EXPECT_LT((r->scale - scale).cwiseAbs().maxCoeff(), 0.001);
}

TEST(AccelSixPositions, TooShortAHoldNamesTheMissingPosition) {
    auto s = sixPositionStream(3.0, Vec3d::Zero(), Vec3d::Ones());
    // The -x position (the last hold) cut to half a second.
    const std::size_t lastHold = 5 * 400;
    s.acc.erase(s.acc.begin() + lastHold + 50, s.acc.begin() + lastHold + 300);
    s.gyr.erase(s.gyr.begin() + lastHold + 50, s.gyr.begin() + lastHold + 300);
    auto means = findSixPositions(s.acc, s.gyr, 100.0);
    ASSERT_FALSE(means);
    EXPECT_NE(means.error().message.find("-x up"), std::string::npos) << means.error().message;
    EXPECT_EQ(means.error().message.find("+x up"), std::string::npos) << means.error().message;
}

// The fourteen directions of a cube's faces and corners, faces and corners alternating.
std::vector<Vec3d> facesAndCorners() {
    const int up[14][3] = {{0, 0, 1},   {1, 1, 1},  {1, 0, 0},   {1, -1, -1}, {0, 0, -1},
                           {-1, 1, -1}, {0, 1, 0},  {-1, -1, 1}, {-1, 0, 0},  {1, 1, -1},
                           {0, -1, 0},  {1, -1, 1}, {-1, 1, 1},  {-1, -1, -1}};
    std::vector<Vec3d> out;
    for (const auto& u : up) {
        out.push_back(Vec3d(u[0], u[1], u[2]).normalized());
    }
    return out;
}

// A part's axes: scale errors on the diagonal, cross-axis terms off it (not symmetric).
Eigen::Matrix3d partAxes() {
    Eigen::Matrix3d m;
    m << 1.012, 0.018, -0.011, -0.006, 0.987, 0.021, 0.014, -0.019, 1.006;
    return m;
}

TEST(AccelAxes, HeldPositionsGiveTheOffsetAndUndoScaleAndCrossAxis) {
    const Vec3d offset(0.3, -0.45, 0.2);
    const Eigen::Matrix3d m = partAxes();
    std::vector<Vec3d> means;
    for (const Vec3d& u : facesAndCorners()) {
        means.push_back(m * (9.81 * u) + offset);
    }
    auto r = calibrateAccelAxes(means);
    ASSERT_TRUE(r) << r.error().message;
    EXPECT_LT((r->offsetMps2 - offset).norm(), 1e-9);  // exact data, exact fit
    // A M is a rotation: the non-symmetric part of M only turns the frame, which no gravity
    // reading can tell; the fit takes the symmetric one and leaves that rotation.
    const Eigen::Matrix3d p = r->matrix * m;
    EXPECT_LT((p.transpose() * p - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff(), 1e-9);
    EXPECT_LT((r->matrix - r->matrix.transpose()).cwiseAbs().maxCoeff(), 1e-12);
    EXPECT_LT(r->residualMps2, 1e-9);
}

TEST(AccelAxes, RefusesFewerThanNinePositions) {
    std::vector<Vec3d> means;
    for (const Vec3d& u : facesAndCorners()) {
        if (means.size() < 8) {
            means.push_back(9.81 * u);
        }
    }
    auto r = calibrateAccelAxes(means);
    ASSERT_FALSE(r);
    EXPECT_NE(r.error().message.find("8 held positions"), std::string::npos) << r.error().message;
}

// A session at 100 Hz: the fourteen positions, each held 2 s, with 1 s turns at a steady rate
// between them. The part reads gyr = G (omega) + bias and acc = f (ideal), with noise.
struct AxesSession {
    std::vector<Vec3d> acc;
    std::vector<Vec3d> gyr;
};

AxesSession axesSession(const Eigen::Matrix3d& gyroAxes, const Vec3d& bias) {
    constexpr double kRate = 100.0;
    std::mt19937 rng(21);
    std::normal_distribution<double> noise(0.0, 1.0);
    AxesSession s;
    const Vec3d up = Vec3d::UnitZ();  // world up
    const auto dirs = facesAndCorners();
    Quatd q = Quatd::FromTwoVectors(dirs[0], up);  // sensor -> world
    for (std::size_t k = 0; k < dirs.size(); ++k) {
        for (int i = 0; i < 200; ++i) {
            s.acc.push_back(9.81 * (q.conjugate() * up) +
                            0.01 * Vec3d(noise(rng), noise(rng), noise(rng)));
            s.gyr.push_back(bias + 0.001 * Vec3d(noise(rng), noise(rng), noise(rng)));
        }
        if (k + 1 == dirs.size()) {
            break;
        }
        const Quatd next = Quatd::FromTwoVectors(dirs[k + 1], up);
        const Eigen::AngleAxisd turn(q.conjugate() * next);  // body frame
        const Vec3d omega = turn.axis() * turn.angle();      // rad/s over one second
        for (int i = 0; i < static_cast<int>(kRate); ++i) {
            q = q * Quatd(Eigen::AngleAxisd(turn.angle() / kRate, turn.axis()));
            s.acc.push_back(9.81 * (q.conjugate() * up));
            s.gyr.push_back(gyroAxes * omega + bias);
        }
        q = next;
    }
    return s;
}

TEST(GyroAxes, TurnsBetweenHeldPositionsUndoScaleAndCrossAxis) {
    const Eigen::Matrix3d g = partAxes();
    const Vec3d bias = Vec3d(0.5, -1.2, 2.0) * kDeg;
    const AxesSession s = axesSession(g, bias);
    auto held = findHeldPositions(s.acc, s.gyr, 100.0);
    ASSERT_TRUE(held) << held.error().message;
    ASSERT_EQ(held->size(), 14u);
    std::vector<Vec3d> means;
    for (const auto& h : *held) {
        means.push_back(h.meanAccMps2);
    }
    auto acc = calibrateAccelAxes(means);
    ASSERT_TRUE(acc) << acc.error().message;
    auto r = calibrateGyroAxes(s.gyr, 100.0, *held, *acc);
    ASSERT_TRUE(r) << r.error().message;
    EXPECT_EQ(r->turns, 13);
    // The mean of 14 x 100 held samples of 1 mrad/s (0.057 deg/s) noise: 0.0015 deg/s per axis.
    EXPECT_LT((r->biasRadS - bias).norm() / kDeg, 0.01);
    // Each turn is 45-180 deg; a 2 % axis error misses it by about a degree, and the fit by the
    // noise of the held positions' directions (0.01 m/s^2 over 100 samples: 0.006 deg each)
    // and of the bias (0.003 deg over a 1 s turn): about 0.01 deg.
    EXPECT_GT(r->uncalibratedDeg, 0.5);
    EXPECT_LT(r->residualDeg, 0.03);
    EXPECT_LT((r->matrix * g - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff(), 2e-4)
        << r->matrix * g;
}

TEST(GyroAxes, RefusesASessionWithTooFewTurns) {
    const AxesSession s = axesSession(Eigen::Matrix3d::Identity(), Vec3d::Zero());
    auto held = findHeldPositions(s.acc, s.gyr, 100.0);
    ASSERT_TRUE(held) << held.error().message;
    std::vector<Vec3d> means;
    for (const auto& h : *held) {
        means.push_back(h.meanAccMps2);
    }
    auto acc = calibrateAccelAxes(means);
    ASSERT_TRUE(acc) << acc.error().message;
    const std::vector<StillInterval> four(held->begin(), held->begin() + 4);
    auto r = calibrateGyroAxes(s.gyr, 100.0, four, *acc);
    ASSERT_FALSE(r);
    EXPECT_NE(r.error().message.find("3 turns"), std::string::npos) << r.error().message;
}

TEST(MagAlignment, FindsTheMagnetometersRotationAgainstTheAccelerometer) {
    // A sensor turned through random orientations in a field of 50 uT dipping 65 deg; its
    // magnetometer's axes are turned 2 deg off the accelerometer's about an oblique axis.
    constexpr double kDip = 65.0 * kDeg;
    const Vec3d fieldWorld = 50.0 * Vec3d(0.0, std::cos(kDip), -std::sin(kDip));  // ENU
    const Eigen::Matrix3d misalign =
        Eigen::AngleAxisd(2.0 * kDeg, Vec3d(0.3, -0.5, 0.8).normalized()).toRotationMatrix();
    std::mt19937 rng(5);
    std::normal_distribution<double> d(0.0, 1.0);
    std::vector<Vec3d> acc;
    std::vector<Vec3d> mag;
    for (int k = 0; k < 2000; ++k) {
        const Quatd q = Quatd(Eigen::Vector4d(d(rng), d(rng), d(rng), d(rng)).normalized());
        acc.push_back(q.conjugate() * Vec3d(0, 0, 9.81) + 0.02 * Vec3d(d(rng), d(rng), d(rng)));
        mag.push_back(misalign.transpose() * (q.conjugate() * fieldWorld) +
                      0.3 * Vec3d(d(rng), d(rng), d(rng)));
    }
    auto r = alignMagToAccel(acc, mag);
    ASSERT_TRUE(r) << r.error().message;
    EXPECT_EQ(r->samples, 2000);
    EXPECT_NEAR(r->dipDeg, 65.0, 0.05);
    // 2000 readings with 0.3 uT of noise (0.3 deg on 50 uT): the rotation within 0.05 deg.
    const double err =
        Eigen::AngleAxisd(Eigen::Matrix3d(r->rotation * misalign.transpose())).angle();
    EXPECT_LT(err / kDeg, 0.05);
    EXPECT_NEAR(r->angleDeg, 2.0, 0.05);
    EXPECT_GT(r->unalignedDeg, 2.0 * r->residualDeg);
}

TEST(MagAlignment, RefusesReadingsTakenWhileAccelerating) {
    std::vector<Vec3d> acc(500, Vec3d(0, 0, 14.0));  // |acc| far from g throughout
    std::vector<Vec3d> mag(500, Vec3d(0, 20, -45));
    auto r = alignMagToAccel(acc, mag);
    ASSERT_FALSE(r);
    EXPECT_NE(r.error().message.find("0 readings"), std::string::npos) << r.error().message;
}

}  // namespace
}  // namespace caphub::fusion
