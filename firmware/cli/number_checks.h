// Checks of numeric options that also refuse what CLI11's own number checks let through: a
// value that is not a finite number (nan, inf) compares false with every bound, so
// CLI::PositiveNumber, CLI::NonNegativeNumber and CLI::Range accept "nan" (an import with
// --pose-rate nan looped for ever).
#pragma once

#include <CLI/CLI.hpp>

namespace caphub::firmware {

// A finite number within [min, max].
CLI::Validator finiteRange(double min, double max);
// A finite number above zero.
CLI::Validator finitePositive();
// A finite number at or above zero.
CLI::Validator finiteNonNegative();

// Not an empty string: a path given as '' (an unset shell variable) is a mistake, not "none".
CLI::Validator nonEmptyPath();

}  // namespace caphub::firmware
