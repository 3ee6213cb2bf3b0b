// --smooth-heading causal|both|rest, on the commands that run the non-causal pass (reprocess,
// evaluate --reprocess-smooth, fusion replay --smooth): fusion::setSmoothHeading reads the value.
#pragma once

#include <string>

#include <CLI/CLI.hpp>

namespace caphub::firmware {

// The option, allowed only beside the flag `smoothFlag` that turns the pass on.
inline void addSmoothHeadingOption(CLI::App& cmd, std::string& value, const char* smoothFlag) {
    cmd.add_option("--smooth-heading", value,
                   "With the non-causal pass, the heading: causal (the live filter's, default) "
                   "or both (the forward and the backward runs' combined, without the heading "
                   "gain's lag; wrong where the field differs from place to place) or rest "
                   "(the causal heading, but between two rests the gyroscope's, anchored on "
                   "the field at each rest: docs/reprocess.md)")
        ->check(CLI::IsMember({"causal", "both", "rest"}))
        ->needs(smoothFlag);
}

}  // namespace caphub::firmware
