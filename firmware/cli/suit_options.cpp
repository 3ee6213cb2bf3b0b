#include "firmware/cli/suit_options.h"

#include <fmt/format.h>

#include "firmware/cli/number_checks.h"

namespace caphub::firmware {

void addSuitOptions(CLI::App& cmd, SuitCliOptions& o) {
    cmd.add_option("--map", o.map, "Joint-name map (TOML); default: detect a built-in preset")
        ->check(nonEmptyPath());
    cmd.add_option("-b,--board", o.board, "A board whose buses are all simulated")
        ->check(nonEmptyPath())
        ->capture_default_str();
    cmd.add_option("--profile", o.profile, "Sensor errors: ideal, typical, harsh")
        ->capture_default_str();
    cmd.add_option("--seed", o.seed, "Seed of the sensor errors and straps")
        ->check(seedNumber())
        ->capture_default_str();
    cmd.add_option("--strap-deg", o.strapDeg,
                   "Scale of each sensor's strapping error off its nominal mounting (deg)")
        ->check(finiteNonNegative())
        ->capture_default_str();
    cmd.add_option("--chip-delay-ms", o.chipDelayMs,
                   "Delay every virtual sensor's signals by this (ms): a chip's digital low-pass, "
                   "which the virtual chips do not model (docs/virtual-suit.md)")
        ->check(finiteRange(0.0, 100.0))
        ->capture_default_str();
}

std::optional<board::sim::ErrorProfile> suitProfile(const SuitCliOptions& o,
                                                    std::string_view command) {
    auto profile = board::sim::parseErrorProfile(o.profile);
    if (!profile) {
        fmt::print(stderr, "{}: --profile: expected ideal, typical or harsh, got '{}'\n", command,
                   o.profile);
    }
    return profile;
}

}  // namespace caphub::firmware
