// What this build of caphub is.
#pragma once

#include <cstdint>
#include <string>

#include "hal/core/error.h"

namespace caphub::firmware {

// "caphub 0.1.0 (abc123, Debug)"
std::string versionLine();

// A recording's summary as `caphub info FILE` prints it (text), with its main figures as data.
struct RecordingSummary {
    std::string text;
    double durationS = 0;
    std::uint64_t records = 0;
    std::uint64_t poses = 0;
    std::uint64_t markers = 0;
    std::size_t damagedRanges = 0;
    std::uint64_t tornTailBytes = 0;
};

// Reads the whole recording. Errors: EINVAL when it is not a recording (or cannot be opened),
// the read's errno when reading fails part way.
Result<RecordingSummary> summarizeRecording(const std::string& path);

}  // namespace caphub::firmware
