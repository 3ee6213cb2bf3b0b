// caphub status: the running hub's live state as JSON (per-sensor rate, errors, lost samples,
// bus load, latency percentiles, recording), as `caphub run` keeps it in its status file.
#include <chrono>
#include <filesystem>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "firmware/cli/app.h"
#include "firmware/cli/commands.h"
#include "firmware/cli/number_checks.h"
#include "firmware/runtime/status_stage.h"
#include "hal/core/input_file.h"

namespace caphub::firmware {

namespace {

namespace fs = std::filesystem;

// Why `text` is not a status document as `caphub run` writes it, or empty when it is one.
std::string statusProblem(const std::string& text) {
    nlohmann::json doc;
    try {
        doc = nlohmann::json::parse(text);
    } catch (const nlohmann::json::parse_error& e) {
        return fmt::format("not JSON: {}", e.what());
    }
    if (!doc.is_object()) {
        return "expected a JSON object";
    }
    for (const char* key : {"board", "running", "sensors", "buses"}) {
        if (!doc.contains(key)) {
            return fmt::format("no \"{}\"", key);
        }
    }
    if (!doc["board"].is_string() || !doc["running"].is_boolean() || !doc["sensors"].is_array() ||
        !doc["buses"].is_array()) {
        return "expected \"board\" a string, \"running\" true or false, \"sensors\" and \"buses\" "
               "arrays";
    }
    return {};
}

int status(const std::string& file) {
    const bool named = !file.empty();
    const fs::path path = named ? fs::path(file) : defaultStatusPath();
    if (!named) {
        // Not there: no hub has run where the hub keeps its status (an answer, not an error in
        // what was given).
        std::error_code ec;
        if (!fs::exists(path, ec)) {
            fmt::print(stderr, "caphub status: no hub has run here (no status at {})\n",
                       path.string());
            return kExitRuntime;
        }
    }
    // A status file is a few kilobytes; anything much larger is not one.
    constexpr std::size_t kMaxStatusBytes = 16u << 20;
    auto text = readInputFile(path, kMaxStatusBytes);
    if (!text) {
        fmt::print(stderr, "caphub status: {}\n", text.error().message);
        return kExitUsage;
    }
    if (const std::string problem = statusProblem(*text); !problem.empty()) {
        fmt::print(stderr, "caphub status: '{}' is not a caphub status document ({})\n",
                   path.string(), problem);
        return kExitUsage;
    }
    fmt::print("{}", *text);
    // The hub rewrites the file every second while it runs: an older one is a hub that stopped
    // without finishing (killed), or the last state of one that finished ("running": false).
    std::error_code ec;
    const auto age = fs::file_time_type::clock::now() - fs::last_write_time(path, ec);
    const bool running = nlohmann::json::parse(*text)["running"].get<bool>();
    if (!ec && running && age > std::chrono::seconds(5)) {
        fmt::print(stderr, "caphub status: {} is {} s old: the hub is not running any more\n",
                   path.string(), std::chrono::duration_cast<std::chrono::seconds>(age).count());
        return kExitRuntime;
    }
    // Written "later than now" (a clock set back, or a file touched): not a live hub's.
    if (!ec && running && age < -std::chrono::seconds(5)) {
        fmt::print(stderr,
                   "caphub status: {} is dated {} s in the future: not written by a running hub "
                   "(or the clock was set back)\n",
                   path.string(), std::chrono::duration_cast<std::chrono::seconds>(-age).count());
        return kExitRuntime;
    }
    return kExitOk;
}

}  // namespace

void addStatusCommand(CLI::App& app, int& exitCode) {
    auto file = std::make_shared<std::string>();
    CLI::App* cmd = app.add_subcommand(
        "status", "The running hub's state as JSON: per-sensor rates, errors, latency, recording");
    cmd->add_option("--file", *file, "The status file (default: where caphub run keeps it)")
        ->check(nonEmptyPath());
    cmd->callback([&exitCode, file] { exitCode = status(*file); });
}

}  // namespace caphub::firmware
