// Skinning throughput (M vertices/s) and the preview's frame time with its stage breakdown.
// Run with LP_NUM_THREADS=1 for the single-core llvmpipe figures.
#include <chrono>
#include <random>

#include <benchmark/benchmark.h>

#include "render/image.h"
#include "render/mjpeg_server.h"
#include "render/renderer.h"
#include "render/skin.h"
#include "render/skinning.h"

namespace {

using namespace caphub;
using namespace caphub::render;

const Skin& defaultSkin() {
    static const Skin skin = [] {
        auto s = loadDefaultSkin();
        if (!s) {
            std::fprintf(stderr, "%s\n", s.error().message.c_str());
            std::abort();
        }
        return std::move(*s);
    }();
    return skin;
}

SkinPose somePose() {
    std::mt19937 rng(1);
    std::uniform_real_distribution<double> u(-0.4, 0.4);
    SkinPose p;
    for (auto& q : p.qWorld) {
        q = Quatd(1.0, u(rng), u(rng), u(rng)).normalized();
    }
    p.pelvisM = Vec3d(0, 0.95, 0);
    return p;
}

enum Mode { kShipped = 0, kAllLbs = 1, kAllDqs = 2 };

// arg0: 0 the shipped groups (rigid + LBS + DQS forearms), 1 every group LBS, 2 every group DQS.
// arg1: 1 rigid groups skinned rigidly, 0 rigid groups blended like the others.
void BM_Skin(benchmark::State& state) {
    const Skin& skin = defaultSkin();
    Skinner sk(skin);
    const auto mode = static_cast<Mode>(state.range(0));
    for (std::size_t g = 0; g < skin.groups.size(); ++g) {
        if (skin.groups[g].method == GroupMethod::Rigid) {
            continue;
        }
        if (mode == kAllLbs) {
            (void)sk.setGroupMethod(static_cast<int>(g), GroupMethod::Lbs);
        } else if (mode == kAllDqs) {
            (void)sk.setGroupMethod(static_cast<int>(g), GroupMethod::Dqs);
        }
    }
    sk.setRigidGroupsBlended(state.range(1) == 0);
    if (mode == kAllDqs && state.range(1) == 0) {
        // Blended rigid groups follow the deformable method of the run.
        for (std::size_t g = 0; g < skin.groups.size(); ++g) {
            (void)sk.setGroupMethod(static_cast<int>(g), GroupMethod::Dqs);
        }
    }
    sk.setPose(somePose());
    for (auto _ : state) {
        sk.skin();
        benchmark::DoNotOptimize(sk.output().data());
        benchmark::ClobberMemory();
    }
    state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(skin.vertexCount()));
    state.counters["Mvert/s"] = benchmark::Counter(static_cast<double>(skin.vertexCount()) * 1e-6,
                                                   benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_Skin)
    ->ArgNames({"mode", "rigid"})
    ->Args({kShipped, 1})
    ->Args({kShipped, 0})
    ->Args({kAllLbs, 1})
    ->Args({kAllLbs, 0})
    ->Args({kAllDqs, 1})
    ->Args({kAllDqs, 0});

void BM_SetPose(benchmark::State& state) {
    Skinner sk(defaultSkin());
    const SkinPose p = somePose();
    for (auto _ : state) {
        sk.setPose(p);
        benchmark::ClobberMemory();
    }
}
BENCHMARK(BM_SetPose);

// One preview frame: skin, upload, draw, read-back, and encode (arg2: 0 JPEG for the MJPEG
// stream, 1 PNG). Per-stage means in ms as counters; the fps counter is the whole frame's.
void BM_PreviewFrame(benchmark::State& state) {
    const Skin& skin = defaultSkin();
    RenderOptions ro;
    ro.width = static_cast<int>(state.range(0));
    ro.height = static_cast<int>(state.range(1));
    auto r = Renderer::create(skin, ro);
    if (!r) {
        state.SkipWithError(r.error().message.c_str());
        return;
    }
    Skinner sk(skin);
    sk.setPose(somePose());
    FrameInput f;
    f.sensors.fill(SensorState::Ok);
    Image img;
    JpegEncoder jpeg;
    std::vector<std::uint8_t> bytes;
    const auto png = std::filesystem::temp_directory_path() / "caphub_bench_frame.png";
    double skinS = 0, uploadS = 0, drawS = 0, readS = 0, encodeS = 0;
    for (auto _ : state) {
        const auto t0 = std::chrono::steady_clock::now();
        sk.skin();
        const auto t1 = std::chrono::steady_clock::now();
        f.vertices = sk.output();
        f.jointsM = sk.jointPositionsM();
        StageTimes st;
        if (!(*r)->render(f, img, &st)) {
            state.SkipWithError("render failed");
            return;
        }
        const auto t2 = std::chrono::steady_clock::now();
        if (state.range(2) == 0) {
            (void)jpeg.encode(img, 80, bytes);
        } else {
            (void)writePng(img, png);
        }
        const auto t3 = std::chrono::steady_clock::now();
        skinS += std::chrono::duration<double>(t1 - t0).count();
        uploadS += static_cast<double>(st.uploadNs) * 1e-9;
        drawS += static_cast<double>(st.drawNs) * 1e-9;
        readS += static_cast<double>(st.readbackNs) * 1e-9;
        encodeS += std::chrono::duration<double>(t3 - t2).count();
    }
    const double n = static_cast<double>(state.iterations());
    state.counters["skin_ms"] = 1e3 * skinS / n;
    state.counters["upload_ms"] = 1e3 * uploadS / n;
    state.counters["draw_ms"] = 1e3 * drawS / n;
    state.counters["readback_ms"] = 1e3 * readS / n;
    state.counters["encode_ms"] = 1e3 * encodeS / n;
    state.counters["fps"] = benchmark::Counter(1.0, benchmark::Counter::kIsIterationInvariantRate);
    std::filesystem::remove(png);
}
BENCHMARK(BM_PreviewFrame)
    ->ArgNames({"w", "h", "png"})
    ->Args({320, 240, 0})
    ->Args({640, 480, 0})
    ->Args({320, 240, 1})
    ->Args({640, 480, 1})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

}  // namespace
