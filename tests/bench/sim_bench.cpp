// The virtual suit's cost: a 17-sensor suit sampled at 200 Hz (gyro/accel every sample, mag and
// the whole suit's ground truth with it), fitting a clip, and reading a BVH file. The suit
// sample reports how many times faster than real time one core simulates (x_realtime).
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <vector>

#include <benchmark/benchmark.h>

#include "board/sim/bvh.h"
#include "board/sim/imu_model.h"
#include "board/sim/joint_map.h"
#include "board/sim/motion.h"

namespace {

using namespace caphub;
using namespace caphub::board::sim;
using caphub::board::Segment;

const std::filesystem::path kWalk =
    std::filesystem::path(CAPHUB_SOURCE_DIR) / "tests" / "data" / "bvh" / "cmu_12_01_walk.bvh";

std::string readFile(const std::filesystem::path& p) {
    std::ifstream in(p, std::ios::binary);
    std::ostringstream s;
    s << in.rdbuf();
    return s.str();
}

const Motion& walkMotion() {
    static const Motion m = [] {
        const auto clip = loadBvh(kWalk);
        return *Motion::fromClip(*clip, *detectJointMap(*clip));
    }();
    return m;
}

void BM_SuitSample17At200Hz(benchmark::State& state) {
    const Motion& motion = walkMotion();
    const Environment env = environmentFor(ErrorProfile::Harsh, Vec3d(0, 1, 0));
    const ImuErrorSpec spec = *errorSpec("icm20948", ErrorProfile::Typical);
    // The 17 segments of the full suit (sim-suit.toml): all but the clavicles and toes.
    std::vector<std::unique_ptr<VirtualImu>> suit;
    std::uint64_t seed = 1;
    for (const auto& s : board::kSegments) {
        if (s.id == Segment::LClavicle || s.id == Segment::RClavicle ||
            s.id == Segment::LMiddistal || s.id == Segment::RMiddistal) {
            continue;
        }
        suit.push_back(std::make_unique<VirtualImu>(
            motion, env, SensorPlacement{s.id, Quatd::Identity(), Vec3d(0.03, 0.05, 0.04)}, spec,
            seed++, 200, 100));
    }
    constexpr std::int64_t kPeriodNs = 5'000'000;  // 200 Hz
    std::int64_t t = 0;
    SuitState truth;
    Vec3d g;
    Vec3d a;
    Vec3d m;
    for (auto _ : state) {
        for (auto& imu : suit) {
            imu->readGyroAccel(t, g, a);
            imu->readMag(t, m);
        }
        motion.evaluateAll(t, truth);
        benchmark::DoNotOptimize(truth);
        t = (t + kPeriodNs) % motion.durationNs();
    }
    state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(suit.size()));
    state.counters["x_realtime"] = benchmark::Counter(
        static_cast<double>(state.iterations()) * kPeriodNs * 1e-9, benchmark::Counter::kIsRate);
}
BENCHMARK(BM_SuitSample17At200Hz);

void BM_FitWalkClip(benchmark::State& state) {
    const auto clip = loadBvh(kWalk);
    const JointMap& map = *detectJointMap(*clip);
    for (auto _ : state) {
        auto m = Motion::fromClip(*clip, map);
        benchmark::DoNotOptimize(m);
    }
    state.SetItemsProcessed(state.iterations() * clip->frameCount);  // frames/s
}
BENCHMARK(BM_FitWalkClip)->Unit(benchmark::kMillisecond);

void BM_ParseWalkClip(benchmark::State& state) {
    const std::string text = readFile(kWalk);
    for (auto _ : state) {
        auto clip = parseBvh(text, "walk");
        benchmark::DoNotOptimize(clip);
    }
    state.SetBytesProcessed(state.iterations() * static_cast<std::int64_t>(text.size()));
}
BENCHMARK(BM_ParseWalkClip)->Unit(benchmark::kMillisecond);

}  // namespace
