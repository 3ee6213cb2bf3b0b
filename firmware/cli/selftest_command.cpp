// caphub selftest: probes every sensor of a board and checks it end to end - it starts (reset,
// identity, configuration), its identity register and its whole configuration read back, and a
// second of samples arrives at its rate with plausible values - and shows each bus's measured
// load beside its budget. Exit 0 when every sensor passes, 1 otherwise.
#include <chrono>
#include <cmath>

#include <fmt/format.h>

#include "board/bus_budget.h"
#include "board/sim/virtual_suit.h"
#include "firmware/cli/app.h"
#include "firmware/cli/commands.h"
#include "firmware/cli/data_dir.h"
#include "firmware/cli/number_checks.h"
#include "firmware/runtime/hub.h"

namespace caphub::firmware {

namespace {

struct SelftestOptions {
    std::string board = "sim-suit";
    double seconds = 1.0;
};

// What one sensor delivered during the sample check.
struct SensorStats {
    std::uint64_t samples = 0;
    Eigen::Vector3d accSum = Eigen::Vector3d::Zero();
    Eigen::Vector3d gyrSum = Eigen::Vector3d::Zero();
    Eigen::Vector3d accFirst = Eigen::Vector3d::Zero();
    bool accChanged = false;
    std::uint64_t saturated = 0;
    std::uint64_t magReadings = 0;
    double magNormSum = 0;

