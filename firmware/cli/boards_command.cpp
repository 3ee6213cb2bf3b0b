// caphub boards: validate a board file and describe its plan, or list the shipped boards.
#include <algorithm>
#include <filesystem>

#include <fmt/format.h>

#include "board/loader.h"
#include "firmware/cli/app.h"
#include "firmware/cli/commands.h"
#include "firmware/cli/data_dir.h"
#include "firmware/cli/number_checks.h"
#include "fusion/body/pose_solver.h"

namespace caphub::firmware {

namespace {

namespace fs = std::filesystem;
using board::Board;
using board::BusLoad;

std::string busKind(const board::BusConfig& bus) {
    switch (bus.type) {
        case board::BusType::I2c:
            return fmt::format("i2c {}", bus.device);
        case board::BusType::Spi:
            return fmt::format("spi {}", bus.device);
        case board::BusType::Sim:
            return fmt::format("sim, models {}", hal::toString(bus.protocol));
    }
    return {};
}

std::string clockText(double hz) {
    return hz >= 1e6 ? fmt::format("{:g} MHz", hz / 1e6) : fmt::format("{:g} kHz", hz / 1e3);
}

std::string placeText(const Board& b, const board::SensorConfig& s) {
    if (s.chipSelect >= 0) {
        return s.magChipSelect >= 0 ? fmt::format("cs{}+cs{}", s.chipSelect, s.magChipSelect)
                                    : fmt::format("cs{}", s.chipSelect);
    }
    std::string where =
        s.mux >= 0
            ? fmt::format("{} ch{} ", b.muxes[static_cast<std::size_t>(s.mux)].name, s.channel)
            : std::string();
    where += fmt::format("0x{:02x}", s.address);
    if (s.magAddress) {
        where += fmt::format("+0x{:02x}", *s.magAddress);
    }
    return where;
}

// The body layout (docs/sparse.md): declared or as the sensors make it, and what it leaves
// unmeasured.
std::string bodyText(const Board& b) {
    std::vector<board::Segment> segments;
    body::SegmentMask sensors = 0;
    for (const auto& s : b.sensors) {
        segments.push_back(s.segment);
        sensors |= body::bit(s.segment);
    }
    const auto matched = board::matchLayout(segments);
    std::string out = b.body.layout
                          ? fmt::format("  body: layout {}", board::toString(*b.body.layout))
                      : matched ? fmt::format("  body: no [body] layout (the sensors make {})",
                                              board::toString(*matched))
                                : std::string("  body: no [body] layout, no sensor on the pelvis");
    const body::SegmentMask covered = body::PoseSolver(sensors).coveredSegments();
    std::string held;
    for (int i = 0; i < body::kSegmentCount; ++i) {
        if (!body::has(covered, i)) {
            held += fmt::format("{}{}", held.empty() ? "" : " ",
                                board::segmentName(static_cast<board::Segment>(i)));
        }
    }
    out += held.empty()
               ? "; every segment measured\n"
               : fmt::format("; not measured (held in the neutral standing pose): {}\n", held);
    if (!body::has(covered, body::idx(board::Segment::LHindfoot)) ||
        !body::has(covered, body::idx(board::Segment::RHindfoot))) {
        out += "  root translation: not measured (it needs a sensor on each foot)\n";
    }
    return out;
}

void describe(const Board& b, const std::vector<BusLoad>& loads) {
    fmt::print("board {} ({})\n", b.name, b.path.string());
    if (!b.description.empty()) {
        fmt::print("  {}\n", b.description);
    }
    fmt::print("  subject {:g} m{}\n", b.subject.heightM,
               b.subject.massKg ? fmt::format(", {:g} kg", *b.subject.massKg) : "");
    if (b.runtime.realtimePriority > 0 || !b.runtime.cpus.empty()) {
        fmt::print(
            "  capture threads: {}{}\n",
            b.runtime.realtimePriority > 0
                ? fmt::format("SCHED_FIFO {}", b.runtime.realtimePriority)
                : std::string("normal scheduling"),
            b.runtime.cpus.empty() ? "" : fmt::format(", CPUs {}", fmt::join(b.runtime.cpus, ",")));
    }
    fmt::print("{}", bodyText(b));
    fmt::print("{} sensors on {} buses, {} muxes\n", b.sensors.size(), b.buses.size(),
               b.muxes.size());
    for (const BusLoad& load : loads) {
        const auto& bus = b.buses[static_cast<std::size_t>(load.bus)];
        fmt::print("\nbus {} ({}, {}): {} sensors, utilisation {:.1f}% of {:.0f}% budget\n",
                   bus.name, busKind(bus), clockText(bus.clockHz), load.sensors.size(),
                   load.utilisation * 100, board::kMaxBusUtilisation * 100);
        fmt::print("  {:.0f} transactions/s, {:.0f} bytes/s{}\n", load.transactionsPerS,
                   load.bytesPerS,
                   load.muxSelectsPerS > 0
                       ? fmt::format(", {:.0f} mux channel selects/s", load.muxSelectsPerS)
                       : "");
        if (load.sensors.empty()) {
            continue;
        }
        fmt::print("  {:<12} {:<12} {:<18} {:<20} {:<14} {:>8} {:>7} {:>6}\n", "sensor", "segment",
                   "chip", "address", "data-ready", "odr Hz", "mag Hz", "load");
        for (const auto& sl : load.sensors) {
            const auto& s = b.sensors[static_cast<std::size_t>(sl.sensor)];
            fmt::print("  {:<12} {:<12} {:<18} {:<20} {:<14} {:>8.4g} {:>7.4g} {:>5.1f}%\n", s.name,
                       board::segmentName(s.segment), s.chip->name, placeText(b, s),
                       s.dataReady ? s.dataReady->text() : "poll (timer)", s.achievedOdrHz,
                       s.magOdrHz, sl.utilisation * 100);
        }
    }
}

int validate(const std::string& given, bool quiet) {
    const fs::path path = resolveBoardFile(given);
    const board::LoadResult r = board::loadBoardFile(path);
    for (const auto& w : r.warnings) {
        fmt::print(stderr, "{}: warning: {}\n", w.where.file, w.str());
    }
    if (!r.ok()) {
        for (const auto& e : r.errors) {
            fmt::print(stderr, "{}\n", e.str());
        }
        fmt::print(stderr, "{}: {} error{}; the board file is not valid\n", path.string(),
                   r.errors.size(), r.errors.size() == 1 ? "" : "s");
        return kExitUsage;
    }
    if (const std::string problem = recordingProblem(*r.board); !problem.empty()) {
        fmt::print(stderr, "{}: {}\n", path.string(), problem);
        fmt::print(stderr, "{}: 1 error; the board file is not valid\n", path.string());
        return kExitUsage;
    }
    if (!quiet) {
        describe(*r.board, r.loads);
    }
    double busiest = 0;
    for (const auto& l : r.loads) {
        busiest = std::max(busiest, l.utilisation);
    }
    fmt::print("\n{}: valid: {} sensors, busiest bus at {:.1f}% (budget {:.0f}%)\n", path.string(),
               r.board->sensors.size(), busiest * 100, board::kMaxBusUtilisation * 100);
    return kExitOk;
}

int list() {
    const auto dir = dataDir();
    if (!dir) {
        fmt::print(stderr, "caphub: no data folder with board files found; set CAPHUB_DATA_DIR\n");
        return kExitRuntime;
    }
    std::vector<fs::path> files;
    for (const auto& e : fs::directory_iterator(*dir / "board")) {
        if (e.path().extension() == ".toml") {
            files.push_back(e.path());
        }
    }
    std::sort(files.begin(), files.end());
    for (const auto& f : files) {
        const auto r = board::loadBoardFile(f);
        if (r.ok()) {
            fmt::print("{:<16} {:>3} sensors  {}\n", f.stem().string(), r.board->sensors.size(),
                       r.board->description);
        } else {
            fmt::print("{:<16} (invalid: {} errors)\n", f.stem().string(), r.errors.size());
        }
    }
    return kExitOk;
}

}  // namespace

void addBoardsCommand(CLI::App& app, int& exitCode) {
    CLI::App* boards = app.add_subcommand("boards", "Board (suit) files: validate and list");
    boards->require_subcommand(1);

    CLI::App* validateCmd = boards->add_subcommand(
        "validate", "Check a board file and print its sensors per bus and each bus's utilisation");
    auto file = std::make_shared<std::string>();
    auto quiet = std::make_shared<bool>(false);
    validateCmd->add_option("FILE", *file, "A board file, or the name of a shipped board")
        ->check(nonEmptyPath())
        ->required();
    validateCmd->add_flag("-q,--quiet", *quiet, "Only report errors and the verdict");
    validateCmd->callback([&exitCode, file, quiet] { exitCode = validate(*file, *quiet); });

    boards->add_subcommand("list", "List the shipped board files")->callback([&exitCode] {
        exitCode = list();
    });
}

}  // namespace caphub::firmware
