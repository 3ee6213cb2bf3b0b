#include "firmware/cli/data_dir.h"

#include <cstdlib>

#include <fmt/format.h>

#include "board/loader.h"
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

std::optional<board::Board> loadCommandBoard(const std::string& nameOrPath) {
    const auto loaded = board::loadBoardFile(resolveBoardFile(nameOrPath));
    if (!loaded.ok()) {
        for (const auto& e : loaded.errors) {
            fmt::print(stderr, "{}\n", e.str());
        }
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
