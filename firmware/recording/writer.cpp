#include "firmware/recording/writer.h"

#include <algorithm>
#include <cerrno>

#include <fcntl.h>
#include <pthread.h>
#include <stdio.h>
#include <unistd.h>

#include "firmware/recording/crc32c.h"

namespace caphub::firmware {

using namespace cap;

namespace {

// A record's header (all but its payload and CRC) at r.
void putRecordHeader(std::uint8_t* r, RecordType type, std::int64_t tNs, std::size_t payloadBytes) {
    std::copy(kSync.begin(), kSync.end(), r);
    r[4] = static_cast<std::uint8_t>(type);
    r[5] = 0;
    put16(r + 6, 0);
    put32(r + 8, static_cast<std::uint32_t>(payloadBytes));
    put64(r + 12, static_cast<std::uint64_t>(tNs));
}

// The CRC after the payload of the record at r, whose header is complete.
void putRecordCrc(std::uint8_t* r) {
    const std::size_t payload = get32(r + 8);
    const std::uint32_t crc = crc32c(std::span(r + 4, kRecordHeaderBytes - 4 + payload));
    put32(r + kRecordHeaderBytes + payload, crc);
}

// Gives the file `from` the name `to` unless `to` exists (then -EEXIST): renameat2's
// RENAME_NOREPLACE, or where the file system lacks it, a hard link and the old name removed.
int publishNoReplace(const std::string& from, const std::string& to) {
    if (::renameat2(AT_FDCWD, from.c_str(), AT_FDCWD, to.c_str(), RENAME_NOREPLACE) == 0) {
        return 0;
    }
    if (errno != EINVAL && errno != ENOSYS) {
        return -errno;
    }
    if (::link(from.c_str(), to.c_str()) < 0) {
        return -errno;
    }
    (void)::unlink(from.c_str());
    return 0;
}

// Why the writer stopped, in the stop event's text (the error itself is in its error field).
constexpr std::string_view kStopText = "write error";

}  // namespace

Result<std::unique_ptr<RecordingWriter>> RecordingWriter::create(const std::string& path,
                                                                 std::string_view metadataToml,
                                                                 const WriterOptions& options) {
    if (metadataToml.size() > kMaxPayloadBytes) {
        return Error{EINVAL, "recording '" + path + "': metadata too large"};
    }
    // The file is written under a hidden name beside the target and appears under its own name
    // only with its header on the disk: a crash in between leaves no recording without a header.
    if (::access(path.c_str(), F_OK) == 0) {
        return errnoError(EEXIST, "cannot create recording '" + path + "'");
    }
    const auto slash = path.rfind('/');
    const std::string dir = slash == std::string::npos ? "." : path.substr(0, slash + 1);
    const std::string creating = path.substr(0, slash + 1) + "." + path.substr(slash + 1) +
                                 ".creating";  // slash + 1 is 0 without a slash
    (void)::unlink(creating.c_str());          // left by a crash in this window; never a recording
    hal::UniqueFd fd(::open(creating.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644));
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
        (void)::unlink(creating.c_str());
        return errnoError(r, "cannot write the header of recording '" + path + "'");
    }
    if (::fdatasync(w->fd_.get()) < 0) {
        const int e = errno;
        (void)::unlink(creating.c_str());
        return errnoError(e, "cannot sync recording '" + path + "'");
    }
    if (int r = publishNoReplace(creating, path); r < 0) {
        (void)::unlink(creating.c_str());
        return errnoError(r, "cannot create recording '" + path + "'");
    }
    // The directory entry must be durable too, or a power cut could lose the whole file.
    hal::UniqueFd dirFd(::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC));
    if (dirFd.isValid()) {
        (void)::fsync(dirFd.get());
    }
    w->lastSync_ = w->clock_.now();
    RecordingWriter* self = w.get();
    w->io_ = std::thread([self] {
        ::pthread_setname_np(::pthread_self(), "caphub-rec-io");
        self->ioLoop();
    });
    return w;
}

RecordingWriter::RecordingWriter(std::string path, hal::UniqueFd fd, const WriterOptions& options)
    : path_(std::move(path)), fd_(std::move(fd)), options_(options) {
    const std::size_t bytes = std::max<std::size_t>(options.bufferBytes, kMaxPayloadBytes / 16);
    queued_.reserve(buffers_.size());
    free_.reserve(buffers_.size());
    for (auto& b : buffers_) {
        b.bytes.resize(bytes);
        free_.push_back(&b);
    }
    active_ = free_.back();
    free_.pop_back();
}

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
        bytesWritten_.fetch_add(static_cast<std::uint64_t>(w), std::memory_order_relaxed);
    }
    return 0;
}

WriterStats RecordingWriter::stats() const {
    WriterStats s;
    s.records = writtenRecords_.load(std::memory_order_acquire);
    s.acceptedRecords = records_;
    s.bytesWritten = bytesWritten_.load(std::memory_order_relaxed);
    s.syncs = syncs_.load(std::memory_order_relaxed);
    s.durableRecords = durableRecords_.load(std::memory_order_acquire);
    return s;
}

