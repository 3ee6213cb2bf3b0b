// What an offline command (import, reprocess, export) writes appears under its own name only
// when complete: it is written as NAME.part beside it, and a signal that ends the program
// (Ctrl-C, SIGTERM, SIGHUP; one ignored when the program started stays ignored) removes the part
// first, then ends the program as the signal would. While a guard is alive, SIGXFSZ is ignored:
// a write past the file size limit (ulimit -f) then fails with EFBIG, which the writers report,
// instead of killing the program with the part left behind.
#pragma once

#include <array>
#include <csignal>
#include <string>

#include "hal/core/error.h"

namespace caphub::firmware {

class PartialOutput {
public:
    // `partial`: the part's path. One guard at a time.
    explicit PartialOutput(std::string partial);
    ~PartialOutput();  // restores the signals' handlers; removes the part unless published
    PartialOutput(const PartialOutput&) = delete;
    PartialOutput& operator=(const PartialOutput&) = delete;

    const std::string& path() const { return partial_; }
    // Renames the part to `target` where nothing is (EEXIST when something is: never replaced).
    Result<void> publishNew(const std::string& target);
    // The caller renamed the part itself (over a target it may replace): nothing to remove.
    void published();

    // The signals that end the program and remove the part first.
    static constexpr std::array<int, 3> kEnding{SIGINT, SIGTERM, SIGHUP};

private:
    std::string partial_;
    std::array<struct sigaction, kEnding.size() + 1> previous_{};  // and SIGXFSZ's
    bool published_ = false;
};

}  // namespace caphub::firmware
