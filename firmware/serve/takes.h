// The recordings folder as the web control plane sees it: the takes in it (.cap files), and the
// one rule for reaching a file in it from a name a client sent: a plain file name (no '/', no
// "..", not hidden), ending in .cap, a regular file and not a symlink, whose canonical path is in
// the canonical folder. Anything else is refused; nothing outside the folder is ever opened.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "hal/core/error.h"

namespace caphub::firmware::serve {

struct TakeFile {
    std::string name;  // the file name, e.g. 20261123-120000-walk.cap
    std::uint64_t bytes = 0;
    std::int64_t modifiedUnixS = 0;
};

// The .cap files directly in the folder (regular files only; symlinks are left out), newest
// first. An empty list when the folder does not exist yet.
std::vector<TakeFile> listTakes(const std::filesystem::path& recordings);

// The path of take `name` in the folder. Errors: EINVAL for a name that is not a plain .cap file
// name, ENOENT when there is no such file, EPERM for a symlink or anything that resolves outside
// the folder.
Result<std::filesystem::path> resolveTake(const std::filesystem::path& recordings,
                                          const std::string& name);

}  // namespace caphub::firmware::serve
