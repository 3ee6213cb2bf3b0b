// Files a command creates where a person said: opened so that the name cannot redirect the
// write (a symbolic link is not followed) or stall it (a FIFO with the name fails at once instead
// of waiting for a reader), and refused unless what was opened is a regular file.
#pragma once

#include <filesystem>

#include "hal/core/error.h"

namespace caphub {

// Creates or truncates `path` for writing (mode 0644, close-on-exec, blocking writes); the caller
// closes the descriptor. Errors: "create 'P': Too many levels of symbolic links" for a link,
// "create 'P': 'P' is not a regular file" (EINVAL) for a device or a FIFO.
Result<int> createOutputFd(const std::filesystem::path& path);

}  // namespace caphub
