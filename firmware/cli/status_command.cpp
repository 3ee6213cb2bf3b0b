// caphub status: the running hub's live state as JSON (per-sensor rate, errors, lost samples,
// bus load, latency percentiles, recording), as `caphub run` keeps it in its status file.
#include <chrono>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <fmt/format.h>

#include "firmware/cli/app.h"
#include "firmware/cli/commands.h"
#include "firmware/runtime/status_stage.h"

namespace caphub::firmware {

namespace {

namespace fs = std::filesystem;

int status(const std::string& file) {
    const fs::path path = file.empty() ? defaultStatusPath() : fs::path(file);
    std::ifstream in(path);
    if (!in) {
        fmt::print(stderr, "caphub status: no hub has run here (no status at {})\n", path.string());
        return kExitRuntime;
    }
    std::stringstream text;
    text << in.rdbuf();
    fmt::print("{}", text.str());
    // The hub rewrites the file every second while it runs: an older one is a hub that stopped
    // without finishing (killed), or the last state of one that finished ("running": false).
    std::error_code ec;
    const auto age = fs::file_time_type::clock::now() - fs::last_write_time(path, ec);
    const bool running = text.str().find("\"running\": true") != std::string::npos;
    if (!ec && running && age > std::chrono::seconds(5)) {
        fmt::print(stderr, "caphub status: {} is {} s old: the hub is not running any more\n",
                   path.string(), std::chrono::duration_cast<std::chrono::seconds>(age).count());
        return kExitRuntime;
    }
    return kExitOk;
}

}  // namespace

void addStatusCommand(CLI::App& app, int& exitCode) {
    auto file = std::make_shared<std::string>();
    CLI::App* cmd = app.add_subcommand(
        "status", "The running hub's state as JSON: per-sensor rates, errors, latency, recording");
    cmd->add_option("--file", *file, "The status file (default: where caphub run keeps it)");
    cmd->callback([&exitCode, file] { exitCode = status(*file); });
}

}  // namespace caphub::firmware
