// Reads a .cap recording, also a damaged one: a record whose sync marker, length or CRC is wrong
// is skipped by scanning for the next sync marker that starts a valid record, and the damage is
// reported (offset and bytes skipped); a torn tail (a power cut mid-record) ends the file cleanly.
#pragma once

#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "firmware/recording/format.h"
#include "hal/core/error.h"
#include "hal/core/time.h"
#include "hal/imu_sample.h"

namespace caphub::firmware {

struct RecordView {
    cap::RecordType type = cap::RecordType::RawSample;
    Timestamp t{};
    std::span<const std::uint8_t> payload;  // valid until the next call to next()
    std::uint64_t offset = 0;               // of the record's sync marker in the file
};

struct Damage {
    std::uint64_t offset = 0;  // where the damaged bytes start
    std::uint64_t bytes = 0;   // how many were skipped
    std::string what;
};

class RecordingReader {
public:
    // Opens the file and reads the header. A damaged header is reported as damage and the
    // records are still read; only a file that is not a recording at all is refused.
    static Result<std::unique_ptr<RecordingReader>> open(const std::string& path);
    // The same over bytes in memory (the fuzz target; recordings received over a network).
    static Result<std::unique_ptr<RecordingReader>> fromMemory(std::span<const std::uint8_t> bytes);

    // The next valid record: 1, 0 at the end of the file, or -errno on a read error.
    [[nodiscard]] int next(RecordView& out);

    const std::string& metadata() const { return metadata_; }
    std::uint16_t version() const { return version_; }
    const std::vector<Damage>& damage() const { return damage_; }
    // Bytes at the end that were not a complete record (a torn tail).
    std::uint64_t tornTailBytes() const { return tornTail_; }

private:
    RecordingReader(std::FILE* file, std::string path) : file_(file), path_(std::move(path)) {}
    static Result<std::unique_ptr<RecordingReader>> openStream(std::FILE* file, std::string name);

    // Makes at least `n` bytes available from pos_; false at the end of the file.
    bool want(std::size_t n);
    // A valid record starting at pos_? Its total size, or 0.
    std::size_t validRecordAt(bool& incomplete);
    void noteDamage(std::uint64_t from, std::uint64_t to, std::string what);

    struct FileCloser {
        void operator()(std::FILE* f) const {
            if (f != nullptr) {
                std::fclose(f);
            }
        }
    };
    std::unique_ptr<std::FILE, FileCloser> file_;
    std::string path_;
    std::string metadata_;
    std::uint16_t version_ = 0;
    std::vector<std::uint8_t> buf_;
    std::size_t pos_ = 0;          // read position in buf_
    std::uint64_t bufOffset_ = 0;  // file offset of buf_[0]
    bool eof_ = false;
    std::vector<Damage> damage_;
    std::uint64_t tornTail_ = 0;
};

// Payload decoders: false when the payload does not have the type's layout.
bool decodeRawSample(const RecordView& r, int& sensor, hal::ImuSample& out);
bool decodeOrientation(const RecordView& r, int& sensor, Eigen::Quaternionf& q);
// notMeasured (optional): bit j set when joint j's segment had no sensor reading in this pose
// (its sensor out: the rotation is held from before); 0 for poses of version-1 files.
bool decodePose(const RecordView& r, Eigen::Vector3f& rootM,
                std::vector<Eigen::Quaternionf>& joints, std::uint32_t* notMeasured = nullptr);
bool decodeEvent(const RecordView& r, cap::EventKind& kind, int& sensor, int& error,
                 std::string& text);

}  // namespace caphub::firmware
