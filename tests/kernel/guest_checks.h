// The kernel-level guest's check counter: every check prints one line, and the guest's summary
// counts them all (I2C and framebuffer sections alike).
#pragma once

#include <cstdio>
#include <string>

#include "hal/core/error.h"

namespace caphub::kernel_test {

// Counts and prints checks: "  ok    what" or "  FAIL  what: detail".
class Checks {
public:
    bool expect(bool ok, const std::string& what, const std::string& detail = {}) {
        ++count_;
        if (!ok) {
            ++failures_;
        }
        // The detail explains a failure; a pass needs only what was checked.
        const bool showDetail = !ok && !detail.empty();
        std::printf("  %-5s %s%s%s\n", ok ? "ok" : "FAIL", what.c_str(), showDetail ? ": " : "",
                    showDetail ? detail.c_str() : "");
        std::fflush(stdout);
        return ok;
    }

    // A bus operation's 0/-errno result.
    bool expectOk(int result, const std::string& what) {
        return expect(result == 0, what, result == 0 ? "" : caphub::errnoText(result));
    }

    static void info(const std::string& line) {
        std::printf("        %s\n", line.c_str());
        std::fflush(stdout);
    }

    int count() const { return count_; }
    int failures() const { return failures_; }

private:
    int count_ = 0;
    int failures_ = 0;
};

}  // namespace caphub::kernel_test
