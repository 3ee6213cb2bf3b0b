// A command's progress on a terminal: "caphub export: reading  42%" rewritten in place on
// stderr, only when stderr is a terminal and only when the percentage or the stage changes;
// cleared when done.
#pragma once

#include <string>
#include <string_view>

namespace caphub::firmware {

class TerminalProgress {
public:
    // `command`: the prefix ("caphub export"); `stageWidth`: the column the stage is padded to.
    TerminalProgress(std::string_view command, int stageWidth);
    ~TerminalProgress() { done(); }
    TerminalProgress(const TerminalProgress&) = delete;
    TerminalProgress& operator=(const TerminalProgress&) = delete;

    void operator()(std::string_view stage, double fraction);
    void done();

private:
    std::string command_;
    int stageWidth_;
    bool enabled_;
    bool shown_ = false;
    int percent_ = -1;
    std::string stage_;
};

}  // namespace caphub::firmware
