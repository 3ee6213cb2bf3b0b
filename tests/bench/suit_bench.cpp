// The whole virtual-suit path, as `caphub run` and `caphub sim` drive it: motion -> IMU model ->
// register-level chip models -> simulated I2C buses and muxes -> drivers -> bus workers, on one
// thread against a stepped clock. The board is sim-suit's 17 ICM-20948, every sensor at 220 Hz
// (the chip's nearest rate at or above 200 Hz); x_realtime says how many simulated seconds one
// core runs per second.
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>

#include <benchmark/benchmark.h>
#include <fmt/format.h>

#include "board/loader.h"
#include "board/sim/virtual_suit.h"
#include "firmware/runtime/stepped_capture.h"

namespace {

using namespace caphub;
namespace fs = std::filesystem;

const fs::path kSource(CAPHUB_SOURCE_DIR);

// The sensors of sim-suit.toml (segments, mountings, positions) at `odrHz`, spread over as many
// simulated 400 kHz I2C buses (each behind a TCA9548A, two sensors per channel) as the bus
// budget needs: at 220 Hz, the ICM-20948's nearest rate at or above 200 Hz, four buses would
// run at 83 % and the loader refuses them.
board::Board suitAt(double odrHz, int buses) {
    const auto base = board::loadBoardFile(kSource / "board" / "sim-suit.toml");
    if (!base.ok()) {
        throw std::runtime_error(base.errors.at(0).str());
    }
    std::string text = fmt::format("schema = 1\nname = \"sim-suit-{:g}hz\"\n", odrHz);
    for (int i = 0; i < buses; ++i) {
        text += fmt::format(
            "[[bus]]\nname = \"b{0}\"\ntype = \"sim\"\nprotocol = \"i2c\"\nclock_hz = 400_000\n"
            "[[mux]]\nname = \"m{0}\"\nchip = \"tca9548a\"\nbus = \"b{0}\"\naddress = 0x70\n",
            i);
    }
    int n = 0;
    for (const auto& sc : base.board->sensors) {
        const int bus = n % buses;
        const int slot = n / buses;
        const Quatd& q = sc.mounting;
        text += fmt::format(
            "[[sensor]]\nname = \"{}\"\nsegment = \"{}\"\nchip = \"icm20948\"\nbus = \"b{}\"\n"
            "mux = \"m{}\"\nchannel = {}\naddress = {}\ndrdy = \"gpiochip0:{}\"\nodr_hz = {:g}\n"
            "mounting_quat = [{:.17g}, {:.17g}, {:.17g}, {:.17g}]\n"
            "position_m = [{:.17g}, {:.17g}, {:.17g}]\n",
            sc.name, board::segmentName(sc.segment), bus, bus, slot / 2,
            slot % 2 == 0 ? "0x68" : "0x69", n, odrHz, q.w(), q.x(), q.y(), q.z(), sc.positionM.x(),
            sc.positionM.y(), sc.positionM.z());
        ++n;
    }
    auto loaded = board::loadBoardText(text, fmt::format("sim-suit@{:g}Hz", odrHz));
    if (!loaded.ok()) {
        throw std::runtime_error(loaded.errors.at(0).str());
    }
    return *loaded.board;
}

// One run of the walking clip on a freshly built suit.
struct Run {
    SimulatedClock clock{Timestamp{std::chrono::seconds(1)}};
    board::sim::ClipSuit clip;
    board::SuitHardware suit;
    std::unique_ptr<firmware::SteppedCapture> capture;
    Timestamp end{};

    Run(const board::Board& b, board::sim::ErrorProfile profile) {
        board::sim::ClipOptions o;
        o.bvh = kSource / "tests" / "data" / "bvh" / "cmu_12_01_walk.bvh";
        o.profile = profile;
        auto c = board::sim::clipSources(o, clock.now());
        clip = std::move(*c);
        end = clock.now() + Duration{clip.motion->durationNs()};
        auto hw = board::sim::buildVirtualSuit(b, clock, clip.sources);
        suit = std::move(*hw);
        capture = std::make_unique<firmware::SteppedCapture>(suit, clock);
        capture->runUntil(clock.now() + std::chrono::milliseconds(300), {});  // sensors start
    }
};

void BM_VirtualSuitWholePath(benchmark::State& state) {
    const board::Board b = suitAt(static_cast<double>(state.range(0)), 5);
    const auto profile = static_cast<board::sim::ErrorProfile>(state.range(1));
    const Duration step = std::chrono::milliseconds(100);
    auto run = std::make_unique<Run>(b, profile);
    std::int64_t samples = 0;
    const auto count = [&samples](const firmware::SensorSample&) { ++samples; };
    for (auto _ : state) {
        if (run->clock.now() + step > run->end) {
            state.PauseTiming();
            run = std::make_unique<Run>(b, profile);
            state.ResumeTiming();
        }
        run->capture->runUntil(run->clock.now() + step, count);
    }
    state.SetItemsProcessed(samples);  // sensor samples per second
    state.counters["x_realtime"] = benchmark::Counter(
        static_cast<double>(state.iterations()) * toSeconds(step), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_VirtualSuitWholePath)
    ->ArgNames({"odr_hz", "profile"})
    ->Args({220, static_cast<int>(board::sim::ErrorProfile::Typical)})
    ->Args({220, static_cast<int>(board::sim::ErrorProfile::Ideal)})
    ->Args({100, static_cast<int>(board::sim::ErrorProfile::Typical)})
    ->Unit(benchmark::kMillisecond);

}  // namespace
