// The full-body solve per frame on the 17-sensor suit: orientations and joint rotations with
// limit checks, FK, joint rates, the five end-effector Jacobians and twists, foot contacts and
// root translation with the pelvis accelerometer and the feet's dead reckoning as the firmware
// passes them (BodySolver::solve); and the body tracker the runtime feeds (BodyTracker: per
// sensor update, with the 60 Hz poses it solves from the 100 Hz samples).
#include <cmath>
#include <random>
#include <vector>

#include <benchmark/benchmark.h>

#include "fusion/body/body_solver.h"
#include "fusion/body/body_tracker.h"

namespace {

using namespace caphub;
using namespace caphub::body;

constexpr SegmentMask kFullSuit =
    ((SegmentMask{1} << kSegmentCount) - 1) &
    ~(bit(Segment::L5) | bit(Segment::C7) | bit(Segment::LMiddistal) | bit(Segment::RMiddistal));

// A second of smooth motion at 100 Hz: every joint swings sinusoidally about a random axis.
std::vector<SensorFrame> makeFrames(const std::array<Quatd, kSegmentCount>& mounting) {
    std::mt19937 rng(1);
    std::normal_distribution<double> n(0, 1);
    std::array<Vec3d, kSegmentCount> axis;
    for (auto& a : axis) {
        a = Vec3d(n(rng), n(rng), n(rng)).normalized();
    }
    BodyCalibration c;
    const Quatd qEnuWorld = c.qEnuWorld();
    std::vector<SensorFrame> frames(100);
    for (int k = 0; k < 100; ++k) {
        Pose p;
        for (int i = 0; i < kSegmentCount; ++i) {
            const auto u = static_cast<std::size_t>(i);
            p.qLocal[u] = fromAxisAngle<double>(axis[u], 0.4 * std::sin(2 * M_PI * k / 100.0 + i));
        }
        worldFromLocal(p);
        frames[static_cast<std::size_t>(k)].mask = kFullSuit;
        for (int i = 0; i < kSegmentCount; ++i) {
            const auto u = static_cast<std::size_t>(i);
            frames[static_cast<std::size_t>(k)].qEnuSensor[u] =
                qEnuWorld * p.qWorld[u] * mounting[u];
        }
    }
    return frames;
}

void BM_FullBodySolve(benchmark::State& state) {
    board::SubjectConfig subject;
    const Skeleton skeleton(*dimensionsFromSubject(subject));
    std::mt19937 rng(2);
    std::normal_distribution<double> n(0, 1);
    std::array<Quatd, kSegmentCount> mounting;
    for (auto& q : mounting) {
        q = Quatd(Eigen::Vector4d(n(rng), n(rng), n(rng), n(rng)).normalized());
    }
    const auto frames = makeFrames(mounting);
    BodyCalibration cal;
    cal.mask = kFullSuit;
    cal.mounting = mounting;
    BodySolver solver(skeleton, kFullSuit);
    solver.setCalibration(cal);
    // The pelvis accelerometer in stance (flight check and take-off estimate run every frame).
    const Vec3d pelvisForce(0.4, 9.9, -0.3);
    // Both feet rolling off the floor (valid, not still): the anchored point's slip runs every
    // frame.
    FootSensorMotion feet;
    feet.valid = {true, true};
    feet.known = feet.valid;
    feet.velocityMps = {Vec3d(0.02, 0.01, 0.05), Vec3d(0.01, 0.0, 0.04)};
    feet.rateRadS = {Vec3d(0.5, 2.0, 0.1), Vec3d(-0.3, 1.5, 0.2)};
    feet.onFootM = {Vec3d(0.0, 0.03, 0.06), Vec3d(0.0, 0.03, 0.06)};
    std::size_t k = 0;
    for (auto _ : state) {
        const Pose& p = solver.solve(frames[k], 0.01, pelvisForce, &feet);
        benchmark::DoNotOptimize(p.positionM[0]);
        k = (k + 1) % frames.size();
    }
    state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_FullBodySolve);

// One sensor on every segment of the full suit, on its nominal mounting.
std::vector<TrackedSensor> fullSuitSensors() {
    std::vector<TrackedSensor> sensors;
    for (int i = 0; i < kSegmentCount; ++i) {
        if (has(kFullSuit, i)) {
            sensors.push_back({static_cast<Segment>(i), Quatd::Identity(), Vec3d(0, 0.03, 0.06)});
        }
    }
    return sensors;
}

// What the runtime's body stage costs per sample: 17 sensors at 100 Hz through the tracker
// (holding, the feet's dead reckoning, the pelvis force) and the 60 Hz poses it solves, with
// the aiding acceleration; items are sensor updates.
void BM_BodyTrackerPerUpdate(benchmark::State& state) {
    board::SubjectConfig subject;
    const Skeleton skeleton(*dimensionsFromSubject(subject));
    const std::vector<TrackedSensor> sensors = fullSuitSensors();
    std::array<Quatd, kSegmentCount> mounting;
    mounting.fill(Quatd::Identity());
    const auto frames = makeFrames(mounting);
    BodyTracker tracker(skeleton, sensors);
    const Duration sample = std::chrono::milliseconds(10);
    Timestamp t{};
    std::size_t k = 0;
    for (auto _ : state) {
        const SensorFrame& f = frames[k];
        for (std::size_t i = 0; i < sensors.size(); ++i) {
            SensorUpdate u;
            u.sensor = static_cast<int>(i);
            u.t = t;
            u.qEnuSensor =
                f.qEnuSensor[static_cast<std::size_t>(idx(sensors[i].segment))].cast<float>();
            u.specificForceMps2 = u.qEnuSensor.conjugate() * Eigen::Vector3f(0.1f, 0.2f, 9.8f);
            u.rateRadS = Eigen::Vector3f(0.5f, -0.2f, 0.1f);
            benchmark::DoNotOptimize(tracker.update(u));
        }
        while (const auto g = tracker.due(t)) {
            benchmark::DoNotOptimize(tracker.solveAt(*g).aidEnuMps2);
        }
        t += sample;
        k = (k + 1) % frames.size();
    }
    state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(sensors.size()));
}
BENCHMARK(BM_BodyTrackerPerUpdate);

