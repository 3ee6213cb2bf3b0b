// Files a command creates where a person said: opened so that the name cannot redirect the
// write (a symbolic link is not followed) or stall it (a FIFO with the name fails at once instead
// of waiting for a reader), and refused unless what was opened is a regular file.
#pragma once

#include <filesystem>
#include <string_view>

#include "hal/core/error.h"

namespace caphub {

// Creates or truncates `path` for writing (mode 0644, close-on-exec, blocking writes); the caller
// closes the descriptor. Errors: "create 'P': Too many levels of symbolic links" for a link,
// "create 'P': 'P' is not a regular file" (EINVAL) for a device or a FIFO.
Result<int> createOutputFd(const std::filesystem::path& path);

// Replaces `path` with `text` as a whole: written into `temporary` (created as above), flushed to
// the disk first when `durable`, then renamed over `path`. On any failure the temporary is removed
// and `path` is as it was. Errors: "create 'T': ...", "write 'T': ...", "rename 'T' to 'P': ...".
Result<void> replaceFileWhole(const std::filesystem::path& path,
                              const std::filesystem::path& temporary, std::string_view text,
                              bool durable = false);

}  // namespace caphub
