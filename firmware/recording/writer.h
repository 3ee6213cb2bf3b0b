// Writes a .cap recording without losing data: records are framed into a preallocated buffer
// (no allocation per record), written out when it fills, and made durable (fdatasync) at a
// bounded interval, so a power cut loses at most that interval. A write error such as a full
// disk stops the recording cleanly: what was written stays readable, and later calls report it.
#pragma once

#include <memory>
#include <span>
#include <string>
#include <string_view>
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
    std::size_t bufferBytes = 256 * 1024;
};

struct WriterStats {
    std::uint64_t records = 0;
    std::uint64_t bytesWritten = 0;  // handed to the kernel
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
    [[nodiscard]] int writePose(Timestamp t, const Eigen::Vector3f& rootM,
                                std::span<const Eigen::Quaternionf> jointRotations);
    [[nodiscard]] int writeEvent(Timestamp t, cap::EventKind kind, int sensor, int error,
                                 std::string_view text);
    [[nodiscard]] int writeMetadata(Timestamp t, std::string_view toml);
    [[nodiscard]] int writeMarker(Timestamp t, std::string_view label);

    // Writes out the buffer, and with sync also makes it durable. Called by the writes
    // themselves when the buffer is full or the sync interval has passed.
    [[nodiscard]] int flush(bool sync);
    // Writes out and syncs when the sync interval has passed: call it when idle, so the bound
    // holds even when no records arrive.
    [[nodiscard]] int maybeSync();
    // Flushes, syncs and closes. Safe to call twice.
    [[nodiscard]] int close();

    // 0, or the -errno that stopped the recording (-ENOSPC: the disk is full).
    int error() const { return error_; }
    const WriterStats& stats() const { return stats_; }
    const std::string& path() const { return path_; }

private:
    RecordingWriter(std::string path, hal::UniqueFd fd, const WriterOptions& options);

    // Reserves a framed record of payloadBytes in the buffer; returns its payload or nullptr.
    std::uint8_t* begin(cap::RecordType type, Timestamp t, std::size_t payloadBytes);
    int end();
    int writeAll(const std::uint8_t* data, std::size_t n);

    std::string path_;
    hal::UniqueFd fd_;
    WriterOptions options_;
    std::vector<std::uint8_t> buffer_;
    std::size_t used_ = 0;
    std::size_t recordStart_ = 0;
    std::uint64_t bufferedRecords_ = 0;
    std::uint64_t writtenRecords_ = 0;
    Timestamp lastSync_{};
    MonotonicClock clock_;
    WriterStats stats_;
    int error_ = 0;
};

}  // namespace caphub::firmware
