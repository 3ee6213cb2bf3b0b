#include "hal/core/log.h"

#include <array>
#include <memory>
#include <optional>
#include <string>

#include <spdlog/sinks/stdout_color_sinks.h>

namespace caphub::log {

namespace {

constexpr std::array<std::string_view, kCategoryCount> kNames = {
    "core", "hal", "sim", "board", "fusion", "body", "render", "firmware", "cli"};

struct Registry {
    Registry() {
        auto sink = std::make_shared<spdlog::sinks::stderr_color_sink_mt>();
        for (int i = 0; i < kCategoryCount; ++i) {
            loggers[static_cast<std::size_t>(i)] = std::make_shared<spdlog::logger>(
                std::string(kNames[static_cast<std::size_t>(i)]), sink);
            loggers[static_cast<std::size_t>(i)]->set_pattern("%^[%L %n]%$ %v");
            loggers[static_cast<std::size_t>(i)]->set_level(spdlog::level::info);
        }
    }
    std::array<std::shared_ptr<spdlog::logger>, kCategoryCount> loggers;
};

Registry& registry() {
    static Registry r;
    return r;
}

std::optional<spdlog::level::level_enum> parseLevel(std::string_view s) {
    static constexpr std::array<std::pair<std::string_view, spdlog::level::level_enum>, 7> kLevels =
        {{{"trace", spdlog::level::trace},
          {"debug", spdlog::level::debug},
          {"info", spdlog::level::info},
          {"warn", spdlog::level::warn},
          {"error", spdlog::level::err},
          {"critical", spdlog::level::critical},
          {"off", spdlog::level::off}}};
    for (const auto& [text, level] : kLevels) {
        if (s == text) {
            return level;
        }
    }
    return std::nullopt;
}

std::optional<int> parseCategory(std::string_view s) {
    for (int i = 0; i < kCategoryCount; ++i) {
        if (kNames[static_cast<std::size_t>(i)] == s) {
            return i;
        }
    }
    return std::nullopt;
}

std::string_view trim(std::string_view s) {
    while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) {
        s.remove_prefix(1);
    }
    while (!s.empty() && (s.back() == ' ' || s.back() == '\t')) {
        s.remove_suffix(1);
    }
    return s;
}

}  // namespace

std::string_view name(Category c) {
    return kNames[static_cast<std::size_t>(c)];
}

spdlog::logger& logger(Category c) {
    return *registry().loggers[static_cast<std::size_t>(c)];
}

Result<void> configure(std::string_view spec) {
    std::array<std::optional<spdlog::level::level_enum>, kCategoryCount> levels{};
    std::optional<spdlog::level::level_enum> all;
    while (!spec.empty()) {
        const auto comma = spec.find(',');
        const std::string_view item = trim(spec.substr(0, comma));
        spec = comma == std::string_view::npos ? std::string_view{} : spec.substr(comma + 1);
        if (item.empty()) {
            continue;
        }
        const auto eq = item.find('=');
        const std::string_view levelText =
            eq == std::string_view::npos ? item : item.substr(eq + 1);
        const auto level = parseLevel(trim(levelText));
        if (!level) {
            return Error{EINVAL,
                         "unknown log level '" + std::string(trim(levelText)) +
                             "' (expected trace, debug, info, warn, error, critical or off)"};
        }
        if (eq == std::string_view::npos) {
            all = level;
            continue;
        }
        const std::string_view categoryText = trim(item.substr(0, eq));
        const auto category = parseCategory(categoryText);
        if (!category) {
            std::string known;
            for (auto n : kNames) {
                known += known.empty() ? "" : ", ";
                known += n;
            }
            return Error{EINVAL, "unknown log category '" + std::string(categoryText) +
                                     "' (expected one of " + known + ")"};
        }
        levels[static_cast<std::size_t>(*category)] = level;
    }
    for (int i = 0; i < kCategoryCount; ++i) {
        auto& l = *registry().loggers[static_cast<std::size_t>(i)];
        if (levels[static_cast<std::size_t>(i)]) {
            l.set_level(*levels[static_cast<std::size_t>(i)]);
        } else if (all) {
            l.set_level(*all);
        }
    }
    return {};
}

}  // namespace caphub::log
