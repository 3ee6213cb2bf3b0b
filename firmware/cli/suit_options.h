// The options of the commands that play a clip on a virtual suit (sim, evaluate): the board, the
// joint map, the sensor error profile, the seed, the strapping error and the chips' output delay.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

#include <CLI/CLI.hpp>

#include "board/sim/imu_model.h"

namespace caphub::firmware {

struct SuitCliOptions {
    std::string map;
    std::string board = "sim-suit";
    std::string profile = "typical";
    std::uint64_t seed = 1;
    double strapDeg = 10;
    double chipDelayMs = 0;
};

void addSuitOptions(CLI::App& cmd, SuitCliOptions& o);

// The error profile named by --profile; an unknown name is reported on stderr as the command's.
std::optional<board::sim::ErrorProfile> suitProfile(const SuitCliOptions& o,
                                                    std::string_view command);

}  // namespace caphub::firmware
