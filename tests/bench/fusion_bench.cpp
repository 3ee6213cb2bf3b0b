// Cost of one full 9-axis update (gyroscope + accelerometer + magnetometer) of the orientation
// filter, float and fixed point, on a buffer of hand-held-like motion.
#include <cmath>
#include <vector>

#include <benchmark/benchmark.h>

#include "fusion/orientation_filter.h"

namespace caphub::fusion {
namespace {

template <typename S>
struct Inputs {
    std::vector<Vec3<typename S::Gyr>> gyr;
    std::vector<Vec3<typename S::Acc>> acc;
    std::vector<Vec3<typename S::Mag>> mag;
};

// 4096 samples of a sensor turning at up to 5 rad/s with linear acceleration and a field of
// 49 uT: every branch of the filter (motion, gravity correction, heading correction) is taken.
template <typename S>
Inputs<S> makeInputs() {
    Inputs<S> in;
    for (int i = 0; i < 4096; ++i) {
        const double t = i / 285.714;
        const double w[3] = {3.0 * std::sin(0.9 * t), 2.0 * std::sin(1.3 * t + 1.0),
                             5.0 * std::sin(0.7 * t + 2.0)};
        const double roll = 0.6 * std::sin(0.4 * t);
        const double pitch = 0.4 * std::sin(0.3 * t + 0.5);
        in.gyr.push_back(fromDoubleVec<typename S::Gyr>(w[0], w[1], w[2]));
        in.acc.push_back(fromDoubleVec<typename S::Acc>(9.81 * std::sin(pitch) + std::sin(5 * t),
                                                        -9.81 * std::sin(roll),
                                                        9.81 * std::cos(roll) * std::cos(pitch)));
        in.mag.push_back(
            fromDoubleVec<typename S::Mag>(19.0 * std::cos(t), 19.0 * std::sin(t), -45.0));
    }
    return in;
}

template <typename S>
void fullUpdate(benchmark::State& state) {
    const Inputs<S> in = makeInputs<S>();
    OrientationFilter<S> f;
    std::size_t i = 0;
    for (auto _ : state) {
        f.updateGyr(in.gyr[i]);
        f.updateAcc(in.acc[i]);
        f.updateMag(in.mag[i]);
        benchmark::DoNotOptimize(f.state().qCorr);
        i = (i + 1) & 4095;
    }
    state.SetItemsProcessed(state.iterations());
    state.counters["ns_per_update"] =
        benchmark::Counter(static_cast<double>(state.iterations()),
                           benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}

void floatFullUpdate(benchmark::State& s) {
    fullUpdate<FloatTypes>(s);
}
void fixedFullUpdate(benchmark::State& s) {
    fullUpdate<FixedTypes>(s);
}
BENCHMARK(floatFullUpdate);
BENCHMARK(fixedFullUpdate);

}  // namespace
}  // namespace caphub::fusion