    void add(const hal::ImuSample& s) {
        const Eigen::Vector3d acc = s.accMps2.cast<double>();
        if (samples == 0) {
            accFirst = acc;
        }
        accChanged = accChanged || acc != accFirst;
        accSum += acc;
        gyrSum += s.gyrRadps.cast<double>();
        ++samples;
        if ((s.flags & (hal::ImuSample::kAccSaturated | hal::ImuSample::kGyrSaturated)) != 0) {
            ++saturated;
        }
        if ((s.flags & hal::ImuSample::kMagFresh) != 0) {
            ++magReadings;
            magNormSum += s.magUt.cast<double>().norm();
        }
    }
};

constexpr double kMinSamples = 20.0;

int selftest(const SelftestOptions& o) {
    const auto loaded = loadCommandBoard(o.board);
    if (!loaded) {
        return kExitUsage;
    }
    const board::Board& b = *loaded;
    const bool sim = board::allBusesSimulated(b);
    // The rate is judged within 5 % (one sample in 20): the slowest sensor must give 20.
    for (const auto& sc : b.sensors) {
        if (o.seconds * sc.achievedOdrHz < kMinSamples) {
            fmt::print(stderr,
                       "caphub selftest: --seconds {:g}: sensor {} at {:g} Hz gives fewer than "
                       "{:g} samples to judge its rate by; give at least {:g} s\n",
                       o.seconds, sc.name, sc.achievedOdrHz, kMinSamples,
                       std::ceil(kMinSamples / sc.achievedOdrHz * 10.0) / 10.0);
            return kExitUsage;
        }
    }
    fmt::print("caphub selftest: {} sensors on {} buses of '{}' ({}), {:g} s of samples\n\n",
               b.sensors.size(), b.buses.size(), b.name, sim ? "virtual suit" : "hub buses",
               o.seconds);

    std::unique_ptr<Clock> clock;
    if (sim) {
        clock = std::make_unique<SimulatedClock>(Timestamp{std::chrono::seconds(1)});
    } else {
        clock = std::make_unique<MonotonicClock>();
    }
    // The virtual suit's sensors lie still on a table (typical chip errors, noise included):
    // the sample check then expects gravity alone.
    board::sim::ScriptOptions rest;
    rest.script = board::sim::Script::Rest;
    auto suit = sim ? board::sim::buildVirtualSuit(
                          b, *clock, board::sim::scriptedSources(rest, clock->now()).sources)
                    : board::openLinuxSuit(b, *clock);
    if (!suit) {
        fmt::print(stderr, "caphub selftest: {}\n", suit.error().message);
        return kExitRuntime;
    }
    std::vector<SensorStats> stats(b.sensors.size());
    std::vector<hal::BusCounterSnapshot> before;
    for (const auto& bus : suit->buses) {
        before.push_back(bus.counters() != nullptr ? hal::snapshot(*bus.counters())
                                                   : hal::BusCounterSnapshot{});
    }
    // A start-up second, then the measured one.
    const Duration startup = std::chrono::seconds(1);
    const Timestamp t0 = clock->now();
    // The hub's pipeline (stepped on the virtual suit): samples of the first second are not
    // counted.
    const Timestamp measuredFrom = t0 + startup;
    CallbackStage tally([&stats, measuredFrom](const SensorSample& s) {
        if (s.sample.t >= measuredFrom) {
            stats[static_cast<std::size_t>(s.sensor)].add(s.sample);
        }
    });
    (void)captureSamples(b, *clock, *suit, sim ? Capture::Mode::Stepped : Capture::Mode::Threaded,
                         startup + durationFromSeconds(o.seconds), tally);
    const double measuredS = o.seconds;

    fmt::print("{:<11} {:<9} {:<9} {:>8} {:>8} {:>9} {:>9} {:>8}  {}\n", "sensor", "identity",
               "settings", "rate Hz", "want Hz", "|acc|", "gyro dps", "mag uT", "result");
    int failed = 0;
    for (auto& bus : suit->buses) {
        for (auto& sh : bus.sensors) {
            const auto i = static_cast<std::size_t>(sh.sensor);
            const auto& sc = b.sensors[i];
            const SensorStats& st = stats[i];
            std::vector<std::string> problems;
            const int id = sh.driver->probe();
            if (id != 0) {
                problems.push_back(id == -ENODEV ? "another chip answers" : errnoText(id));
            }
            // Read back every configured register once.
            int mismatches = 0;
            const std::size_t n = sh.driver->settings().size();
            bool running = sh.driver->state() == hal::ImuDriver::State::Running;
            for (std::size_t k = 0; running && k < n; ++k) {
                const int r = sh.driver->checkNextSetting(clock->now());
                if (r == 1) {
                    ++mismatches;
                    running = false;
                } else if (r < 0) {
                    problems.push_back("read-back: " + errnoText(r));
                    break;
                }
            }
            if (!running && mismatches == 0 && problems.empty()) {
                problems.push_back("did not start");
            }
            if (mismatches > 0) {
                problems.push_back("a setting did not read back");
            }
            const double rate = static_cast<double>(st.samples) / measuredS;
            const double want = sc.achievedOdrHz;
            // Within 5 %: a missed or doubled sample per 20 is a real fault, jitter is not.
            if (std::abs(rate - want) > 0.05 * want) {
                problems.push_back(fmt::format("rate {:.1f} Hz", rate));
            }
            const double count = static_cast<double>(std::max<std::uint64_t>(st.samples, 1));
            const double accNorm = (st.accSum / count).norm();
            const double gyroDps = (st.gyrSum / count).norm() * 180.0 / hal::kPi;
            const double magUt =
                st.magReadings > 0 ? st.magNormSum / static_cast<double>(st.magReadings) : 0.0;
            if (st.samples > 0 && !st.accChanged) {
                problems.push_back("samples do not change (stuck)");
            }
            if (st.saturated > 0) {
                problems.push_back(fmt::format("{} saturated samples", st.saturated));
            }
            // At rest the accelerometer reads gravity within its offset and scale tolerances
            // (datasheets: tens of mg); 1.5 m/s^2 off means a broken or mis-scaled part.
            if (sim && st.samples > 0 && std::abs(accNorm - hal::kStandardGravity) > 1.5) {
                problems.push_back(fmt::format("|acc| {:.2f} m/s^2 at rest", accNorm));
            }
            if (!problems.empty()) {
                ++failed;
            }
            std::string result = problems.empty() ? "ok" : "FAIL:";
            for (const auto& p : problems) {
                result += " " + p + ";";
            }
            fmt::print("{:<11} {:<9} {:<9} {:>8.1f} {:>8.1f} {:>9.3f} {:>9.3f} {:>8.2f}  {}\n",
                       sc.name, id == 0 ? "ok" : "FAIL", mismatches == 0 && running ? "ok" : "FAIL",
                       rate, want, accNorm, gyroDps, magUt, result);
        }
    }
    fmt::print("\n");
    const auto loads = board::computeBusLoads(b);
    for (std::size_t k = 0; k < suit->buses.size(); ++k) {
        const auto& bus = suit->buses[k];
        const auto& bc = b.buses[static_cast<std::size_t>(bus.bus)];
        hal::BusCounterSnapshot after =
            bus.counters() != nullptr ? hal::snapshot(*bus.counters()) : hal::BusCounterSnapshot{};
        const double seconds = toSeconds(clock->now() - t0);
        fmt::print(
            "bus {:<10} {:>7.0f} transactions/s {:>8.0f} bytes/s, {} errors; planned load {:.1f}% "
            "(budget {:.0f}%)\n",
            bc.name, static_cast<double>(after.transactions - before[k].transactions) / seconds,
            static_cast<double>(after.bytes - before[k].bytes) / seconds,
            after.errors - before[k].errors,
            loads[static_cast<std::size_t>(bus.bus)].utilisation * 100.0,
            board::kMaxBusUtilisation * 100.0);
    }
    fmt::print("\n{} of {} sensors passed\n", b.sensors.size() - static_cast<std::size_t>(failed),
               b.sensors.size());
    return failed == 0 ? kExitOk : kExitRuntime;
}

}  // namespace

void addSelftestCommand(CLI::App& app, int& exitCode) {
    auto o = std::make_shared<SelftestOptions>();
    CLI::App* cmd = app.add_subcommand(
        "selftest", "Probe every sensor of a board: identity, configuration read-back, samples");
    cmd->add_option("-b,--board", o->board, "Board file, or the name of a shipped board")
        ->check(nonEmptyPath())
        ->capture_default_str();
    cmd->add_option("--seconds", o->seconds, "Seconds of samples to check")
        ->check(finiteRange(0.0, 3600.0))
        ->capture_default_str();
    cmd->callback([&exitCode, o] { exitCode = selftest(*o); });
}

}  // namespace caphub::firmware