// The same after a T-pose calibration whose headings were all free (no magnetometer calibration):
// every sample also goes into its joints' relative headings (JointHeading), and the free
// headings, each sensor strapped off its nominal mounting by an angle of its own about the
// segment's up, are turned from the joints as they are found (turned_deg: by how much in all).
// The body's acceleration is one horizontal swing seen by every sensor through its true
// orientation.
void BM_BodyTrackerPerUpdateFreeHeadings(benchmark::State& state) {
    board::SubjectConfig subject;
    const Skeleton skeleton(*dimensionsFromSubject(subject));
    const std::vector<TrackedSensor> sensors = fullSuitSensors();
    std::array<Quatd, kSegmentCount> mounting;
    mounting.fill(Quatd::Identity());
    std::array<double, kSegmentCount> offset{};
    std::mt19937 rng(2);
    std::uniform_real_distribution<double> angle(-0.2, 0.2);
    for (const TrackedSensor& sensor : sensors) {
        const auto seg = static_cast<std::size_t>(idx(sensor.segment));
        offset[seg] = angle(rng);
        mounting[seg] = Quatd(Eigen::AngleAxisd(angle(rng), Vec3d::UnitY()));  // the strap's turn
    }
    const auto frames = makeFrames(mounting);
    BodyTrackerOptions options;
    options.solveUncalibrated = false;
    BodyTracker tracker(skeleton, sensors, options);
    const Duration sample = std::chrono::milliseconds(10);
    const Quatd qEnuWorld = BodyCalibration().qEnuWorld();
    const auto tpose = referencePose(ReferencePoseKind::T);
    Timestamp t{};
    std::size_t k = 0;
    const auto feed = [&](const auto& trueOrientation, double tS) {
        const Vec3d accEnu(1.5 * std::sin(2 * M_PI * 1.7 * tS), 1.0 * std::cos(2 * M_PI * 1.7 * tS),
                           9.81);
        for (std::size_t i = 0; i < sensors.size(); ++i) {
            const auto seg = static_cast<std::size_t>(idx(sensors[i].segment));
            const Quatd q = trueOrientation(seg);
            SensorUpdate u;
            u.sensor = static_cast<int>(i);
            u.t = t;
            u.headingFree = true;
            u.qEnuSensor =
                (Quatd(Eigen::AngleAxisd(offset[seg], Vec3d::UnitZ())) * q).cast<float>();
            u.specificForceMps2 = (q.conjugate() * accEnu).cast<float>();
            u.rateRadS = Eigen::Vector3f(0.5f, -0.2f, 0.1f);
            benchmark::DoNotOptimize(tracker.update(u));
        }
        while (const auto g = tracker.due(t)) {
            benchmark::DoNotOptimize(tracker.solveAt(*g).aidEnuMps2);
        }
        t += sample;
    };
    tracker.startCalibration(ReferencePoseKind::T, t);
    for (int n = 0; n < 120; ++n) {
        feed([&](std::size_t seg) { return qEnuWorld * tpose[seg] * mounting[seg]; }, 0.0);
    }
    double tS = 0;
    for (auto _ : state) {
        const SensorFrame& f = frames[k];
        feed([&](std::size_t seg) { return f.qEnuSensor[seg]; }, tS);
        tS += 0.01;
        k = (k + 1) % frames.size();
    }
    state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(sensors.size()));
    state.counters["turned_deg"] = [&] {
        double sum = 0;
        for (const double a : tracker.jointHeadingTurns()) {
            sum += std::abs(a) * 180.0 / M_PI;
        }
        return sum;
    }();
}
BENCHMARK(BM_BodyTrackerPerUpdateFreeHeadings);

}  // namespace
