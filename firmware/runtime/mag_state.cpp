#include "firmware/runtime/mag_state.h"

#include <cerrno>
#include <sstream>

#include <fmt/format.h>
#include <sys/stat.h>
#include <unistd.h>

#include "hal/core/input_file.h"
#include "hal/core/log.h"
#include "hal/core/output_fd.h"

namespace caphub::firmware {

namespace fs = std::filesystem;

namespace {

// A state file is small (17 lines of 74 numbers, about 30 kB); anything far larger is not one.
constexpr std::size_t kMaxFileBytes = 4u << 20;

// Its first line.
constexpr std::string_view kHeaderStart = "# caphub online hard- and soft-iron estimators";
constexpr std::string_view kHeader =
    "# caphub online hard- and soft-iron estimators (docs/fusion.md): sensor, anchor (3), "
    "moments (55), alignment moments (15), samples\n";

}  // namespace

Result<void> loadMagState(const fs::path& path, const board::Board& b, FusionStage& fusion) {
    std::error_code ec;
    if (!fs::exists(fs::symlink_status(path, ec))) {
        return {};  // the first run: nothing to start from
    }
    auto text = readInputFile(path, kMaxFileBytes);
    if (!text) {
        return text.error();
    }
    std::istringstream in(*text);
    std::string line;
    int lineNo = 0;
    // Every line is checked before any is applied: a damaged file loads nothing.
    std::vector<std::pair<int, fusion::OnlineHardIronState>> parsed;
    while (std::getline(in, line)) {
        ++lineNo;
        const auto first = line.find_first_not_of(" \t\r");
        if (first == std::string::npos || line[first] == '#') {
            continue;
        }
        const auto nameEnd = line.find_first_of(" \t", first);
        const std::string name = line.substr(first, nameEnd - first);
        const auto state = nameEnd == std::string::npos
                               ? std::nullopt
                               : fusion::parseHardIronState(line.substr(nameEnd));
        if (!state) {
            return Error{EINVAL, fmt::format("{}:{}: expected a sensor name and {} finite numbers "
                                             "(anchor, moments, samples; a state written "
                                             "before 2026-11-26 has 19 and must be learnt again)",
                                             path.string(), lineNo, fusion::kHardIronStateNumbers)};
        }
        int sensor = -1;
        for (std::size_t i = 0; i < b.sensors.size(); ++i) {
            if (b.sensors[i].name == name) {
                sensor = static_cast<int>(i);
            }
        }
        if (sensor < 0) {
            return Error{EINVAL, fmt::format("{}:{}: unknown sensor '{}' (board '{}')",
                                             path.string(), lineNo, name, b.name)};
        }
        for (const auto& given : parsed) {
            if (given.first == sensor) {
                return Error{EINVAL, fmt::format("{}:{}: sensor '{}' is given twice", path.string(),
                                                 lineNo, name)};
            }
        }
        parsed.emplace_back(sensor, *state);
    }
    for (const auto& [sensor, state] : parsed) {
        fusion.setMagEstimatorState(sensor, state);
    }
    return {};
}

Result<void> checkMagStateFile(const fs::path& path) {
    std::error_code ec;
    if (!fs::exists(fs::symlink_status(path, ec))) {
        return {};
    }
    auto text = readInputFile(path, kMaxFileBytes);
    if (!text) {
        return text.error();
    }
    if (!text->empty() && !text->starts_with(kHeaderStart)) {
        return Error{EINVAL, fmt::format("'{}' is not a magnetometer state file (its first line is "
                                         "not \"{}\"): it is not replaced",
                                         path.string(), kHeaderStart)};
    }
    return {};
}

MagStates magStates(const board::Board& b, const FusionStage& fusion) {
    MagStates out;
    out.reserve(b.sensors.size());
    for (std::size_t i = 0; i < b.sensors.size(); ++i) {
        out.push_back(fusion.magEstimatorState(static_cast<int>(i)));
    }
    return out;
}

std::string magStateText(const board::Board& b, const MagStates& states) {
    std::string text(kHeader);
    for (std::size_t i = 0; i < states.size() && i < b.sensors.size(); ++i) {
        if (states[i]) {
            text += b.sensors[i].name + " " + fusion::formatHardIronState(*states[i]) + "\n";
        }
    }
    return text;
}

Result<void> writeMagStateFile(const fs::path& path, const std::string& text) {
    struct stat st {};
    if (::lstat(path.c_str(), &st) == 0 && !S_ISREG(st.st_mode)) {
        return Error{EEXIST, fmt::format("'{}' is not a regular file: the magnetometer estimates "
                                         "are written to regular files only",
                                         path.string())};
    }
    // Per process: two hubs sharing a path never write into each other's file.
    const fs::path tmp = fs::path(path.string() + "." + std::to_string(::getpid()) + ".tmp");
    return replaceFileWhole(path, tmp, text, true);
}

MagStateStage::MagStateStage(const board::Board& board, const FusionStage& fusion, fs::path path,
                             Duration every)
    : board_(board),
      fusion_(fusion),
      path_(std::move(path)),
      every_(every),
      writer_("caphub-magstate", [this](const MagStates& states) { write(states); }) {}

MagStateStage::~MagStateStage() = default;

void MagStateStage::onTick(Timestamp now) {
    if (!last_) {
        last_ = now;
        return;
    }
    if (now - *last_ >= every_) {
        last_ = now;
        writer_.publish(magStates(board_, fusion_));
    }
}

void MagStateStage::finish(Timestamp now) {
    last_ = now;
    writer_.publish(magStates(board_, fusion_));
    writer_.flush();
}

void MagStateStage::write(const MagStates& states) {
    const auto r = writeMagStateFile(path_, magStateText(board_, states));
    std::lock_guard lock(resultMutex_);
    if (!r && error_.empty()) {
        // Said once; a later success clears it.
        log::logger(log::Category::Firmware)
            .warn("magnetometer estimates not saved: {}", r.error().message);
    }
    error_ = r ? std::string() : r.error().message;
    written_ += r ? 1 : 0;
}

std::uint64_t MagStateStage::written() const {
    std::lock_guard lock(resultMutex_);
    return written_;
}

std::string MagStateStage::error() const {
    std::lock_guard lock(resultMutex_);
    return error_;
}

}  // namespace caphub::firmware
