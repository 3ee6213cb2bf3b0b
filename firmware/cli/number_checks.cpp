#include "firmware/cli/number_checks.h"

#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <limits>
#include <string>

#include <fmt/format.h>

namespace caphub::firmware {

namespace {

// The value parsed the way the option will be (strtod accepts nan and inf), or the reason not.
CLI::Validator finiteCheck(const std::string& description, double min, bool minOpen, double max) {
    return CLI::Validator(
        [min, minOpen, max](std::string& input) -> std::string {
            char* end = nullptr;
            const double v = std::strtod(input.c_str(), &end);
            if (input.empty() || end == input.c_str() || *end != '\0') {
                return fmt::format("Value {} is not a number", input);
            }
            if (!std::isfinite(v)) {
                return fmt::format("Value {} is not a finite number", input);
            }
            if (v < min || (minOpen && v == min) || v > max) {
                if (max == std::numeric_limits<double>::max()) {
                    return fmt::format("Value {} must be {} {}", input,
                                       minOpen ? "above" : "at least", min);
                }
                return fmt::format("Value {} not in range {} to {}", input, min, max);
            }
            return std::string();
        },
        description);
}

}  // namespace

CLI::Validator finiteRange(double min, double max) {
    return finiteCheck(fmt::format("FINITE in [{} - {}]", min, max), min, false, max);
}

CLI::Validator zeroOrRange(double min, double max) {
    const CLI::Validator range = finiteRange(min, max);
    return CLI::Validator(
        [range, min, max](std::string& input) -> std::string {
            std::string copy = input;
            const std::string why = range(copy);
            char* end = nullptr;
            const double v = std::strtod(input.c_str(), &end);
            const bool finite = !input.empty() && *end == '\0' && std::isfinite(v);
            if (why.empty() || (finite && v == 0.0)) {
                return {};
            }
            // Not a number, or not a finite one: said as every other option says it.
            return finite ? fmt::format("Value {} must be 0 or from {} to {}", input, min, max)
                          : why;
        },
        fmt::format("0 or FINITE in [{} - {}]", min, max));
}

CLI::Validator finitePositive() {
    return finiteCheck("POSITIVE", 0.0, true, std::numeric_limits<double>::max());
}

CLI::Validator seedNumber() {
    return CLI::Validator(
        [](std::string& input) -> std::string {
            std::uint64_t v = 0;
            const char* end = input.data() + input.size();
            const auto [at, ec] = std::from_chars(input.data(), end, v);
            if (input.empty() || ec != std::errc{} || at != end) {
                return fmt::format("Value '{}' is not a seed (a whole number, 0 to {})", input,
                                   std::numeric_limits<std::uint64_t>::max());
            }
            return std::string();
        },
        "SEED");
}

CLI::Validator nonEmptyPath() {
    return CLI::Validator(
        [](std::string& input) -> std::string {
            return input.empty() ? std::string("an empty path names no file") : std::string();
        },
        "PATH");
}

CLI::Validator finiteNonNegative() {
    return finiteCheck("NONNEGATIVE", 0.0, false, std::numeric_limits<double>::max());
}

}  // namespace caphub::firmware