std::uint8_t* RecordingWriter::begin(RecordType type, Timestamp t, std::size_t payloadBytes) {
    if (error() != 0 || closed_ || payloadBytes > kMaxPayloadBytes) {
        return nullptr;
    }
    const std::size_t total = kRecordOverheadBytes + payloadBytes;
    if (active_->used + total > active_->bytes.size()) {
        if (handOff(false) < 0) {
            return nullptr;
        }
        if (total > active_->bytes.size()) {
            active_->bytes.resize(total);  // a rare oversize record (metadata); not per sample
        }
    }
    std::uint8_t* r = active_->bytes.data() + active_->used;
    putRecordHeader(r, type, toNs(t), payloadBytes);
    recordStart_ = active_->used;
    active_->used += total;
    return r + kRecordHeaderBytes;
}

int RecordingWriter::end() {
    putRecordCrc(active_->bytes.data() + recordStart_);
    active_->tailStarts[active_->records % kTailRecords] = static_cast<std::uint32_t>(recordStart_);
    ++active_->records;
    ++records_;
    if (clock_.now() - lastSync_ >= options_.syncInterval) {
        return handOff(true);
    }
    return 0;
}

int RecordingWriter::handOff(bool sync) {
    if (sync) {
        lastSync_ = clock_.now();
    }
    if (int e = error(); e != 0) {
        return e;
    }
    if (closed_) {
        return -EBADF;
    }
    if (active_->used == 0 && !(sync && unsynced_)) {
        return 0;  // nothing to write or to make durable
    }
    active_->sync = sync;
    unsynced_ = !sync;
    std::unique_lock lock(mutex_);
    queued_.push_back(active_);
    ioWake_.notify_one();
    // The I/O thread returns every buffer it takes, even after an error.
    callerWake_.wait(lock, [this] { return !free_.empty(); });
    active_ = free_.back();
    free_.pop_back();
    lock.unlock();
    return error();
}

void RecordingWriter::rememberTail(std::uint64_t offset, std::int64_t tNs) {
    if (tailCount_ == kTailRecords) {
        std::move(tail_.begin() + 1, tail_.end(), tail_.begin());
        --tailCount_;
    }
    tail_[tailCount_++] = {offset, tNs};
}

void RecordingWriter::writeOut(Buffer& b) {
    if (error() != 0) {
        return;  // the recording has stopped: later buffers are dropped
    }
    if (b.used > 0) {
        const std::uint64_t base = bytesWritten_.load(std::memory_order_relaxed);
        if (int r = writeAll(b.bytes.data(), b.used); r < 0) {
            stopAfterWriteError(b, base, r);
            return;
        }
        const std::uint64_t first = b.records > kTailRecords ? b.records - kTailRecords : 0;
        for (std::uint64_t k = first; k < b.records; ++k) {
            const std::uint32_t start = b.tailStarts[k % kTailRecords];
            rememberTail(base + start, static_cast<std::int64_t>(get64(&b.bytes[start + 12])));
        }
        writtenRecords_.fetch_add(b.records, std::memory_order_release);
    }
    if (b.sync) {
        if (::fdatasync(fd_.get()) < 0) {
            // What the kernel holds may or may not be on the disk: the error is the news.
            error_.store(-errno, std::memory_order_release);
            return;
        }
        syncs_.fetch_add(1, std::memory_order_relaxed);
        durableRecords_.store(writtenRecords_.load(std::memory_order_relaxed),
                              std::memory_order_release);
    }
}

