// Cost of one full 9-axis update (gyroscope + accelerometer + magnetometer) of the orientation
// filter, float and fixed point: on a buffer of synthetic hand-held-like motion, and on real
// recorded data (the shipped excerpt of BROAD trial 21, fast combined motion at 285.7 Hz), whose
// noise, rests and field changes take the branches as a person's motion does.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include <benchmark/benchmark.h>

#include "firmware/io/broad_csv.h"
#include "fusion/calibration/online_hard_iron.h"
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

// The shipped excerpt of BROAD trial 21 (6000 samples, 21 s) in the filter's scalar types. The
// file is part of the source tree: a benchmark that cannot read it stops with the reason.
template <typename S>
Inputs<S> loadBroadExcerpt() {
    const char* path = CAPHUB_SOURCE_DIR "/tests/data/broad/21_fast_combined_excerpt.csv.gz";
    auto trial = firmware::readBroadCsv(path);
    if (!trial) {
        std::fprintf(stderr, "%s\n", trial.error().message.c_str());
        std::exit(1);
    }
    Inputs<S> in;
    for (const ImuSample& x : trial->samples) {
        in.gyr.push_back(
            fromDoubleVec<typename S::Gyr>(x.gyrRadS.x(), x.gyrRadS.y(), x.gyrRadS.z()));
        in.acc.push_back(
            fromDoubleVec<typename S::Acc>(x.accMps2.x(), x.accMps2.y(), x.accMps2.z()));
        in.mag.push_back(fromDoubleVec<typename S::Mag>(x.magUt.x(), x.magUt.y(), x.magUt.z()));
    }
    return in;
}

// One full update per iteration, in the order of the samples. At the end of the buffer the
// filter starts again from its reset state (once per 4096 or 6000 updates), so that the data's
// own sequence is what the filter sees, never a jump from its last sample to its first.
template <typename S>
void fullUpdate(benchmark::State& state, const Inputs<S>& in) {
    OrientationFilter<S> f;
    const std::size_t n = in.gyr.size();
    std::size_t i = 0;
    for (auto _ : state) {
        f.updateGyr(in.gyr[i]);
        f.updateAcc(in.acc[i]);
        f.updateMag(in.mag[i]);
        benchmark::DoNotOptimize(f.state().qCorr);
        if (++i == n) [[unlikely]] {
            i = 0;
            f.resetState();
        }
    }
    state.SetItemsProcessed(state.iterations());
    state.counters["ns_per_update"] =
        benchmark::Counter(static_cast<double>(state.iterations()),
                           benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}

void floatFullUpdate(benchmark::State& s) {
    fullUpdate<FloatTypes>(s, makeInputs<FloatTypes>());
}
void fixedFullUpdate(benchmark::State& s) {
    fullUpdate<FixedTypes>(s, makeInputs<FixedTypes>());
}
void floatFullUpdateBroad21(benchmark::State& s) {
    fullUpdate<FloatTypes>(s, loadBroadExcerpt<FloatTypes>());
}
void fixedFullUpdateBroad21(benchmark::State& s) {
    fullUpdate<FixedTypes>(s, loadBroadExcerpt<FixedTypes>());
}
// The online hard- and soft-iron estimator of an uncalibrated magnetometer (FusionStage feeds it
// every reading): one reading and its up direction into the sums, on the BROAD excerpt's field
// with a 150 uT offset; the fit itself runs about once a second (estimateOnce below).
void onlineMagAdd(benchmark::State& state) {
    const Inputs<FloatTypes> in = loadBroadExcerpt<FloatTypes>();
    OnlineHardIron est(285.714);
    const Vec3d offset(150.0, -80.0, 60.0);
    std::vector<Vec3d> mag;
    for (const auto& m : in.mag) {
        mag.push_back(Vec3d(m.x, m.y, m.z) + offset);
    }
    for (const Vec3d& m : mag) {
        est.add(m);
    }
    est.refresh();
    std::size_t i = 0;
    for (auto _ : state) {
        est.add(mag[i]);
        est.addAlignment(mag[i], Vec3d::UnitZ());
        benchmark::DoNotOptimize(est.state().moments(0, 0));
        i = i + 1 == mag.size() ? 0 : i + 1;
    }
    state.SetItemsProcessed(state.iterations());
}
void onlineMagEstimate(benchmark::State& state) {
    const Inputs<FloatTypes> in = loadBroadExcerpt<FloatTypes>();
    OnlineHardIron est(285.714);
    for (const auto& m : in.mag) {
        est.add(Vec3d(m.x, m.y, m.z));
    }
    for (auto _ : state) {
        benchmark::DoNotOptimize(est.estimate().offsetUt);
    }
    state.SetItemsProcessed(state.iterations());
}
BENCHMARK(onlineMagAdd);
BENCHMARK(onlineMagEstimate);
BENCHMARK(floatFullUpdate);
BENCHMARK(fixedFullUpdate);
BENCHMARK(floatFullUpdateBroad21);
BENCHMARK(fixedFullUpdateBroad21);

}  // namespace
}  // namespace caphub::fusion
