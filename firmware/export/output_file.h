// A text file being written by an exporter: buffered stdio, and every error (open, write,
// close: a full disk shows up late) turned into one message naming the file. And where an export
// may write at all: over a regular file (or into the regular file a symbolic link names), never
// over a directory, a device, a FIFO or a socket.
#pragma once

#include <cstdio>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "hal/core/error.h"

namespace caphub::firmware::exporter {

// The file an export given `-o path` replaces: `path` when it is a regular file or does not
// exist yet; for a symbolic link, the regular file it names (the link stays a link). Anything
// else is refused with what it is: "'P' is a directory", "'P' is a device", "'P' is a FIFO
// (named pipe)", "'P' is a socket", "'L' is a symbolic link that names 'P', which does not
// exist", each followed by ": only a regular file is written".
Result<std::filesystem::path> regularOutputTarget(const std::string& path);

// Where a command may write the file its option `option` (e.g. "--json") names, checked before the
// command's work starts so that a long run does not end in "cannot write": regularOutputTarget's
// target, which is none of `others` (the files the command reads, and its other outputs) under
// any name, and whose folder exists.
Result<std::filesystem::path> claimOutputTarget(const std::string& path, std::string_view option,
                                                const std::vector<std::string>& others);

// Writes `text` to `target` (a claimOutputTarget) as a whole: into TARGET.part, renamed over
// the target when complete; a failure or Ctrl-C leaves the target as it was.
Result<void> writeWholeFile(const std::filesystem::path& target, std::string_view text);

class OutputFile {
public:
    // Creates or truncates a regular file (never follows a symbolic link, never opens a FIFO or
    // a device that happens to have the name).
    static Result<OutputFile> open(const std::string& path);
    OutputFile(OutputFile&& other) noexcept;
    OutputFile& operator=(OutputFile&&) = delete;
    OutputFile(const OutputFile&) = delete;
    ~OutputFile();

    // Appends bytes; a failure is remembered and reported by close().
    void write(std::string_view bytes);
    // Flushes and closes: the first error met, if any.
    Result<void> close();

private:
    OutputFile(std::FILE* f, std::string path) : file_(f), path_(std::move(path)) {}
    std::FILE* file_ = nullptr;
    std::string path_;
    int errno_ = 0;  // of the first failed write
};

}  // namespace caphub::firmware::exporter
