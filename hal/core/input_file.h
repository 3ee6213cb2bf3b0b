// Files a person names as input (board, calibration, names, map, clip, recording and status
// files): one place that opens them and says plainly what is wrong, so that a directory or a
// device given where a file is expected is called one, not read as an empty or garbled file.
#pragma once

#include <cstddef>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <string>

#include "hal/core/error.h"

namespace caphub {

// Whether `path` can be read as a file: it exists and is a regular file or a pipe (what a
// symbolic link names counts). Errors: "open 'P': No such file or directory", "'P' is a
// directory, not a file" (EISDIR), "'P' is a device, not a file" (ENODEV), "'P' is a socket,
// not a file" (ENXIO).
Result<void> checkInputFile(const std::filesystem::path& path);

// Opens it for reading (binary, close-on-exec) after the same checks; the caller closes it. The
// open does not wait for a FIFO's writer (one without any reads as empty).
Result<std::FILE*> openInputFile(const std::filesystem::path& path);

// Its whole content; a file larger than maxBytes is refused unread (EFBIG: "'P' is N bytes,
// more than the M bytes allowed").
Result<std::string> readInputFile(const std::filesystem::path& path,
                                  std::size_t maxBytes = std::numeric_limits<std::size_t>::max());

}  // namespace caphub
