#include "firmware/export/output_file.h"

#include <cerrno>
#include <utility>

namespace caphub::firmware::exporter {

Result<OutputFile> OutputFile::open(const std::string& path) {
    std::FILE* f = std::fopen(path.c_str(), "wb");
    if (f == nullptr) {
        return errnoError(errno, "create '" + path + "'");
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
    const int rc = std::fclose(std::exchange(file_, nullptr));
    if (errno_ != 0) {
        return errnoError(errno_, "write '" + path_ + "'");
    }
    if (rc != 0) {
        return errnoError(errno != 0 ? errno : EIO, "write '" + path_ + "'");
    }
    return {};
}

}  // namespace caphub::firmware::exporter
