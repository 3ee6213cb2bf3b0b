#include "hal/core/input_file.h"

#include <cerrno>
#include <memory>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace caphub {

namespace {

std::string quoted(const std::filesystem::path& path) {
    return "'" + path.string() + "'";
}

// The problem with a file of this mode, or success for one that can be read.
Result<void> checkMode(const std::filesystem::path& path, mode_t mode) {
    if (S_ISREG(mode) || S_ISFIFO(mode)) {
        return {};
    }
    if (S_ISDIR(mode)) {
        return Error{EISDIR, quoted(path) + " is a directory, not a file"};
    }
    if (S_ISCHR(mode) || S_ISBLK(mode)) {
        return Error{ENODEV, quoted(path) + " is a device, not a file"};
    }
    if (S_ISSOCK(mode)) {
        return Error{ENXIO, quoted(path) + " is a socket, not a file"};
    }
    return Error{EINVAL, quoted(path) + " is not a regular file"};
}

}  // namespace

Result<void> checkInputFile(const std::filesystem::path& path) {
    struct stat st {};
    if (::stat(path.c_str(), &st) != 0) {
        return errnoError(errno, "open " + quoted(path));
    }
    return checkMode(path, st.st_mode);
}

Result<std::FILE*> openInputFile(const std::filesystem::path& path) {
    // Checked before opening (opening a device can have effects) and again on what was opened.
    if (auto ok = checkInputFile(path); !ok) {
        return ok.error();
    }
    // Not blocking in the open: a FIFO that nobody writes to would wait there for ever (it
    // then reads as empty); reads block again as usual afterwards (a pipe being written to).
    const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
    if (fd < 0) {
        return errnoError(errno, "open " + quoted(path));
    }
    if (const int flags = ::fcntl(fd, F_GETFL);
        flags < 0 || ::fcntl(fd, F_SETFL, flags & ~O_NONBLOCK) != 0) {
        const int err = errno;
        ::close(fd);
        return errnoError(err, "open " + quoted(path));
    }
    struct stat st {};
    if (::fstat(fd, &st) != 0) {
        const int err = errno;
        ::close(fd);
        return errnoError(err, "open " + quoted(path));
    }
    if (auto ok = checkMode(path, st.st_mode); !ok) {
        ::close(fd);
        return ok.error();
    }
    std::FILE* f = ::fdopen(fd, "rb");
    if (f == nullptr) {
        const int err = errno;
        ::close(fd);
        return errnoError(err, "open " + quoted(path));
    }
    return f;
}

Result<std::string> readInputFile(const std::filesystem::path& path, std::size_t maxBytes) {
    auto opened = openInputFile(path);
    if (!opened) {
        return opened.error();
    }
    std::unique_ptr<std::FILE, int (*)(std::FILE*)> f(*opened, &std::fclose);
    struct stat st {};
    if (::fstat(::fileno(f.get()), &st) == 0 && S_ISREG(st.st_mode) &&
        static_cast<std::size_t>(st.st_size) > maxBytes) {
        return Error{EFBIG, quoted(path) + " is " + std::to_string(st.st_size) +
                                " bytes, more than the " + std::to_string(maxBytes) +
                                " bytes allowed"};
    }
    std::string text;
    char buf[64 * 1024];
    std::size_t n = 0;
    while ((n = std::fread(buf, 1, sizeof buf, f.get())) > 0) {
        if (text.size() + n > maxBytes) {  // a pipe: its size shows only while reading
            return Error{EFBIG, quoted(path) + " is more than the " + std::to_string(maxBytes) +
                                    " bytes allowed"};
        }
        text.append(buf, n);
    }
    if (std::ferror(f.get()) != 0) {
        return errnoError(errno != 0 ? errno : EIO, "read " + quoted(path));
    }
    // A FIFO nobody writes into reads as empty: said so, rather than as an empty or malformed
    // file (a status file "not JSON: unexpected end of input").
    if (text.empty() && S_ISFIFO(st.st_mode)) {
        return Error{ENODATA,
                     quoted(path) + " is a FIFO (named pipe) with nothing written into it"};
    }
    return text;
}

}  // namespace caphub
