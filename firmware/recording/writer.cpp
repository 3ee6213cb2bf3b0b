#include "firmware/recording/writer.h"

#include <algorithm>
#include <cerrno>

#include <fcntl.h>
#include <unistd.h>

#include "firmware/recording/crc32c.h"

namespace caphub::firmware {

using namespace cap;

Result<std::unique_ptr<RecordingWriter>> RecordingWriter::create(const std::string& path,
                                                                 std::string_view metadataToml,
                                                                 const WriterOptions& options) {
    if (metadataToml.size() > kMaxPayloadBytes) {
        return Error{EINVAL, "recording '" + path + "': metadata too large"};
    }
    hal::UniqueFd fd(::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644));
    if (!fd.isValid()) {
        return errnoError(errno, "cannot create recording '" + path + "'");
    }
    std::unique_ptr<RecordingWriter> w(new RecordingWriter(path, std::move(fd), options));
    std::vector<std::uint8_t> header(kHeaderFixedBytes + metadataToml.size());
    std::copy(kMagic.begin(), kMagic.end(), header.begin());
    put16(&header[8], kVersion);
    put16(&header[10], 0);
    put32(&header[12], static_cast<std::uint32_t>(metadataToml.size()));
    std::copy(metadataToml.begin(), metadataToml.end(), header.begin() + kHeaderFixedBytes);
    std::uint32_t crc = crc32c(std::span(header.data(), 16));
    crc = crc32c(std::span(header.data() + kHeaderFixedBytes, metadataToml.size()), crc);
    put32(&header[16], crc);
    if (int r = w->writeAll(header.data(), header.size()); r < 0) {
        return errnoError(r, "cannot write the header of recording '" + path + "'");
    }
    if (::fdatasync(w->fd_.get()) < 0) {
        return errnoError(errno, "cannot sync recording '" + path + "'");
    }
    // The directory entry must be durable too, or a power cut could lose the whole file.
    const auto slash = path.rfind('/');
    const std::string dir = slash == std::string::npos ? "." : path.substr(0, slash + 1);
    hal::UniqueFd dirFd(::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC));
    if (dirFd.isValid()) {
        (void)::fsync(dirFd.get());
    }
    w->lastSync_ = w->clock_.now();
    return w;
}

RecordingWriter::RecordingWriter(std::string path, hal::UniqueFd fd, const WriterOptions& options)
    : path_(std::move(path)),
      fd_(std::move(fd)),
      options_(options),
      buffer_(std::max<std::size_t>(options.bufferBytes, kMaxPayloadBytes / 16)) {}

RecordingWriter::~RecordingWriter() {
    (void)close();
}

int RecordingWriter::writeAll(const std::uint8_t* data, std::size_t n) {
    while (n > 0) {
        const ssize_t w = ::write(fd_.get(), data, n);
        if (w < 0) {
            if (errno == EINTR) {
                continue;
            }
            return -errno;
        }
        data += w;
        n -= static_cast<std::size_t>(w);
        stats_.bytesWritten += static_cast<std::uint64_t>(w);
    }
    return 0;
}

std::uint8_t* RecordingWriter::begin(RecordType type, Timestamp t, std::size_t payloadBytes) {
    if (error_ != 0 || !fd_.isValid() || payloadBytes > kMaxPayloadBytes) {
        return nullptr;
    }
    const std::size_t total = kRecordOverheadBytes + payloadBytes;
    if (used_ + total > buffer_.size()) {
        if (flush(false) < 0) {
            return nullptr;
        }
        if (total > buffer_.size()) {
            buffer_.resize(total);  // a rare oversize record (metadata); not on the sample path
        }
    }
    std::uint8_t* r = buffer_.data() + used_;
    std::copy(kSync.begin(), kSync.end(), r);
    r[4] = static_cast<std::uint8_t>(type);
    r[5] = 0;
    put16(r + 6, 0);
    put32(r + 8, static_cast<std::uint32_t>(payloadBytes));
    put64(r + 12, static_cast<std::uint64_t>(toNs(t)));
    recordStart_ = used_;
    used_ += total;
    return r + kRecordHeaderBytes;
}

int RecordingWriter::end() {
    std::uint8_t* r = buffer_.data() + recordStart_;
    const std::size_t payload = get32(r + 8);
    const std::uint32_t crc = crc32c(std::span(r + 4, kRecordHeaderBytes - 4 + payload));
    put32(r + kRecordHeaderBytes + payload, crc);
    ++bufferedRecords_;
    ++stats_.records;
    if (clock_.now() - lastSync_ >= options_.syncInterval) {
        return flush(true);
    }
    return 0;
}