void RecordingWriter::stopAfterWriteError(const Buffer& b, std::uint64_t base, int err) {
    // The kernel took the first bytes of b (a partial write), then refused: b's records that
    // fit whole are in the file, the next one is torn.
    const std::uint64_t fileEnd = bytesWritten_.load(std::memory_order_relaxed);
    const std::size_t taken = static_cast<std::size_t>(fileEnd - base);
    std::size_t s = 0;
    std::uint64_t complete = 0;
    while (s < b.used) {
        const std::size_t total = kRecordOverheadBytes + get32(&b.bytes[s + 8]);
        if (s + total > taken) {
            break;
        }
        rememberTail(base + s, static_cast<std::int64_t>(get64(&b.bytes[s + 12])));
        ++complete;
        s += total;
    }
    std::uint64_t written = writtenRecords_.load(std::memory_order_relaxed) + complete;
    const std::uint64_t completeEnd = base + s;  // where the torn record starts

    // The stop event, timed at the first record that is not in the file. The disk takes no new
    // byte, but the bytes it took are the file's: the event overwrites the torn record and, if
    // that is too short for it, the last complete records, which needs no new space (on a
    // file system that writes in place), and the file is cut after it.
    std::array<std::uint8_t, kMaxStopEventBytes> event{};
    const std::size_t eventBytes = kRecordOverheadBytes + kEventFixedBytes + kStopText.size();
    static_assert(kRecordOverheadBytes + kEventFixedBytes + kStopText.size() <= kMaxStopEventBytes);
    std::uint64_t at = completeEnd;
    std::int64_t tNs = static_cast<std::int64_t>(get64(&b.bytes[s + 12]));
    std::uint64_t replaced = 0;
    while (fileEnd - at < eventBytes && replaced < tailCount_) {
        const TailRecord& r = tail_[tailCount_ - 1 - replaced];
        at = r.offset;
        tNs = r.tNs;
        ++replaced;
    }
    if (fileEnd - at < eventBytes) {
        // Too few records to make room (the disk was full from the start): try past them.
        at = completeEnd;
        tNs = static_cast<std::int64_t>(get64(&b.bytes[s + 12]));
        replaced = 0;
    }
    putRecordHeader(event.data(), RecordType::Event, tNs, kEventFixedBytes + kStopText.size());
    std::uint8_t* p = event.data() + kRecordHeaderBytes;
    p[0] = static_cast<std::uint8_t>(EventKind::RecordingStopped);
    put16(p + 2, static_cast<std::uint16_t>(-1));
    put32(p + 4, static_cast<std::uint32_t>(err));
    std::copy(kStopText.begin(), kStopText.end(), p + kEventFixedBytes);
    putRecordCrc(event.data());

    ssize_t put = -1;
    do {
        put = ::pwrite(fd_.get(), event.data(), eventBytes, static_cast<off_t>(at));
    } while (put < 0 && errno == EINTR);
    if (put == static_cast<ssize_t>(eventBytes)) {
        written = written - replaced + 1;
        (void)::ftruncate(fd_.get(), static_cast<off_t>(at + eventBytes));
    } else if (put > 0) {
        // Half an event over the records it was to replace: they are gone, so is the event.
        written -= replaced;
        (void)::ftruncate(fd_.get(), static_cast<off_t>(at));
    } else {
        // Nothing written: at least the torn record goes, so the file ends on a record.
        (void)::ftruncate(fd_.get(), static_cast<off_t>(completeEnd));
    }
    writtenRecords_.store(written, std::memory_order_release);
    if (::fdatasync(fd_.get()) == 0) {
        syncs_.fetch_add(1, std::memory_order_relaxed);
        durableRecords_.store(written, std::memory_order_release);
    } else if (durableRecords_.load(std::memory_order_relaxed) > written) {
        durableRecords_.store(written, std::memory_order_release);
    }
    // Last: a caller that sees the error sees the final counts.
    error_.store(err, std::memory_order_release);
}

void RecordingWriter::ioLoop() {
    std::unique_lock lock(mutex_);
    for (;;) {
        ioWake_.wait(lock, [this] { return !queued_.empty() || stopping_; });
        if (queued_.empty()) {
            return;  // stopping, and everything queued is written
        }
        Buffer* b = queued_.front();
        queued_.erase(queued_.begin());
        ioBusy_ = true;
        lock.unlock();
        writeOut(*b);
        b->used = 0;
        b->records = 0;
        lock.lock();
        ioBusy_ = false;
        free_.push_back(b);
        callerWake_.notify_all();
    }
}

int RecordingWriter::flush(bool sync) {
    if (int r = handOff(sync); r < 0) {
        return r;
    }
    std::unique_lock lock(mutex_);
    callerWake_.wait(lock, [this] { return queued_.empty() && !ioBusy_; });
    return error();
}

int RecordingWriter::maybeSync() {
    if (error() == 0 && !closed_ && clock_.now() - lastSync_ >= options_.syncInterval) {
        return handOff(true);
    }
    return error();
}

int RecordingWriter::close() {
    if (closed_) {
        return error();
    }
    if (io_.joinable()) {
        (void)handOff(true);
        {
            std::lock_guard lock(mutex_);
            stopping_ = true;
        }
        ioWake_.notify_one();
        io_.join();
    }
    closed_ = true;
    fd_.reset();
    return error();
}

int RecordingWriter::writeRawSample(int sensor, const hal::ImuSample& s) {
    std::uint8_t* p = begin(RecordType::RawSample, s.t, kRawSampleBytes);
    if (p == nullptr) {
        return refusal();
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
        return refusal();
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
                               std::span<const Eigen::Quaternionf> joints,
                               std::uint32_t notMeasured) {
    std::uint8_t* p = begin(RecordType::Pose, t, kPoseFixedBytes + 16 * joints.size() + 4);
    if (p == nullptr) {
        return refusal();
    }
    put16(p, static_cast<std::uint16_t>(joints.size()));
    put16(p + 2, kPoseHasNotMeasured);
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
    put32(q, notMeasured);
    return end();
}

int RecordingWriter::writeEvent(Timestamp t, EventKind kind, int sensor, int error,
                                std::string_view text) {
    std::uint8_t* p = begin(RecordType::Event, t, kEventFixedBytes + text.size());
    if (p == nullptr) {
        return refusal();
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
        return refusal();
    }
    std::copy(toml.begin(), toml.end(), p);
    return end();
}

int RecordingWriter::writeMarker(Timestamp t, std::string_view label) {
    std::uint8_t* p = begin(RecordType::Marker, t, label.size());
    if (p == nullptr) {
        return refusal();
    }
    std::copy(label.begin(), label.end(), p);
    return end();
}

}  // namespace caphub::firmware
