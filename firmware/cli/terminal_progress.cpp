#include "firmware/cli/terminal_progress.h"

#include <cmath>
#include <cstdio>

#include <fmt/format.h>
#include <unistd.h>

namespace caphub::firmware {

TerminalProgress::TerminalProgress(std::string_view command, int stageWidth)
    : command_(command), stageWidth_(stageWidth), enabled_(isatty(STDERR_FILENO) == 1) {}

void TerminalProgress::operator()(std::string_view stage, double fraction) {
    if (!enabled_) {
        return;
    }
    const int percent = static_cast<int>(std::floor(fraction * 100));
    if (percent == percent_ && stage == stage_) {
        return;
    }
    percent_ = percent;
    stage_ = stage;
    fmt::print(stderr, "\r{}: {:<{}} {:3d}%", command_, stage, stageWidth_, percent);
    std::fflush(stderr);
    shown_ = true;
}

void TerminalProgress::done() {
    if (shown_) {
        fmt::print(stderr, "\r{:40}\r", "");
        shown_ = false;
    }
}

}  // namespace caphub::firmware
