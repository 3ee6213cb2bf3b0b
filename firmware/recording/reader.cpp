#include "firmware/recording/reader.h"

#include <algorithm>
#include <cerrno>

#include "firmware/recording/crc32c.h"
#include "hal/core/input_file.h"

namespace caphub::firmware {

using namespace cap;

namespace {
constexpr std::size_t kChunk = 64 * 1024;
}

Result<std::unique_ptr<RecordingReader>> RecordingReader::open(const std::string& path) {
    auto f = openInputFile(path);
    if (!f) {
        return Error{f.error().code, "cannot open recording: " + f.error().message};
    }
    return openStream(*f, path);
}

Result<std::unique_ptr<RecordingReader>> RecordingReader::fromMemory(
    std::span<const std::uint8_t> bytes) {
    if (bytes.empty()) {
        return Error{EINVAL, "an empty buffer is not a caphub recording"};
    }
    std::FILE* f = ::fmemopen(const_cast<std::uint8_t*>(bytes.data()), bytes.size(), "rb");
    if (f == nullptr) {
        return errnoError(errno, "fmemopen");
    }
    return openStream(f, "(memory)");
}

Result<std::unique_ptr<RecordingReader>> RecordingReader::openStream(std::FILE* f,
                                                                     std::string name) {
    const std::string path = name;
    std::unique_ptr<RecordingReader> r(new RecordingReader(f, std::move(name)));
    if (!r->want(kHeaderFixedBytes) || !std::equal(kMagic.begin(), kMagic.end(), r->buf_.begin())) {
        return Error{EINVAL, "'" + path + "' is not a caphub recording (no .cap header)"};
    }
    const std::uint8_t* h = r->buf_.data();
    r->version_ = get16(h + 8);
    if (r->version_ < kOldestReadableVersion || r->version_ > kVersion) {
        return Error{EINVAL, "recording '" + path + "' has format version " +
                                 std::to_string(r->version_) + "; this caphub reads versions " +
                                 std::to_string(kOldestReadableVersion) + " to " +
                                 std::to_string(kVersion)};
    }
    const std::uint32_t metaLen = get32(h + 12);
    const std::uint32_t storedCrc = get32(h + 16);
    bool headerOk = metaLen <= kMaxPayloadBytes && r->want(kHeaderFixedBytes + metaLen);
    if (headerOk) {
        h = r->buf_.data();
        std::uint32_t crc = crc32c(std::span(h, 16));
        crc = crc32c(std::span(h + kHeaderFixedBytes, metaLen), crc);
        headerOk = crc == storedCrc;
    }
    if (headerOk) {
        r->metadata_.assign(reinterpret_cast<const char*>(h + kHeaderFixedBytes), metaLen);
        r->pos_ = kHeaderFixedBytes + metaLen;
    } else {
        r->noteDamage(8, 8, "damaged header: metadata lost, records follow");
        r->pos_ = 8;
    }
    return r;
}

bool RecordingReader::want(std::size_t n) {
    while (buf_.size() - pos_ < n) {
        if (eof_) {
            return false;
        }
        // Drop what was consumed, then read another chunk.
        if (pos_ > 0) {
            buf_.erase(buf_.begin(), buf_.begin() + static_cast<std::ptrdiff_t>(pos_));
            bufOffset_ += pos_;
            pos_ = 0;
        }
        const std::size_t old = buf_.size();
        buf_.resize(old + kChunk);
        const std::size_t got = std::fread(buf_.data() + old, 1, kChunk, file_.get());
        buf_.resize(old + got);
        if (got < kChunk) {
            eof_ = true;
        }
    }
    return true;
}

void RecordingReader::noteDamage(std::uint64_t from, std::uint64_t to, std::string what) {
    damage_.push_back({from, to - from, std::move(what)});
}

std::size_t RecordingReader::validRecordAt(bool& incomplete) {
    incomplete = false;
    if (!want(kRecordHeaderBytes)) {
        incomplete = true;
        return 0;
    }
    const std::uint8_t* r = buf_.data() + pos_;
    if (!std::equal(kSync.begin(), kSync.end(), r) || !isKnownType(r[4])) {
        return 0;
    }
    const std::uint32_t len = get32(r + 8);
    if (len > kMaxPayloadBytes) {
        return 0;
    }
    const std::size_t total = kRecordOverheadBytes + len;
    if (!want(total)) {
        incomplete = true;
        return 0;
    }
    r = buf_.data() + pos_;
    const std::uint32_t crc = crc32c(std::span(r + 4, kRecordHeaderBytes - 4 + len));
    return crc == get32(r + kRecordHeaderBytes + len) ? total : 0;
}

int RecordingReader::next(RecordView& out) {
    std::uint64_t damageStart = 0;
    bool inDamage = false;
    for (;;) {
        bool incomplete = false;
        const std::size_t total = validRecordAt(incomplete);
        const std::uint64_t here = bufOffset_ + pos_;
        if (total > 0) {
            if (inDamage) {
                noteDamage(damageStart, here, "corrupt bytes skipped (bad marker, length or CRC)");
            }
            const std::uint8_t* r = buf_.data() + pos_;
            out.type = static_cast<RecordType>(r[4]);
            out.t = timestampFromNs(static_cast<std::int64_t>(get64(r + 12)));
            out.payload = std::span(r + kRecordHeaderBytes, get32(r + 8));
            out.offset = here;
            pos_ += total;
            return 1;
        }
        if (incomplete && eof_) {
            // Nothing valid can start here any more: if these bytes hold a sync marker, they are
            // the start of a record cut short; either way the file ends.
            const std::uint64_t end = bufOffset_ + buf_.size();
            if (inDamage) {
                noteDamage(damageStart, here, "corrupt bytes skipped (bad marker, length or CRC)");
            }
            // Scan the rest for a later valid record (a short damaged record before the tail).
            bool found = false;
            for (std::size_t p = pos_ + 1; p + kRecordOverheadBytes <= buf_.size(); ++p) {
                if (std::equal(kSync.begin(), kSync.end(), buf_.begin() + static_cast<long>(p))) {
                    const std::size_t save = pos_;
                    pos_ = p;
                    bool inc = false;
                    if (validRecordAt(inc) > 0) {
                        noteDamage(here, bufOffset_ + p, "corrupt bytes skipped");
                        found = true;
                        break;
                    }
                    pos_ = save;
                }
            }
            if (found) {
                inDamage = false;
                continue;
            }
            tornTail_ = end - here;
            pos_ = buf_.size();
            return 0;
        }
        if (!inDamage) {
            inDamage = true;
            damageStart = here;
        }
        ++pos_;  // resynchronise: try the next byte
        if (!want(1)) {
            noteDamage(damageStart, bufOffset_ + pos_, "corrupt bytes at the end");
            return 0;
        }
    }
}

bool decodeRawSample(const RecordView& r, int& sensor, hal::ImuSample& out) {
    if (r.type != RecordType::RawSample || r.payload.size() != kRawSampleBytes) {
        return false;
    }
    const std::uint8_t* p = r.payload.data();
    sensor = get16(p);
    out.t = r.t;
    out.flags = p[2];
    for (int i = 0; i < 3; ++i) {
        out.accMps2[i] = getF32(p + 4 + 4 * i);
        out.gyrRadps[i] = getF32(p + 16 + 4 * i);
        out.magUt[i] = getF32(p + 28 + 4 * i);
    }
    out.temperatureC = getF32(p + 40);
    return true;
}

bool decodeOrientation(const RecordView& r, int& sensor, Eigen::Quaternionf& q) {
    if (r.type != RecordType::Orientation || r.payload.size() != kOrientationBytes) {
        return false;
    }
    const std::uint8_t* p = r.payload.data();
    sensor = get16(p);
    q = Eigen::Quaternionf(getF32(p + 4), getF32(p + 8), getF32(p + 12), getF32(p + 16));
    return true;
}

bool decodePose(const RecordView& r, Eigen::Vector3f& rootM,
                std::vector<Eigen::Quaternionf>& joints, std::uint32_t* notMeasured) {
    if (r.type != RecordType::Pose || r.payload.size() < kPoseFixedBytes) {
        return false;
    }
    const std::uint8_t* p = r.payload.data();
    const std::size_t n = get16(p);
    const std::uint16_t flags = get16(p + 2);
    const bool hasMask = (flags & kPoseHasNotMeasured) != 0;
    if ((flags & ~kPoseHasNotMeasured) != 0 ||
        r.payload.size() != kPoseFixedBytes + 16 * n + (hasMask ? 4 : 0)) {
        return false;
    }
    rootM = Eigen::Vector3f(getF32(p + 4), getF32(p + 8), getF32(p + 12));
    joints.resize(n);
    const std::uint8_t* q = p + kPoseFixedBytes;
    for (std::size_t i = 0; i < n; ++i, q += 16) {
        joints[i] = Eigen::Quaternionf(getF32(q), getF32(q + 4), getF32(q + 8), getF32(q + 12));
    }
    if (notMeasured != nullptr) {
        *notMeasured = hasMask ? get32(q) : 0;
    }
    return true;
}

bool decodeEvent(const RecordView& r, EventKind& kind, int& sensor, int& error, std::string& text) {
    if (r.type != RecordType::Event || r.payload.size() < kEventFixedBytes) {
        return false;
    }
    const std::uint8_t* p = r.payload.data();
    kind = static_cast<EventKind>(p[0]);
    sensor = static_cast<std::int16_t>(get16(p + 2));
    error = static_cast<std::int32_t>(get32(p + 4));
    text.assign(reinterpret_cast<const char*>(p + kEventFixedBytes),
                r.payload.size() - kEventFixedBytes);
    return true;
}

}  // namespace caphub::firmware
