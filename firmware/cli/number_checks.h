// Checks of numeric options that also refuse what CLI11's own number checks let through: a
// value that is not a finite number (nan, inf) compares false with every bound, so
// CLI::PositiveNumber, CLI::NonNegativeNumber and CLI::Range accept "nan" (an import with
// --pose-rate nan looped for ever).
#pragma once

#include <CLI/CLI.hpp>

namespace caphub::firmware {

// A finite number within [min, max].
CLI::Validator finiteRange(double min, double max);
// A capture's or a service's -d: 1 ms (a shorter one rounds to nothing) to three years (the
// nanosecond clock holds 292).
inline constexpr double kMinDurationS = 1e-3;
inline constexpr double kMaxDurationS = 1e8;

// 0 (what the option's help says it means), or a finite number within [min, max]: a duration of
// 1e-10 s rounded to 0 ns, which means "until Ctrl-C".
CLI::Validator zeroOrRange(double min, double max);
// A finite number above zero.
CLI::Validator finitePositive();
// A finite number at or above zero.
CLI::Validator finiteNonNegative();

// A seed: digits only, 0 to 2^64 - 1 (CLI11 reads "-1" into an unsigned as 2^64 - 1, and a
// seed given as '' as 0).
CLI::Validator seedNumber();

// Not an empty string: a path given as '' (an unset shell variable) is a mistake, not "none".
CLI::Validator nonEmptyPath();

}  // namespace caphub::firmware
