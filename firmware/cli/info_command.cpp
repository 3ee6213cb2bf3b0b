// caphub version and caphub info: what this build is and what it supports.
#include <fmt/format.h>

#include "board/segment.h"
#include "firmware/cli/app.h"
#include "firmware/cli/commands.h"
#include "firmware/cli/data_dir.h"
#include "firmware/cli/info.h"
#include "firmware/version.h"
#include "hal/chip_info.h"

namespace caphub::firmware {

std::string versionLine() {
    return fmt::format("caphub {} ({}, {})", kVersion, kGitRevision, kBuildType);
}

namespace {

std::string joinNumbers(std::span<const double> v, const char* unit) {
    std::string out;
    for (double x : v) {
        out += fmt::format("{}{:g}", out.empty() ? "" : ", ", x);
    }
    return out + " " + unit;
}

void printInfo() {
    fmt::print("{}\n", versionLine());
    const auto dir = dataDir();
    fmt::print("data folder: {}\n\n", dir ? dir->string() : "(none found; set CAPHUB_DATA_DIR)");
    fmt::print("chips:\n");
    for (const auto& c : hal::chipCatalog()) {
        fmt::print("  {:<18} {}\n", c.name, c.description);
        fmt::print("  {:<18} rates {}; accel {}; gyro {}; magnetometer {}\n", "", c.odrRule,
                   joinNumbers(c.accelRangesG, "g"), joinNumbers(c.gyroRangesDps, "dps"),
                   joinNumbers(c.magOdrsHz, "Hz"));
    }
    fmt::print("\nsegments ({}):\n", board::kSegmentCount);
    for (const auto& s : board::kSegments) {
        fmt::print("  {:<12} {}\n", s.name, s.description);
    }
}

}  // namespace

void addInfoCommands(CLI::App& app, int& exitCode) {
    app.add_subcommand("version", "Print the version of caphub")->callback([&exitCode] {
        fmt::print("{}\n", versionLine());
        exitCode = kExitOk;
    });
    app.add_subcommand("info", "Print this build's chips, body segments and data folder")
        ->callback([&exitCode] {
            printInfo();
            exitCode = kExitOk;
        });
}

}  // namespace caphub::firmware
