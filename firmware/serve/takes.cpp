#include "firmware/serve/takes.h"

#include <algorithm>
#include <chrono>

#include <fmt/format.h>

namespace caphub::firmware::serve {

namespace fs = std::filesystem;

namespace {

std::int64_t unixSeconds(fs::file_time_type t) {
    const auto sys = std::chrono::file_clock::to_sys(t);
    return std::chrono::duration_cast<std::chrono::seconds>(sys.time_since_epoch()).count();
}

}  // namespace

std::vector<TakeFile> listTakes(const fs::path& recordings) {
    std::vector<TakeFile> out;
    std::error_code ec;
    for (fs::directory_iterator it(recordings, ec), end; !ec && it != end; it.increment(ec)) {
        const fs::path& p = it->path();
        std::error_code e2;
        if (p.extension() != ".cap" || it->is_symlink(e2) || !it->is_regular_file(e2) ||
            p.filename().string().starts_with('.')) {
            continue;
        }
        TakeFile t;
        t.name = p.filename().string();
        t.bytes = it->file_size(e2);
        t.modifiedUnixS = unixSeconds(it->last_write_time(e2));
        out.push_back(std::move(t));
    }
    std::sort(out.begin(), out.end(), [](const TakeFile& a, const TakeFile& b) {
        return a.modifiedUnixS != b.modifiedUnixS ? a.modifiedUnixS > b.modifiedUnixS
                                                  : a.name > b.name;
    });
    return out;
}

Result<fs::path> resolveTake(const fs::path& recordings, const std::string& name) {
    if (name.empty() || name.size() > 255 || name.find('/') != std::string::npos ||
        name.find('\\') != std::string::npos || name.find('\0') != std::string::npos ||
        name.starts_with('.') || name.find("..") != std::string::npos ||
        fs::path(name).extension() != ".cap") {
        return Error{EINVAL, fmt::format("'{}' is not a take's file name (NAME.cap in the "
                                         "recordings folder)",
                                         name)};
    }
    const fs::path path = recordings / name;
    std::error_code ec;
    const auto status = fs::symlink_status(path, ec);
    if (ec || !fs::exists(status)) {
        return Error{ENOENT, fmt::format("no take '{}'", name)};
    }
    if (fs::is_symlink(status) || !fs::is_regular_file(status)) {
        return Error{EPERM,
                     fmt::format("'{}' is not a regular file in the recordings folder", name)};
    }
    // The folder itself may be a symlink (a mounted card): compare canonical paths.
    const fs::path folder = fs::canonical(recordings, ec);
    const fs::path real = ec ? fs::path() : fs::canonical(path, ec);
    if (ec || real.parent_path() != folder) {
        return Error{EPERM, fmt::format("'{}' resolves outside the recordings folder", name)};
    }
    return real;
}

}  // namespace caphub::firmware::serve
