#include "firmware/cli/data_dir.h"

#include <cstdlib>

#include <fmt/format.h>

#include "board/loader.h"
#include "firmware/cli/info.h"
#include "firmware/recording/format.h"
#include "firmware/runtime/recorder_stage.h"
#include "firmware/version.h"

namespace caphub::firmware {

namespace fs = std::filesystem;

std::vector<fs::path> dataDirCandidates() {
    std::vector<fs::path> out;
    if (const char* env = std::getenv("CAPHUB_DATA_DIR"); env != nullptr && *env != '\0') {
        out.emplace_back(env);
    }
    out.emplace_back(kInstallDataDir);
    out.emplace_back(kSourceDir);
    return out;
}

std::optional<fs::path> dataDir() {
    for (const auto& d : dataDirCandidates()) {
        std::error_code ec;
        if (fs::is_directory(d / "board", ec)) {
            return d;
        }
    }
    return std::nullopt;
}

fs::path resolveBoardFile(const std::string& nameOrPath) {
    const fs::path given(nameOrPath);
    std::error_code ec;
    if (fs::exists(given, ec) || given.has_parent_path() || given.extension() == ".toml") {
        return given;
    }
    if (auto d = dataDir()) {
        const fs::path shipped = *d / "board" / (nameOrPath + ".toml");
        if (fs::exists(shipped, ec)) {
            return shipped;
        }
    }
    return given;
}

fs::path defaultMotionClip() {
    if (auto d = dataDir()) {
        const fs::path clip = *d / "tests" / "data" / "bvh" / "cmu_12_01_walk.bvh";
        std::error_code ec;
        if (fs::exists(clip, ec)) {
            return clip;
        }
    }
    return {};
}

std::string recordingProblem(const board::Board& b, const std::string& calibrationPath,
                             const std::string& calibrationText) {
    const std::string metadata =
        recordingMetadata(b, b.text, versionLine(), calibrationPath, calibrationText);
    if (metadata.size() <= cap::kMaxPayloadBytes) {
        return {};
    }
    const std::size_t boardEscaped = tomlString(b.text).size();
    std::string cause = fmt::format(
        "the board file is {} bytes ({} once escaped); a recording embeds the board file in its "
        "metadata, which holds at most {} bytes (1 MiB)",
        b.text.size(), boardEscaped, cap::kMaxPayloadBytes);
    if (!calibrationText.empty()) {
        cause += fmt::format(" together with the calibration file '{}' ({} bytes once escaped)",
                             calibrationPath, tomlString(calibrationText).size());
    }
    return fmt::format("{}; the metadata would be {} bytes: make the board file smaller", cause,
                       metadata.size());
}

std::optional<board::Board> loadCommandBoard(const std::string& nameOrPath) {
    const auto loaded = board::loadBoardFile(resolveBoardFile(nameOrPath));
    if (!loaded.ok()) {
        for (const auto& e : loaded.errors) {
            fmt::print(stderr, "{}\n", e.str());
        }
        return std::nullopt;
    }
    if (const std::string problem = recordingProblem(*loaded.board); !problem.empty()) {
        fmt::print(stderr, "{}: {}\n", loaded.board->path.string(), problem);
        return std::nullopt;
    }
    return *loaded.board;
}

std::optional<board::Board> loadVirtualSuitBoard(const std::string& nameOrPath,
                                                 std::string_view command, std::string_view needs) {
    auto b = loadCommandBoard(nameOrPath);
    if (b && !board::allBusesSimulated(*b)) {
        fmt::print(stderr,
                   "{}: '{}' has real buses; {} needs a board whose buses are all 'sim' (e.g. "
                   "sim-suit, sim-upper10)\n",
                   command, b->path.string(), needs);
        return std::nullopt;
    }
    return b;
}

}  // namespace caphub::firmware
