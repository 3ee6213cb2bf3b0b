#include "firmware/export/output_file.h"

#include <cerrno>
#include <utility>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace caphub::firmware::exporter {

namespace fs = std::filesystem;

namespace {

constexpr const char* kRegularOnly = ": an export writes regular files only";

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

Result<OutputFile> OutputFile::open(const std::string& path) {
    // O_NONBLOCK: opening a FIFO that has the name fails at once instead of waiting for a reader.
    const int fd = ::open(path.c_str(),
                          O_WRONLY | O_CREAT | O_TRUNC | O_NOFOLLOW | O_NONBLOCK | O_CLOEXEC, 0644);
    if (fd < 0) {
        return errnoError(errno, "create '" + path + "'");
    }
    struct stat st {};
    if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
        ::close(fd);
        return Error{EINVAL, "create '" + path + "': '" + path + "' is " + kindOf(st.st_mode) +
                                 kRegularOnly};
    }
    (void)::fcntl(fd, F_SETFL, ::fcntl(fd, F_GETFL) & ~O_NONBLOCK);
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