int RecordingWriter::flush(bool sync) {
    if (error_ != 0) {
        return error_;
    }
    if (!fd_.isValid()) {
        return -EBADF;
    }
    if (used_ > 0) {
        if (int r = writeAll(buffer_.data(), used_); r < 0) {
            // Stop cleanly: nothing more is written, what is on disk stays readable (a torn
            // last record is skipped by the reader).
            error_ = r;
            used_ = 0;
            return r;
        }
        used_ = 0;
        writtenRecords_ += bufferedRecords_;
        bufferedRecords_ = 0;
    }
    if (sync) {
        if (::fdatasync(fd_.get()) < 0) {
            error_ = -errno;
            return error_;
        }
        ++stats_.syncs;
        stats_.durableRecords = writtenRecords_;
        lastSync_ = clock_.now();
    }
    return 0;
}

int RecordingWriter::maybeSync() {
    if (error_ == 0 && fd_.isValid() && clock_.now() - lastSync_ >= options_.syncInterval) {
        return flush(true);
    }
    return error_;
}

int RecordingWriter::close() {
    if (!fd_.isValid()) {
        return error_;
    }
    const int r = flush(true);
    fd_.reset();
    return r;
}

int RecordingWriter::writeRawSample(int sensor, const hal::ImuSample& s) {
    std::uint8_t* p = begin(RecordType::RawSample, s.t, kRawSampleBytes);
    if (p == nullptr) {
        return error_ != 0 ? error_ : -EINVAL;
    }
    put16(p, static_cast<std::uint16_t>(sensor));
    p[2] = s.flags;
    p[3] = 0;
    for (int i = 0; i < 3; ++i) {
        putF32(p + 4 + 4 * i, s.accMps2[i]);
        putF32(p + 16 + 4 * i, s.gyrRadps[i]);
        putF32(p + 28 + 4 * i, s.magUt[i]);
    }
    putF32(p + 40, s.temperatureC);
    return end();
}

int RecordingWriter::writeOrientation(int sensor, Timestamp t, const Eigen::Quaternionf& q) {
    std::uint8_t* p = begin(RecordType::Orientation, t, kOrientationBytes);
    if (p == nullptr) {
        return error_ != 0 ? error_ : -EINVAL;
    }
    put16(p, static_cast<std::uint16_t>(sensor));
    put16(p + 2, 0);
    putF32(p + 4, q.w());
    putF32(p + 8, q.x());
    putF32(p + 12, q.y());
    putF32(p + 16, q.z());
    return end();
}

int RecordingWriter::writePose(Timestamp t, const Eigen::Vector3f& rootM,
                               std::span<const Eigen::Quaternionf> joints) {
    std::uint8_t* p = begin(RecordType::Pose, t, kPoseFixedBytes + 16 * joints.size());
    if (p == nullptr) {
        return error_ != 0 ? error_ : -EINVAL;
    }
    put16(p, static_cast<std::uint16_t>(joints.size()));
    put16(p + 2, 0);
    for (int i = 0; i < 3; ++i) {
        putF32(p + 4 + 4 * i, rootM[i]);
    }
    std::uint8_t* q = p + kPoseFixedBytes;
    for (const auto& j : joints) {
        putF32(q, j.w());
        putF32(q + 4, j.x());
        putF32(q + 8, j.y());
        putF32(q + 12, j.z());
        q += 16;
    }
    return end();
}

int RecordingWriter::writeEvent(Timestamp t, EventKind kind, int sensor, int error,
                                std::string_view text) {
    std::uint8_t* p = begin(RecordType::Event, t, kEventFixedBytes + text.size());
    if (p == nullptr) {
        return error_ != 0 ? error_ : -EINVAL;
    }
    p[0] = static_cast<std::uint8_t>(kind);
    p[1] = 0;
    put16(p + 2, static_cast<std::uint16_t>(static_cast<std::int16_t>(sensor)));
    put32(p + 4, static_cast<std::uint32_t>(error));
    std::copy(text.begin(), text.end(), p + kEventFixedBytes);
    return end();
}

int RecordingWriter::writeMetadata(Timestamp t, std::string_view toml) {
    std::uint8_t* p = begin(RecordType::Metadata, t, toml.size());
    if (p == nullptr) {
        return error_ != 0 ? error_ : -EINVAL;
    }
    std::copy(toml.begin(), toml.end(), p);
    return end();
}

int RecordingWriter::writeMarker(Timestamp t, std::string_view label) {
    std::uint8_t* p = begin(RecordType::Marker, t, label.size());
    if (p == nullptr) {
        return error_ != 0 ? error_ : -EINVAL;
    }
    std::copy(label.begin(), label.end(), p);
    return end();
}

}  // namespace caphub::firmware
