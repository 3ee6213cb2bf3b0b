#include "hal/core/output_fd.h"

#include <cerrno>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace caphub {

Result<int> createOutputFd(const std::filesystem::path& path) {
    const int fd = ::open(path.c_str(),
                          O_WRONLY | O_CREAT | O_TRUNC | O_NOFOLLOW | O_NONBLOCK | O_CLOEXEC, 0644);
    if (fd < 0) {
        return errnoError(errno, "create '" + path.string() + "'");
    }
    struct stat st {};
    if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
        ::close(fd);
        return Error{EINVAL, "create '" + path.string() + "': '" + path.string() +
                                 "' is not a regular file"};
    }
    (void)::fcntl(fd, F_SETFL, ::fcntl(fd, F_GETFL) & ~O_NONBLOCK);
    return fd;
}

Result<void> replaceFileWhole(const std::filesystem::path& path,
                              const std::filesystem::path& temporary, std::string_view text,
                              bool durable) {
    auto fd = createOutputFd(temporary);
    if (!fd) {
        return fd.error();
    }
    const auto failed = [&](const std::string& what) {
        const Error e = errnoError(errno != 0 ? errno : EIO, what);
        ::unlink(temporary.c_str());
        return e;
    };
    std::size_t done = 0;
    while (done < text.size()) {
        const ssize_t n = ::write(*fd, text.data() + done, text.size() - done);
        if (n < 0 && errno == EINTR) {
            continue;
        }
        if (n <= 0) {
            if (n == 0) {
                errno = EIO;
            }
            const Error e = failed("write '" + temporary.string() + "'");
            ::close(*fd);
            return e;
        }
        done += static_cast<std::size_t>(n);
    }
    if (durable && ::fsync(*fd) != 0) {
        const Error e = failed("write '" + temporary.string() + "'");
        ::close(*fd);
        return e;
    }
    if (::close(*fd) != 0) {
        return failed("write '" + temporary.string() + "'");
    }
    if (::rename(temporary.c_str(), path.c_str()) != 0) {
        return failed("rename '" + temporary.string() + "' to '" + path.string() + "'");
    }
    return {};
}

}  // namespace caphub
