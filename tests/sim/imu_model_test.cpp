// The physical IMU model against analytic motions and a real clip, and the error model's
// profiles: figures, reproducibility, noise level, worst cases, drift, disturbances.
#include "board/sim/imu_model.h"

#include <atomic>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <new>
#include <numbers>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

// Counts heap allocations so a test can check that a reading allocates nothing.
namespace {
std::atomic<long> gAllocations{0};
}  // namespace

void* operator new(std::size_t n) {
    gAllocations.fetch_add(1, std::memory_order_relaxed);
    if (void* p = std::malloc(n == 0 ? 1 : n)) {
        return p;
    }
    throw std::bad_alloc();
}
// The replacement new above allocates with malloc, so free is the matching release; GCC 12's
// -Wmismatched-new-delete misreads that once the operators are inlined at -O2.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
void operator delete(void* p) noexcept {
    std::free(p);
}
void operator delete(void* p, std::size_t) noexcept {
    std::free(p);
}
#pragma GCC diagnostic pop

namespace caphub::board::sim {
namespace {

using board::Segment;
using ::testing::HasSubstr;

const std::filesystem::path kData = std::filesystem::path(CAPHUB_TEST_DATA_DIR) / "bvh";
constexpr double kRad = std::numbers::pi / 180.0;
constexpr double kG = 9.81;

// A segment held still at a fixed pose.
class Still : public SegmentTrajectory {
public:
    Still(const Quatd& q, const Vec3d& p) : q_(q), p_(p) {}
    void evaluate(Segment, std::int64_t, SegmentState& out) const override {
        out = SegmentState{};
        out.qWorldSegment = q_;
        out.positionM = p_;
    }

private:
    Quatd q_;
    Vec3d p_;
};

// A segment turning at a constant body rate about a fixed origin: q(t) = q0 exp(omega t).
class Spinning : public SegmentTrajectory {
public:
    Spinning(const Quatd& q0, const Vec3d& omegaRadS) : q0_(q0), omega_(omegaRadS) {}
    void evaluate(Segment, std::int64_t tNs, SegmentState& out) const override {
        out = SegmentState{};
        out.qWorldSegment =
            q0_ * fromRotationVector<double>(omega_ * (static_cast<double>(tNs) * 1e-9));
        out.omegaRadS = omega_;
    }

private:
    Quatd q0_;
    Vec3d omega_;
};

ImuErrorSpec spec(const char* chip, ErrorProfile p) {
    auto s = errorSpec(chip, p);
    EXPECT_TRUE(s.ok()) << s.error().message;
    return s.ok() ? *s : ImuErrorSpec{};
}

// Only the white noise of a chip: for statistics on the noise alone.
ImuErrorSpec noiseOnly(const char* chip) {
    const ImuErrorSpec t = spec(chip, ErrorProfile::Typical);
    ImuErrorSpec s;
    s.gyro.noiseDensity = t.gyro.noiseDensity;
    s.accel.noiseDensity = t.accel.noiseDensity;
    s.mag.noiseRms = t.mag.noiseRms;
    return s;
}

const Environment kEarth;

TEST(ImuModel, SensorAtRestReadsGravityUpAndTheEarthField) {
    const Quatd q = Quatd(Eigen::AngleAxisd(0.7, Vec3d(1, 2, 3).normalized()));
    const Still still(q, Vec3d(0, 1, 0));
    VirtualImu imu(still, kEarth, {Segment::Pelvis, Quatd::Identity(), Vec3d::Zero()},
                   ImuErrorSpec{}, 1, 200, 100);
    Vec3d gyro;
    Vec3d accel;
    Vec3d mag;
    imu.readGyroAccel(0, gyro, accel);
    imu.readMag(0, mag);
    EXPECT_EQ(gyro, Vec3d::Zero());
    // Specific force at rest points up (the ground pushes); in the sensor frame it is q^-1 up.
    EXPECT_LT((accel - q.conjugate() * Vec3d(0, kG, 0)).norm(), 1e-12);
    // In ENU the field is 50 uT at 65 degrees below north.
    const Vec3d magEnu = qEnuWorld() * q * mag;
    EXPECT_LT((magEnu - Vec3d(0, 50 * std::cos(65 * kRad), -50 * std::sin(65 * kRad))).norm(),
              1e-12);
}

TEST(ImuModel, SensorAtRestWithChipNoiseReadsGravityWithinNoise) {
    const Still still(Quatd::Identity(), Vec3d::Zero());
    VirtualImu imu(still, kEarth, {}, noiseOnly("icm20948"), 5, 200, 100);
    constexpr int kN = 4000;
    double sum = 0;
    for (int i = 0; i < kN; ++i) {
        Vec3d g;
        Vec3d a;
        imu.readGyroAccel(i * 5'000'000LL, g, a);
        sum += a.norm();
    }
    const double sigma = 230e-6 * 9.80665 * std::sqrt(200.0 / 2);  // per axis, per sample
    // The mean of |a| is 9.81 to within 4 standard errors (sigma / sqrt(N)) plus the bias of a
    // noisy vector's norm, sigma^2 / |g|.
    EXPECT_NEAR(sum / kN, kG, 4 * sigma / std::sqrt(kN) + sigma * sigma / kG);
}

TEST(ImuModel, TypicalPartReadsItsOwnScaleAndBiasOfGravity) {
    const Still still(Quatd::Identity(), Vec3d::Zero());
    VirtualImu imu(still, kEarth, {}, spec("icm20948", ErrorProfile::Typical), 9, 200, 100);
    Vec3d mean = Vec3d::Zero();
    constexpr int kN = 2000;
    for (int i = 0; i < kN; ++i) {
        Vec3d g;
        Vec3d a;
        imu.readGyroAccel(i * 5'000'000LL, g, a);  // 10 s: the drift stays far below the bias
        mean += a / kN;
    }
    const Vec3d expected =
        imu.constants().accelMatrix * Vec3d(0, kG, 0) + imu.constants().accelBiasMps2;
    // Noise averages to sigma / sqrt(N) = 1.6e-3 m/s^2; the 10 s bias walk adds < 1e-4.
    EXPECT_LT((mean - expected).norm(), 1e-2);
    EXPECT_GT((expected - Vec3d(0, kG, 0)).norm(), 1e-3);  // the part is not ideal
}

TEST(ImuModel, ConstantRotationRateReadsThatRateInTheSensorFrame) {
    const Vec3d omega(0.3, -1.2, 2.5);
    const Spinning spin(Quatd(Eigen::AngleAxisd(0.4, Vec3d::UnitZ())), omega);
    const Quatd mounting(Eigen::AngleAxisd(90 * kRad, Vec3d::UnitX()));
    VirtualImu imu(spin, kEarth, {Segment::LForearm, mounting, Vec3d::Zero()}, ImuErrorSpec{}, 1,
                   200, 100);
    for (std::int64_t t = 0; t < 2'000'000'000; t += 123'456'789) {
        Vec3d g;
        Vec3d a;
        imu.readGyroAccel(t, g, a);
        EXPECT_LT((g - mounting.conjugate() * omega).norm(), 1e-12);
        EXPECT_NEAR(a.norm(), kG, 1e-12);  // turning about its own origin: gravity only
    }
}

TEST(ImuModel, SensorOnARotatingArmReadsTheCentripetalAcceleration) {
    const double rate = 3.0;  // rad/s about the vertical
    const Spinning spin(Quatd::Identity(), Vec3d(0, rate, 0));
    const Vec3d arm(0.6, 0, 0);
    VirtualImu imu(spin, kEarth, {Segment::RHand, Quatd::Identity(), arm}, ImuErrorSpec{}, 1, 200,
                   100);
    Vec3d g;
    Vec3d a;
    imu.readGyroAccel(777'000'000, g, a);
    // Toward the axis, rate^2 r = 5.4 m/s^2, within 1 %; gravity up on the sensor's y.
    EXPECT_NEAR(-a.x(), rate * rate * arm.x(), 0.01 * rate * rate * arm.x());
    EXPECT_NEAR(a.y(), kG, 1e-12);
    EXPECT_NEAR(a.z(), 0, 1e-12);
}

TEST(ImuModel, SensorOnAnArmTurnedByABvhClipReadsTheCentripetalAcceleration) {
    // One joint turning about Y by 2 degrees per 10 ms frame (200 deg/s) for 2 s.
    std::string text =
        "HIERARCHY\nROOT Arm\n{\nOFFSET 0 0 0\nCHANNELS 1 Yrotation\nEnd Site\n{\nOFFSET 50 0 "
        "0\n}\n}\nMOTION\nFrames: 201\nFrame Time: 0.01\n";
    for (int f = 0; f < 201; ++f) {
        text += std::to_string(2 * f) + "\n";
    }
    const auto clip = parseBvh(text, "arm");
    ASSERT_TRUE(clip.ok()) << clip.error().message;
    JointMap map;
    map.name = "arm";
    map.unitM = 0.01;
    map.joints[static_cast<std::size_t>(Segment::Pelvis)] = {"Arm"};
    const auto motion = Motion::fromClip(*clip, map);
    ASSERT_TRUE(motion.ok()) << motion.error().message;
    const double rate = 200 * kRad;
    const Vec3d arm(0.5, 0, 0);
    VirtualImu imu(*motion, kEarth, {Segment::Pelvis, Quatd::Identity(), arm}, ImuErrorSpec{}, 1,
                   200, 100);
    for (std::int64_t t = 100'000'000; t < 1'900'000'000; t += 37'000'000) {
        Vec3d g;
        Vec3d a;
        imu.readGyroAccel(t, g, a);
        EXPECT_NEAR(-a.x(), rate * rate * arm.x(), 0.01 * rate * rate * arm.x()) << t;
        EXPECT_NEAR(g.y(), rate, 1e-9) << t;
    }
}

TEST(ImuModel, GyroIntegratedOverTheWalkClipReproducesEveryOrientation) {
    const auto clip = loadBvh(kData / "cmu_12_01_walk.bvh");
    ASSERT_TRUE(clip.ok()) << clip.error().message;
    const auto motion = Motion::fromClip(*clip, *detectJointMap(*clip));
    ASSERT_TRUE(motion.ok()) << motion.error().message;
    const Quatd mounting(Eigen::AngleAxisd(1.0, Vec3d(0.3, -0.5, 0.8).normalized()));
    constexpr std::int64_t kStepNs = 1'000'000;  // the gyro read at 1 kHz
    double worstDeg = 0;
    for (const auto& s : board::kSegments) {
        VirtualImu imu(*motion, kEarth, {s.id, mounting, Vec3d(0.02, 0.05, 0.03)},
                       spec("icm20948", ErrorProfile::Ideal), 3, 1000, 100);
        SegmentState st;
        motion->evaluate(s.id, 0, st);
        Quatd q = st.qWorldSegment * mounting;  // start from the truth, then gyro only
        for (std::int64_t t = 0; t + kStepNs <= motion->durationNs(); t += kStepNs) {
            Vec3d g;
            Vec3d a;
            imu.readGyroAccel(t + kStepNs / 2, g, a);  // midpoint rule
            q = integrateBodyRate(q, g, static_cast<double>(kStepNs) * 1e-9);
            if ((t / kStepNs) % 10 == 9) {  // compare every 10 ms
                motion->evaluate(s.id, t + kStepNs, st);
                worstDeg = std::max(worstDeg, angleBetween(q, st.qWorldSegment * mounting) / kRad);
            }
        }
    }
    RecordProperty("worst_deg", std::to_string(worstDeg));
    std::printf("gyro integration over the walk clip, 21 segments, 1 kHz: worst %.3g deg\n",
                worstDeg);
    EXPECT_LT(worstDeg, 0.1);
}

TEST(ImuModel, MagnetometerAddsADipoleFieldAtTheSensor) {
    Environment env;
    env.dipoles.push_back({Vec3d(1.3, 1, 0), Vec3d(1, 0, 0)});  // 1 A m^2 along +x
    const Still still(Quatd::Identity(), Vec3d(1, 1, 0));
    VirtualImu imu(still, env, {}, ImuErrorSpec{}, 1, 200, 100);
    Vec3d mag;
    imu.readMag(0, mag);
    // On the dipole's axis, 0.3 m away: mu0 / (4 pi) * 2 m / r^3 = 1e-7 * 2 / 0.027 T.
    const Vec3d dipole = mag - env.earthFieldWorldUt();
    EXPECT_LT((dipole - Vec3d(2e-7 / 0.027 * 1e6, 0, 0)).norm(), 1e-9);
}

TEST(ImuModel, EarthFieldIntensityDipAndDeclinationAreConfigurable) {
    Environment env;
    env.fieldUt = 30;
    env.dipDeg = -40;  // southern hemisphere: the field points up
    env.declinationDeg = 10;
    const Vec3d enu = qEnuWorld() * env.earthFieldWorldUt();
    EXPECT_NEAR(enu.norm(), 30, 1e-12);
    EXPECT_NEAR(std::asin(-enu.z() / 30) / kRad, -40, 1e-9);
    EXPECT_NEAR(std::atan2(enu.x(), enu.y()) / kRad, 10, 1e-9);  // east of north
}

TEST(ImuModel, WorldFrameIsTheEnuFrameTurnedYUp) {
    const Quatd q = qEnuWorld();
    EXPECT_LT((q * Vec3d::UnitX() - Vec3d(-1, 0, 0)).norm(), 1e-15);  // west
    EXPECT_LT((q * Vec3d::UnitY() - Vec3d(0, 0, 1)).norm(), 1e-15);   // up
    EXPECT_LT((q * Vec3d::UnitZ() - Vec3d(0, 1, 0)).norm(), 1e-15);   // north
}

TEST(ErrorModel, NoiseHasTheDatasheetDensityAtTheOutputRate) {
    const Still still(Quatd::Identity(), Vec3d::Zero());
    VirtualImu imu(still, kEarth, {}, noiseOnly("lsm6dsox+lis3mdl"), 11, 416, 80);
    constexpr int kN = 20000;
    Eigen::Array3d sumSq = Eigen::Array3d::Zero();
    Eigen::Array3d magSq = Eigen::Array3d::Zero();
    const Vec3d magTrue = kEarth.earthFieldWorldUt();
    for (int i = 0; i < kN; ++i) {
        Vec3d g;
        Vec3d a;
        Vec3d m;
        imu.readGyroAccel(i * 2'403'846LL, g, a);
        imu.readMag(i * 12'500'000LL, m);
        sumSq += g.array().square();
        magSq += (m - magTrue).array().square();
    }
    const double expected = 3.8e-3 * kRad * std::sqrt(416.0 / 2);
    // The sample standard deviation of N normals has a relative standard error of
    // 1 / sqrt(2 N) = 0.5 %; 3 % is six of them.
    for (int axis = 0; axis < 3; ++axis) {
        EXPECT_NEAR(std::sqrt(sumSq[axis] / kN), expected, 0.03 * expected);
        EXPECT_NEAR(std::sqrt(magSq[axis] / kN), 0.41, 0.03 * 0.41);  // LIS3MDL 4.1 mgauss
    }
}

TEST(ErrorModel, SameSeedSameReadingsAndTheSameInstantReadsTheSame) {
    const Still still(Quatd::Identity(), Vec3d::Zero());
    const ImuErrorSpec s = spec("icm20948", ErrorProfile::Typical);
    VirtualImu a(still, kEarth, {}, s, 42, 200, 100);
    VirtualImu b(still, kEarth, {}, s, 42, 200, 100);
    for (std::int64_t t = 0; t < 100'000'000; t += 5'000'000) {
        Vec3d ga;
        Vec3d aa;
        Vec3d gb;
        Vec3d ab;
        a.readGyroAccel(t, ga, aa);
        b.readGyroAccel(t, gb, ab);
        EXPECT_EQ(ga, gb);
        EXPECT_EQ(aa, ab);
        Vec3d again;
        a.readGyroAccel(t, again, aa);  // a second read of the same instant
        EXPECT_EQ(again, ga);
    }
}

TEST(ErrorModel, DifferentSeedsMakeDifferentParts) {
    const Still still(Quatd::Identity(), Vec3d::Zero());
    const ImuErrorSpec s = spec("icm20948", ErrorProfile::Typical);
    const VirtualImu a(still, kEarth, {}, s, 1, 200, 100);
    const VirtualImu b(still, kEarth, {}, s, 2, 200, 100);
    EXPECT_NE(a.constants().gyroBiasRadS, b.constants().gyroBiasRadS);
    EXPECT_NE(a.constants().magOffsetUt, b.constants().magOffsetUt);
}

TEST(ErrorModel, IdealProfileHasNoErrors) {
    const Still still(Quatd::Identity(), Vec3d::Zero());
    const VirtualImu imu(still, kEarth, {}, spec("icm20948", ErrorProfile::Ideal), 1, 200, 100);
    EXPECT_EQ(imu.constants().gyroMatrix, Eigen::Matrix3d::Identity());
    EXPECT_EQ(imu.constants().magMatrix, Eigen::Matrix3d::Identity());
    EXPECT_EQ(imu.constants().accelBiasMps2, Vec3d::Zero());
    EXPECT_EQ(imu.constants().magOffsetUt, Vec3d::Zero());
}

TEST(ErrorModel, HarshPartSitsAtTheWorstCase) {
    const Still still(Quatd::Identity(), Vec3d::Zero());
    const VirtualImu imu(still, kEarth, {}, spec("icm20948", ErrorProfile::Harsh), 8, 200, 100);
    // Three times the typical +-5 dps zero-rate tolerance on every axis, sign drawn.
    for (int axis = 0; axis < 3; ++axis) {
        EXPECT_NEAR(std::abs(imu.constants().gyroBiasRadS[axis]), 15 * kRad, 1e-15);
        EXPECT_NEAR(std::abs(imu.constants().gyroMatrix(axis, axis) - 1), 3 * 0.015, 1e-15);
    }
}

TEST(ErrorModel, BiasRandomWalkGrowsWithTheSquareRootOfTime) {
    const Still still(Quatd::Identity(), Vec3d::Zero());
    ImuErrorSpec s;
    s.gyro.biasRandomWalk = 1e-3;  // rad/s/sqrt(s)
    constexpr int kParts = 400;
    constexpr double kSpanS = 100;
    double sumSq = 0;
    for (int seed = 0; seed < kParts; ++seed) {
        VirtualImu imu(still, kEarth, {}, s, static_cast<std::uint64_t>(seed), 10, 10);
        Vec3d g;
        Vec3d a;
        for (int i = 0; i <= 10; ++i) {  // ten steps of 10 s
            imu.readGyroAccel(static_cast<std::int64_t>(i * kSpanS / 10 * 1e9), g, a);
        }
        sumSq += g.squaredNorm();
    }
    const double expected = 3 * 1e-6 * kSpanS;  // three axes, variance rate^2 t each
    // 1200 squared normals: relative standard error sqrt(2 / 1200) = 4 %; 15 % is 3.7 of them.
    EXPECT_NEAR(sumSq / kParts, expected, 0.15 * expected);
}

TEST(ErrorModel, ProfilesHaveNamesAndUnknownChipsAreRefused) {
    EXPECT_EQ(parseErrorProfile("typical"), ErrorProfile::Typical);
    EXPECT_EQ(parseErrorProfile("harsh"), ErrorProfile::Harsh);
    EXPECT_EQ(parseErrorProfile("ideal"), ErrorProfile::Ideal);
    EXPECT_FALSE(parseErrorProfile("Typical"));
    const auto r = errorSpec("bno055", ErrorProfile::Typical);
    ASSERT_FALSE(r.ok());
    EXPECT_THAT(r.error().message, HasSubstr("no error figures for chip 'bno055'"));
}

TEST(ErrorModel, HarshEnvironmentDisturbsTheFieldAroundTheCaptureArea) {
    const Vec3d centre(0, 1, 0);
    const Environment calm = environmentFor(ErrorProfile::Typical, centre);
    const Environment harsh = environmentFor(ErrorProfile::Harsh, centre);
    EXPECT_TRUE(calm.dipoles.empty());
    ASSERT_FALSE(harsh.dipoles.empty());
    // Near the floor by the centre (a foot) and at hip height by the cabinet.
    EXPECT_GT((harsh.fieldWorldUt(centre + Vec3d(0, -0.9, 0)) - harsh.earthFieldWorldUt()).norm(),
              5.0);
    EXPECT_GT((harsh.fieldWorldUt(centre + Vec3d(0.5, 0, 0)) - harsh.earthFieldWorldUt()).norm(),
              5.0);
}

TEST(ErrorModel, ReadingsDoNotAllocate) {
    const auto clip = loadBvh(kData / "cmu_12_01_walk.bvh");
    ASSERT_TRUE(clip.ok());
    const auto motion = Motion::fromClip(*clip, *detectJointMap(*clip));
    ASSERT_TRUE(motion.ok());
    VirtualImu imu(*motion, environmentFor(ErrorProfile::Harsh, Vec3d(0, 1, 0)),
                   {Segment::LHand, Quatd::Identity(), Vec3d(0.05, 0, 0)},
                   spec("icm20948", ErrorProfile::Harsh), 1, 200, 100);
    SuitState truth;
    Vec3d g;
    Vec3d a;
    Vec3d m;
    const long before = gAllocations.load();
    for (std::int64_t t = 0; t < 1'000'000'000; t += 5'000'000) {
        imu.readGyroAccel(t, g, a);
        imu.readMag(t, m);
        motion->evaluateAll(t, truth);
    }
    EXPECT_EQ(gAllocations.load() - before, 0);
}

}  // namespace
}  // namespace caphub::board::sim
