// Writes a .cap recording without losing data: records are framed into preallocated buffers
// (no allocation per record); a full buffer, or the current one when the sync interval has
// passed, goes to the writer's own I/O thread, which writes it out and makes it durable
// (fdatasync), so a power cut loses at most about that interval and the thread that records
// never waits for the disk (unless every buffer is in flight: the disk is slower than the data).
// A write error such as a full disk stops the recording cleanly: the file ends with a
// "recording stopped" event in place of its last records (docs/recording-format.md), what was
// written stays readable, and later calls report the error.
#pragma once

#include <array>
#include <atomic>
#include <condition_variable>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include <Eigen/Geometry>

#include "firmware/recording/format.h"
#include "hal/core/clock.h"
#include "hal/core/error.h"
#include "hal/imu_sample.h"
#include "hal/linux/unique_fd.h"

namespace caphub::firmware {

struct WriterOptions {
    Duration syncInterval = std::chrono::milliseconds(200);  // the most a power cut may lose
    std::size_t bufferBytes = 256 * 1024;                    // each of kWriterBuffers
};

// Buffers per writer: one being filled, the others queued for or in the I/O thread.
inline constexpr int kWriterBuffers = 4;

struct WriterStats {
    // Complete records in the file (handed to the kernel whole; after a write error, without
    // the torn one and those the stop event took the place of, with the stop event): what a
    // reader reads back once the writer is closed.
    std::uint64_t records = 0;
    std::uint64_t acceptedRecords = 0;  // records the caller wrote, in the file or still queued
    std::uint64_t bytesWritten = 0;     // handed to the kernel
    std::uint64_t syncs = 0;
    std::uint64_t durableRecords = 0;  // records covered by the last fdatasync
};

class RecordingWriter {
public:
    // Creates the file (refusing to overwrite one) and writes the header with its metadata
    // (TOML text: board, skeleton, calibration, software version).
    static Result<std::unique_ptr<RecordingWriter>> create(const std::string& path,
                                                           std::string_view metadataToml,
                                                           const WriterOptions& options = {});
    ~RecordingWriter();

    [[nodiscard]] int writeRawSample(int sensor, const hal::ImuSample& s);
    [[nodiscard]] int writeOrientation(int sensor, Timestamp t, const Eigen::Quaternionf& q);
    // notMeasured: bit j set when joint j's segment had no sensor reading (at most 32 joints).
    [[nodiscard]] int writePose(Timestamp t, const Eigen::Vector3f& rootM,
                                std::span<const Eigen::Quaternionf> jointRotations,
                                std::uint32_t notMeasured = 0);
    [[nodiscard]] int writeEvent(Timestamp t, cap::EventKind kind, int sensor, int error,
                                 std::string_view text);
    [[nodiscard]] int writeMetadata(Timestamp t, std::string_view toml);
    [[nodiscard]] int writeMarker(Timestamp t, std::string_view label);

    // Writes out what is buffered, and with sync also makes it durable; returns when done.
    // The writes themselves hand buffers to the I/O thread without waiting.
    [[nodiscard]] int flush(bool sync);
    // Hands the buffer over to be written and synced when the sync interval has passed: call
    // it when idle, so the bound holds even when no records arrive.
    [[nodiscard]] int maybeSync();
    // Flushes, syncs, stops the I/O thread and closes. Safe to call twice.
    [[nodiscard]] int close();

    // 0, or the -errno that stopped the recording (-ENOSPC: the disk is full).
    int error() const { return error_.load(std::memory_order_acquire); }
    // A snapshot: what reached the file and the disk, and what the caller handed over.
    WriterStats stats() const;
    const std::string& path() const { return path_; }

private:
    // Where the last few complete records start: after a write error the stop event takes the
    // place of as many of them as it needs (every record is at least 24 bytes, the event at most
    // kMaxStopEventBytes).
    static constexpr std::size_t kTailRecords = 4;
    static constexpr std::size_t kMaxStopEventBytes = 64;

    struct Buffer {
        std::vector<std::uint8_t> bytes;
        std::size_t used = 0;
        std::uint64_t records = 0;
        std::array<std::uint32_t, kTailRecords> tailStarts{};  // ring, by records % kTailRecords
        bool sync = false;
    };
    struct TailRecord {
        std::uint64_t offset = 0;  // in the file
        std::int64_t tNs = 0;
    };

    RecordingWriter(std::string path, hal::UniqueFd fd, const WriterOptions& options);

    // Reserves a framed record of payloadBytes in the buffer; returns its payload or nullptr.
    std::uint8_t* begin(cap::RecordType type, Timestamp t, std::size_t payloadBytes);
    int end();
    // Why begin() refused a record: the error that stopped the recording, or -EINVAL.
    int refusal() const { return error() != 0 ? error() : -EINVAL; }
    // Queues the current buffer for the I/O thread (with sync: and an fdatasync after it) and
    // takes a free one, waiting only when none is free.
    int handOff(bool sync);
    void ioLoop();
    void writeOut(Buffer& b);
    // After a write error while writing b from file offset base: counts b's complete records,
    // puts the stop event in place of the torn record (and of as many complete ones before it as
    // it needs) and cuts the file after it.
    void stopAfterWriteError(const Buffer& b, std::uint64_t base, int err);
    void rememberTail(std::uint64_t offset, std::int64_t tNs);
    int writeAll(const std::uint8_t* data, std::size_t n);

    std::string path_;
    hal::UniqueFd fd_;
    WriterOptions options_;
    MonotonicClock clock_;
    std::atomic<int> error_{0};

    // The recording thread's side.
    std::array<Buffer, kWriterBuffers> buffers_;
    Buffer* active_ = nullptr;
    std::size_t recordStart_ = 0;
    std::uint64_t records_ = 0;
    Timestamp lastSync_{};
    bool unsynced_ = false;  // buffers handed off since the last sync
    bool closed_ = false;

    // Between the two threads.
    std::mutex mutex_;
    std::condition_variable ioWake_;
    std::condition_variable callerWake_;
    std::vector<Buffer*> queued_;  // in order; capacity reserved for every buffer
    std::vector<Buffer*> free_;
    bool ioBusy_ = false;
    bool stopping_ = false;
    std::thread io_;

    // The I/O thread's side.
    std::atomic<std::uint64_t> writtenRecords_{0};
    std::array<TailRecord, kTailRecords> tail_{};  // the file's last complete records, oldest first
    std::size_t tailCount_ = 0;
    std::atomic<std::uint64_t> bytesWritten_{0};
    std::atomic<std::uint64_t> syncs_{0};
    std::atomic<std::uint64_t> durableRecords_{0};
};

}  // namespace caphub::firmware
