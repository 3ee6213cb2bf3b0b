// A text file being written by an exporter: buffered stdio, and every error (open, write,
// close: a full disk shows up late) turned into one message naming the file.
#pragma once

#include <cstdio>
#include <string>
#include <string_view>

#include "hal/core/error.h"

namespace caphub::firmware::exporter {

class OutputFile {
public:
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
