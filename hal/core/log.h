// Logging: one spdlog logger per module, all writing to stderr through one sink.
// Not for the per-sample hot path: count events there and log the counters.
#pragma once

#include <string_view>

#include <spdlog/logger.h>

#include "hal/core/error.h"

namespace caphub::log {

enum class Category { Core, Hal, Sim, Board, Fusion, Body, Render, Firmware, Cli };
inline constexpr int kCategoryCount = 9;

std::string_view name(Category c);

// The logger of a module, e.g. logger(Category::Hal).warn("bus {}: {}", path, errnoText(err)).
spdlog::logger& logger(Category c);

// Applies a level spec: a default level and per-module overrides, comma separated, e.g.
// "info", "warn,hal=debug", "fusion=trace". Levels: trace debug info warn error critical off.
// On a bad spec nothing changes and the error names the offending item.
Result<void> configure(std::string_view spec);

}  // namespace caphub::log
