#include "firmware/export/output_file.h"

#include <cerrno>
#include <utility>

#include <fcntl.h>
#include <fmt/format.h>
#include <sys/stat.h>
#include <unistd.h>

#include "firmware/export/partial_output.h"
#include "hal/core/output_fd.h"

namespace caphub::firmware::exporter {

namespace fs = std::filesystem;

namespace {

constexpr const char* kRegularOnly = ": only a regular file is written";

// What a file of this mode is, for a person; empty for a regular file.
std::string kindOf(mode_t mode) {
    if (S_ISREG(mode)) {
        return {};
    }
    if (S_ISDIR(mode)) {
        return "a directory";
    }
    if (S_ISCHR(mode) || S_ISBLK(mode)) {
        return "a device";
    }
    if (S_ISFIFO(mode)) {
        return "a FIFO (named pipe)";
    }
    if (S_ISSOCK(mode)) {
        return "a socket";
    }
    return "not a regular file";
}

int errnoOfKind(mode_t mode) {
    return S_ISDIR(mode) ? EISDIR : EINVAL;
}

}  // namespace

Result<fs::path> regularOutputTarget(const std::string& path) {
    struct stat st {};
    if (::lstat(path.c_str(), &st) != 0) {
        if (errno == ENOENT) {
            return fs::path(path);  // a new file (a missing folder shows when it is created)
        }
        return errnoError(errno, "-o '" + path + "'");
    }
    fs::path target = path;
    if (S_ISLNK(st.st_mode)) {
        std::error_code ec;
        const fs::path named = fs::read_symlink(path, ec);
        target = fs::canonical(path, ec);
        if (ec) {
            return Error{ENOENT, "'" + path + "' is a symbolic link that names '" + named.string() +
                                     "', which does not exist" + kRegularOnly};
        }
        if (::stat(target.c_str(), &st) != 0) {
            return errnoError(errno, "-o '" + path + "' -> '" + target.string() + "'");
        }
    }
    if (const std::string kind = kindOf(st.st_mode); !kind.empty()) {
        return Error{errnoOfKind(st.st_mode),
                     "'" + target.string() + "' is " + kind + kRegularOnly};
    }
    return target;
}

Result<fs::path> claimOutputTarget(const std::string& path, std::string_view option,
                                   const std::vector<std::string>& others) {
    auto target = regularOutputTarget(path);
    if (!target) {
        return Error{target.error().code, fmt::format("{}: {}", option, target.error().message)};
    }
    std::error_code ec;
    const bool exists = fs::exists(*target, ec);
    for (const std::string& other : others) {
        // The same file under another name; one not made yet, under the same path.
        std::error_code e1;
        std::error_code e2;
        const bool same = !other.empty() && (exists ? fs::equivalent(*target, other, e1)
                                                    : fs::weakly_canonical(*target, e1) ==
                                                          fs::weakly_canonical(other, e2));
        if (same) {
            return Error{EINVAL, fmt::format("{} '{}' is '{}', which the command also reads or "
                                             "writes: not replaced",
                                             option, path, other)};
        }
    }
    const fs::path folder = target->has_parent_path() ? target->parent_path() : fs::path(".");
    if (!fs::is_directory(folder, ec)) {
        return Error{ENOENT, fmt::format("{} '{}': the folder '{}' does not exist", option, path,
                                         folder.string())};
    }
    if (::access(folder.c_str(), W_OK) != 0) {
        return errnoError(errno,
                          fmt::format("{} '{}': the folder '{}'", option, path, folder.string()));
    }
    return target;
}

Result<void> writeWholeFile(const fs::path& target, std::string_view text) {
    PartialOutput part(target.string() + ".part");
    auto file = OutputFile::open(part.path());
    if (!file) {
        return file.error();
    }
    file->write(text);
    if (auto closed = file->close(); !closed) {
        return closed.error();
    }
    std::error_code ec;
    fs::rename(part.path(), target, ec);
    if (ec) {
        return Error{ec.value(), fmt::format("rename '{}' to '{}': {}", part.path(),
                                             target.string(), ec.message())};
    }
    part.published();
    return {};
}

Result<OutputFile> OutputFile::open(const std::string& path) {
    auto created = createOutputFd(path);
    if (!created) {
        return Error{created.error().code, created.error().message + kRegularOnly};
    }
    const int fd = *created;
    std::FILE* f = ::fdopen(fd, "wb");
    if (f == nullptr) {
        const int err = errno;
        ::close(fd);
        return errnoError(err, "create '" + path + "'");
    }
    // Exports run to hundreds of megabytes: large writes keep the syscall count down.
    (void)std::setvbuf(f, nullptr, _IOFBF, 1 << 20);
    return OutputFile(f, path);
}

OutputFile::OutputFile(OutputFile&& other) noexcept
    : file_(std::exchange(other.file_, nullptr)),
      path_(std::move(other.path_)),
      errno_(other.errno_) {}

OutputFile::~OutputFile() {
    if (file_ != nullptr) {
        std::fclose(file_);
    }
}

void OutputFile::write(std::string_view bytes) {
    if (file_ == nullptr || errno_ != 0 || bytes.empty()) {
        return;
    }
    if (std::fwrite(bytes.data(), 1, bytes.size(), file_) != bytes.size()) {
        errno_ = errno != 0 ? errno : EIO;
    }
}

Result<void> OutputFile::close() {
    if (file_ == nullptr) {
        return {};
    }
    errno = 0;
    const int rc = std::fclose(std::exchange(file_, nullptr));
    const int closeErrno = errno;
    if (errno_ != 0) {
        return errnoError(errno_, "write '" + path_ + "'");
    }
    if (rc != 0) {
        return errnoError(closeErrno != 0 ? closeErrno : EIO, "write '" + path_ + "'");
    }
    return {};
}

}  // namespace caphub::firmware::exporter
