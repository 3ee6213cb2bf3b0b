// The .cap recording: round trips, and what a person relies on when things go wrong: a torn or
// bit-flipped file reads up to the damage and past it, a full disk stops cleanly, and a process
// killed at any moment leaves every record up to the last durable point.
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include "firmware/recording/crc32c.h"
#include "firmware/recording/reader.h"
#include "firmware/recording/writer.h"

namespace caphub::firmware {
namespace {

namespace fs = std::filesystem;

std::string tempPath(const std::string& name) {
    const fs::path dir = fs::path(::testing::TempDir()) / "caphub-recording-test";
    fs::create_directories(dir);
    const fs::path p = dir / (name + "-" + std::to_string(::getpid()) + ".cap");
    fs::remove(p);
    return p.string();
}

std::vector<std::uint8_t> readFile(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), {}};
}

void writeFile(const std::string& path, const std::vector<std::uint8_t>& bytes) {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(bytes.data()),
              static_cast<std::streamsize>(bytes.size()));
}

hal::ImuSample sample(int seq) {
    hal::ImuSample s;
    s.t = timestampFromNs(1'000'000'000 + seq * 5'000'000LL);
    s.accMps2 = {0.1f * static_cast<float>(seq), -9.81f, 0.5f};
    s.gyrRadps = {0.01f, 0.02f * static_cast<float>(seq), -0.03f};
    s.magUt = {20, -30, 40};
    s.temperatureC = static_cast<float>(seq);  // exact up to 2^24: a sequence number
    s.flags = hal::ImuSample::kMagFresh;
    return s;
}

// All records of a file with their sequence numbers (raw samples) and the reader's damage.
struct ReadBack {
    std::vector<int> seqs;
    std::vector<Damage> damage;
    std::uint64_t tornTail = 0;
    int otherRecords = 0;
};

ReadBack readBack(const std::string& path) {
    ReadBack out;
    auto r = RecordingReader::open(path);
    if (!r.ok()) {
        ADD_FAILURE() << r.error().message;
        return out;
    }
    RecordView v;
    while ((*r)->next(v) == 1) {
        int sensor = 0;
        hal::ImuSample s;
        if (decodeRawSample(v, sensor, s)) {
            out.seqs.push_back(static_cast<int>(s.temperatureC));
            EXPECT_EQ(s.t, sample(static_cast<int>(s.temperatureC)).t);
        } else {
            ++out.otherRecords;
        }
    }
    out.damage = (*r)->damage();
    out.tornTail = (*r)->tornTailBytes();
    return out;
}

TEST(Crc32c, MatchesTheStandardCheckValue) {
    // The CRC-32C check value of "123456789" (RFC 3720, iSCSI).
    const std::string s = "123456789";
    EXPECT_EQ(crc32c(std::span(reinterpret_cast<const std::uint8_t*>(s.data()), s.size())),
              0xE3069283u);
    // Continuing a CRC equals computing it in one go.
    const auto* p = reinterpret_cast<const std::uint8_t*>(s.data());
    EXPECT_EQ(crc32c(std::span(p + 4, 5), crc32c(std::span(p, 4))), 0xE3069283u);
}

TEST(Recording, APoseCarriesWhichJointsWereNotMeasured) {
    const std::string path = tempPath("not-measured");
    const std::vector<Eigen::Quaternionf> joints(21, Eigen::Quaternionf::Identity());
    {
        auto w = RecordingWriter::create(path, "");
        ASSERT_TRUE(w.ok()) << w.error().message;
        ASSERT_EQ((*w)->writePose(timestampFromNs(1), {0, 1, 0}, joints), 0);
        ASSERT_EQ((*w)->writePose(timestampFromNs(2), {0, 1, 0}, joints, (1u << 5) | (1u << 20)),
                  0);
        ASSERT_EQ((*w)->close(), 0);
    }
    auto r = RecordingReader::open(path);
    ASSERT_TRUE(r.ok());
    EXPECT_EQ((*r)->version(), cap::kVersion);
    RecordView v;
    Eigen::Vector3f root;
    std::vector<Eigen::Quaternionf> got;
    std::uint32_t mask = 99;
    ASSERT_EQ((*r)->next(v), 1);
    ASSERT_TRUE(decodePose(v, root, got, &mask));
    EXPECT_EQ(mask, 0u);
    ASSERT_EQ((*r)->next(v), 1);
    ASSERT_TRUE(decodePose(v, root, got, &mask));
    EXPECT_EQ(mask, (1u << 5) | (1u << 20));
    EXPECT_EQ(got.size(), 21u);
}

TEST(Recording, AVersionOnePoseReadsAsEveryJointMeasured) {
    // The version-1 layout: flags 0, no mask after the joints.
    std::vector<std::uint8_t> payload(cap::kPoseFixedBytes + 16 * 2, 0);
    cap::put16(payload.data(), 2);
    cap::putF32(payload.data() + 4, 1.5f);
    RecordView v;
    v.type = cap::RecordType::Pose;
    v.payload = payload;
    Eigen::Vector3f root;
    std::vector<Eigen::Quaternionf> joints;
    std::uint32_t mask = 99;
    ASSERT_TRUE(decodePose(v, root, joints, &mask));
    EXPECT_EQ(mask, 0u);
    EXPECT_EQ(root.x(), 1.5f);
    // A flag this reader does not know, or a length that does not match the flags: malformed.
    cap::put16(payload.data() + 2, 2);
    EXPECT_FALSE(decodePose(v, root, joints, &mask));
    cap::put16(payload.data() + 2, cap::kPoseHasNotMeasured);
    EXPECT_FALSE(decodePose(v, root, joints, &mask));
}

TEST(Recording, RoundTripsEveryRecordType) {
    const std::string path = tempPath("roundtrip");
    {
        auto w = RecordingWriter::create(path, "[board]\nname = \"test\"\n");
        ASSERT_TRUE(w.ok()) << w.error().message;
        ASSERT_EQ((*w)->writeRawSample(3, sample(7)), 0);
        ASSERT_EQ((*w)->writeOrientation(2, timestampFromNs(42),
                                         Eigen::Quaternionf(0.5f, 0.5f, -0.5f, 0.5f)),
                  0);
        const std::vector<Eigen::Quaternionf> joints = {Eigen::Quaternionf::Identity(),
                                                        Eigen::Quaternionf(0, 1, 0, 0)};
        ASSERT_EQ((*w)->writePose(timestampFromNs(43), {1, 2, 3}, joints), 0);
        ASSERT_EQ(
            (*w)->writeEvent(timestampFromNs(44), cap::EventKind::SensorLost, 5, -ENXIO, "l_hand"),
            0);
        ASSERT_EQ((*w)->writeMarker(timestampFromNs(45), "jump"), 0);
        ASSERT_EQ((*w)->writeMetadata(timestampFromNs(46), "[calibration]\n"), 0);
        ASSERT_EQ((*w)->close(), 0);
        EXPECT_EQ((*w)->stats().records, 6u);
        EXPECT_EQ((*w)->stats().durableRecords, 6u);
    }
    auto r = RecordingReader::open(path);
    ASSERT_TRUE(r.ok());
    EXPECT_EQ((*r)->metadata(), "[board]\nname = \"test\"\n");
    RecordView v;
    ASSERT_EQ((*r)->next(v), 1);
    int sensor = 0;
    hal::ImuSample s;
    ASSERT_TRUE(decodeRawSample(v, sensor, s));
    EXPECT_EQ(sensor, 3);
    EXPECT_EQ(s.accMps2, sample(7).accMps2);
    EXPECT_EQ(s.t, sample(7).t);
    ASSERT_EQ((*r)->next(v), 1);
    Eigen::Quaternionf q;
    ASSERT_TRUE(decodeOrientation(v, sensor, q));
    EXPECT_EQ(sensor, 2);
    EXPECT_EQ(q.coeffs(), Eigen::Quaternionf(0.5f, 0.5f, -0.5f, 0.5f).coeffs());
    ASSERT_EQ((*r)->next(v), 1);
    Eigen::Vector3f root;
    std::vector<Eigen::Quaternionf> joints;
    ASSERT_TRUE(decodePose(v, root, joints));
    EXPECT_EQ(root, Eigen::Vector3f(1, 2, 3));
    ASSERT_EQ(joints.size(), 2u);
    EXPECT_EQ(joints[1].x(), 1.0f);
    ASSERT_EQ((*r)->next(v), 1);
    cap::EventKind kind{};
    int err = 0;
    std::string text;
    ASSERT_TRUE(decodeEvent(v, kind, sensor, err, text));
    EXPECT_EQ(kind, cap::EventKind::SensorLost);
    EXPECT_EQ(err, -ENXIO);
    EXPECT_EQ(text, "l_hand");
    ASSERT_EQ((*r)->next(v), 1);
    EXPECT_EQ(v.type, cap::RecordType::Marker);
    ASSERT_EQ((*r)->next(v), 1);
    EXPECT_EQ(v.type, cap::RecordType::Metadata);
    EXPECT_EQ((*r)->next(v), 0);
    EXPECT_TRUE((*r)->damage().empty());
    EXPECT_EQ((*r)->tornTailBytes(), 0u);
}

TEST(Recording, RefusesToOverwriteAFile) {
    const std::string path = tempPath("exists");
    ASSERT_TRUE(RecordingWriter::create(path, "").ok());
    const auto again = RecordingWriter::create(path, "");
    ASSERT_FALSE(again.ok());
    EXPECT_THAT(again.error().message, ::testing::HasSubstr("File exists"));
}

TEST(Recording, RefusesToReplaceADanglingSymlink) {
    const std::string path = tempPath("dangling");
    const std::string target = path + ".nowhere";
    fs::remove(target);
    fs::create_symlink(target, path);
    const auto w = RecordingWriter::create(path, "");
    ASSERT_FALSE(w.ok());
    EXPECT_THAT(w.error().message, ::testing::HasSubstr("File exists"));
    EXPECT_TRUE(fs::is_symlink(path));
    EXPECT_FALSE(fs::exists(target));
    fs::remove(path);
}

// The file takes its name only with its header on the disk (docs/recording-format.md): what a
// crash before that left under the hidden name is replaced, and nothing is left beside it.
TEST(Recording, AppearsUnderItsNameWithItsHeaderAndLeavesNothingBeside) {
    const std::string path = tempPath("appears");
    const fs::path p(path);
    const fs::path creating = p.parent_path() / ("." + p.filename().string() + ".creating");
    writeFile(creating.string(), {'t', 'o', 'r', 'n'});
    {
        auto w = RecordingWriter::create(path, "a = 1\n");
        ASSERT_TRUE(w.ok()) << w.error().message;
        EXPECT_FALSE(fs::exists(creating));
        EXPECT_TRUE(RecordingReader::open(path).ok());  // the header is there from the start
        ASSERT_EQ((*w)->writeRawSample(0, sample(0)), 0);
        ASSERT_EQ((*w)->close(), 0);
    }
    EXPECT_EQ(readBack(path).seqs, std::vector<int>{0});
    EXPECT_FALSE(fs::exists(creating));
}

TEST(Recording, ANonRecordingIsRefusedClearly) {
    const std::string path = tempPath("notcap");
    writeFile(path, {'h', 'e', 'l', 'l', 'o', ' ', 'w', 'o', 'r', 'l', 'd',
                     '!', '!', '!', '!', '!', '!', '!', '!', '!', '!'});
    const auto r = RecordingReader::open(path);
    ASSERT_FALSE(r.ok());
    EXPECT_THAT(r.error().message, ::testing::HasSubstr("not a caphub recording"));
}

// Writes n raw samples and returns the file's bytes and each record's end offset.
std::vector<std::uint8_t> smallRecording(const std::string& path, int n,
                                         std::vector<std::size_t>& recordEnds) {
    auto w = RecordingWriter::create(path, "name = \"cut\"\n");
    EXPECT_TRUE(w.ok());
    const std::size_t header = cap::kHeaderFixedBytes + std::string("name = \"cut\"\n").size();
    for (int i = 0; i < n; ++i) {
        EXPECT_EQ((*w)->writeRawSample(0, sample(i)), 0);
        recordEnds.push_back(header + (i + 1) * (cap::kRecordOverheadBytes + cap::kRawSampleBytes));
    }
    EXPECT_EQ((*w)->close(), 0);
    return readFile(path);
}

TEST(Recording, TruncatedAtEveryByteReadsEveryCompleteRecordBeforeTheCut) {
    const std::string path = tempPath("full");
    std::vector<std::size_t> ends;
    const auto bytes = smallRecording(path, 12, ends);
    ASSERT_EQ(bytes.size(), ends.back());
    const std::string cutPath = tempPath("cut");
    const std::size_t headerEnd = ends.front() - (cap::kRecordOverheadBytes + cap::kRawSampleBytes);
    for (std::size_t cut = 0; cut <= bytes.size(); ++cut) {
        writeFile(cutPath,
                  std::vector<std::uint8_t>(bytes.begin(), bytes.begin() + static_cast<long>(cut)));
        auto r = RecordingReader::open(cutPath);
        if (cut < cap::kHeaderFixedBytes) {
            EXPECT_FALSE(r.ok()) << "cut at " << cut;  // not even a header: refused, no crash
            continue;
        }
        ASSERT_TRUE(r.ok()) << "cut at " << cut;
        const ReadBack rb = readBack(cutPath);
        const auto complete = static_cast<int>(
            std::count_if(ends.begin(), ends.end(), [&](std::size_t e) { return e <= cut; }));
        ASSERT_EQ(static_cast<int>(rb.seqs.size()), complete) << "cut at " << cut;
        for (int i = 0; i < complete; ++i) {
            ASSERT_EQ(rb.seqs[static_cast<std::size_t>(i)], i) << "cut at " << cut;
        }
        if (cut >= headerEnd) {
            // A torn tail is not damage; it is reported as such.
            EXPECT_TRUE(rb.damage.empty()) << "cut at " << cut;
            const bool onBoundary =
                cut == headerEnd || std::find(ends.begin(), ends.end(), cut) != ends.end();
            EXPECT_EQ(rb.tornTail == 0, onBoundary) << "cut at " << cut;
        }
    }
}

TEST(Recording, AFlippedBitLosesOnlyItsRecord) {
    const std::string path = tempPath("flip-src");
    std::vector<std::size_t> ends;
    const auto bytes = smallRecording(path, 12, ends);
    const std::string flipped = tempPath("flip");
    std::mt19937 rng(3);
    for (int trial = 0; trial < 200; ++trial) {
        const int victim = static_cast<int>(rng() % 12);
        const std::size_t start = ends[static_cast<std::size_t>(victim)] -
                                  (cap::kRecordOverheadBytes + cap::kRawSampleBytes);
        const std::size_t offset =
            start + rng() % (cap::kRecordOverheadBytes + cap::kRawSampleBytes);
        auto damaged = bytes;
        damaged[offset] ^= static_cast<std::uint8_t>(1u << (rng() % 8));
        writeFile(flipped, damaged);
        const ReadBack rb = readBack(flipped);
        ASSERT_EQ(rb.seqs.size(), 11u) << "flip at " << offset;
        for (int i = 0, k = 0; i < 12; ++i) {
            if (i != victim) {
                ASSERT_EQ(rb.seqs[static_cast<std::size_t>(k++)], i);
            }
        }
        // Reported as damage at the record; the last record with a length made too long is
        // indistinguishable from a record cut short, and is reported as a torn tail instead.
        if (rb.damage.empty()) {
            EXPECT_EQ(victim, 11) << "flip at " << offset;
            EXPECT_GT(rb.tornTail, 0u);
        } else {
            ASSERT_EQ(rb.damage.size(), 1u);
            EXPECT_EQ(rb.damage[0].offset, start);
        }
    }
}

TEST(Recording, ADamagedHeaderStillGivesTheRecords) {
    const std::string path = tempPath("hdr-src");
    std::vector<std::size_t> ends;
    auto bytes = smallRecording(path, 5, ends);
    bytes[cap::kHeaderFixedBytes + 2] ^= 0x40;  // inside the metadata
    writeFile(path, bytes);
    auto r = RecordingReader::open(path);
    ASSERT_TRUE(r.ok());
    EXPECT_TRUE((*r)->metadata().empty());
    ASSERT_FALSE((*r)->damage().empty());
    EXPECT_THAT((*r)->damage()[0].what, ::testing::HasSubstr("header"));
    EXPECT_EQ(readBack(path).seqs.size(), 5u);
}

TEST(Recording, AFullDiskStopsTheRecordingCleanly) {
    const std::string path = tempPath("full-disk");
    const pid_t child = ::fork();
    ASSERT_GE(child, 0);
    if (child == 0) {
        // A file size limit stands in for a full disk: write() fails (EFBIG) the same way.
        ::signal(SIGXFSZ, SIG_IGN);
        rlimit lim{40'000, 40'000};
        ::setrlimit(RLIMIT_FSIZE, &lim);
        WriterOptions options;
        options.bufferBytes = 4096;
        auto w = RecordingWriter::create(path, "", options);
        if (!w.ok()) {
            ::_exit(10);
        }
        int r = 0;
        int i = 0;
        for (; i < 10'000 && r == 0; ++i) {
            r = (*w)->writeRawSample(0, sample(i));
        }
        const bool stopped =
            r == -EFBIG && (*w)->error() == -EFBIG && (*w)->writeRawSample(0, sample(i)) == -EFBIG;
        ::_exit(stopped ? 0 : 11);
    }
    int status = 0;
    ::waitpid(child, &status, 0);
    ASSERT_TRUE(WIFEXITED(status));
    ASSERT_EQ(WEXITSTATUS(status), 0);
    const ReadBack rb = readBack(path);
    EXPECT_GT(rb.seqs.size(), 500u);
    for (std::size_t i = 0; i < rb.seqs.size(); ++i) {
        ASSERT_EQ(rb.seqs[i], static_cast<int>(i));
    }
    EXPECT_TRUE(rb.damage.empty());
}

// A recording that runs into a file size limit (a full disk, the same way: write() takes what
// fits, then fails) in a child process: the file and what the writer reported after close().
struct FullDiskRun {
    std::string path;
    std::uint64_t records = 0;  // WriterStats::records
    int error = 0;
};

FullDiskRun recordUntilFull(const std::string& name, rlim_t limitBytes) {
    FullDiskRun out;
    out.path = tempPath(name);
    int pipeFds[2];
    if (::pipe(pipeFds) != 0) {
        ADD_FAILURE() << "pipe";
        return out;
    }
    const pid_t child = ::fork();
    if (child == 0) {
        ::close(pipeFds[0]);
        ::signal(SIGXFSZ, SIG_IGN);
        rlimit lim{limitBytes, limitBytes};
        ::setrlimit(RLIMIT_FSIZE, &lim);
        auto w = RecordingWriter::create(out.path, "");
        if (!w.ok()) {
            ::_exit(10);
        }
        int r = 0;
        for (int i = 0; i < 100'000 && r == 0; ++i) {
            r = (*w)->writeRawSample(0, sample(i));
        }
        (void)(*w)->close();
        const std::uint64_t report[2] = {(*w)->stats().records,
                                         static_cast<std::uint64_t>(-(*w)->error())};
        ::_exit(::write(pipeFds[1], report, sizeof report) == sizeof report ? 0 : 11);
    }
    ::close(pipeFds[1]);
    std::uint64_t report[2] = {0, 0};
    const bool got = ::read(pipeFds[0], report, sizeof report) == sizeof report;
    ::close(pipeFds[0]);
    int status = 0;
    ::waitpid(child, &status, 0);
    EXPECT_TRUE(got && WIFEXITED(status) && WEXITSTATUS(status) == 0) << name;
    out.records = report[0];
    out.error = -static_cast<int>(report[1]);
    return out;
}

// The limits put the end of the file 64, 34 and 0 bytes into a 68-byte record (after the
// 20-byte header): the stop event (43 bytes) fits in the torn record, or takes the place of the
// last complete one.
constexpr rlim_t kFullDiskLimits[] = {20 + 587 * 68 + 64, 20 + 587 * 68 + 34, 20 + 588 * 68};

TEST(Recording, AfterAFullDiskTheRecordCountIsWhatTheFileHolds) {
    for (const rlim_t limit : kFullDiskLimits) {
        const FullDiskRun run = recordUntilFull("count-" + std::to_string(limit), limit);
        ASSERT_EQ(run.error, -EFBIG) << limit;
        const ReadBack rb = readBack(run.path);
        EXPECT_GT(rb.seqs.size(), 500u) << limit;
        EXPECT_EQ(run.records, rb.seqs.size() + static_cast<std::size_t>(rb.otherRecords))
            << "limit " << limit;
    }
}

TEST(Recording, AFullDiskEndsTheFileWithARecordingStoppedEvent) {
    for (const rlim_t limit : kFullDiskLimits) {
        const FullDiskRun run = recordUntilFull("stop-" + std::to_string(limit), limit);
        const ReadBack rb = readBack(run.path);
        EXPECT_TRUE(rb.damage.empty()) << limit;
        EXPECT_EQ(rb.tornTail, 0u) << limit;  // the event took the torn record's place
        EXPECT_LE(std::filesystem::file_size(run.path), limit);
        for (std::size_t i = 0; i < rb.seqs.size(); ++i) {
            ASSERT_EQ(rb.seqs[i], static_cast<int>(i)) << limit;
        }
        auto r = RecordingReader::open(run.path);
        ASSERT_TRUE(r.ok());
        RecordView v;
        RecordView last;
        std::vector<std::uint8_t> lastPayload;
        while ((*r)->next(v) == 1) {
            last = v;
            lastPayload.assign(v.payload.begin(), v.payload.end());
        }
        last.payload = lastPayload;
        cap::EventKind kind{};
        int sensor = 0;
        int err = 0;
        std::string text;
        ASSERT_TRUE(decodeEvent(last, kind, sensor, err, text)) << "limit " << limit;
        EXPECT_EQ(kind, cap::EventKind::RecordingStopped);
        EXPECT_EQ(sensor, -1);
        EXPECT_EQ(err, -EFBIG);
        EXPECT_EQ(text, "write error");
        // Timed at the first sample that is not in the file: the data ends there.
        EXPECT_EQ(last.t, sample(static_cast<int>(rb.seqs.size())).t) << limit;
    }
}

// kill -9 of a recording process at random moments: every record up to the last durable point
// reads back, in order, and nothing else appears.
TEST(Recording, KillNineAtTwentyRandomMomentsLosesNothingDurable) {
    std::mt19937 rng(2026);
    std::uint64_t durableTotal = 0;
    for (int trial = 0; trial < 20; ++trial) {
        const std::string path = tempPath("kill" + std::to_string(trial));
        int pipeFds[2];
        ASSERT_EQ(::pipe(pipeFds), 0);
        const pid_t child = ::fork();
        ASSERT_GE(child, 0);
        if (child == 0) {
            ::close(pipeFds[0]);
            WriterOptions options;
            options.syncInterval = std::chrono::milliseconds(5);
            options.bufferBytes = 8192;
            auto w = RecordingWriter::create(path, "", options);
            if (!w.ok()) {
                ::_exit(10);
            }
            std::uint64_t reported = 0;
            for (int i = 0;; ++i) {
                if ((*w)->writeRawSample(0, sample(i)) != 0) {
                    ::_exit(11);
                }
                const std::uint64_t durable = (*w)->stats().durableRecords;
                if (durable != reported) {
                    reported = durable;
                    // Told only after fdatasync returned: these records are on the disk.
                    if (::write(pipeFds[1], &reported, sizeof reported) != sizeof reported) {
                        ::_exit(12);
                    }
                }
                if (i % 64 == 0) {
                    ::usleep(200);
                }
            }
        }
        ::close(pipeFds[1]);
        ::usleep(static_cast<useconds_t>(30'000 + rng() % 120'000));
        ::kill(child, SIGKILL);
        int status = 0;
        ::waitpid(child, &status, 0);
        ASSERT_TRUE(WIFSIGNALED(status)) << "trial " << trial;
        std::uint64_t durable = 0;
        std::uint64_t v = 0;
        while (::read(pipeFds[0], &v, sizeof v) == sizeof v) {
            durable = v;
        }
        ::close(pipeFds[0]);
        if (!fs::exists(path)) {
            // Killed before it created the file (a slow start, e.g. under an emulator).
            ASSERT_EQ(durable, 0u) << "trial " << trial;
            continue;
        }
        const ReadBack rb = readBack(path);
        ASSERT_GE(rb.seqs.size(), durable) << "trial " << trial;
        for (std::size_t i = 0; i < rb.seqs.size(); ++i) {
            ASSERT_EQ(rb.seqs[i], static_cast<int>(i)) << "trial " << trial;
        }
        EXPECT_TRUE(rb.damage.empty()) << "trial " << trial;
        durableTotal += durable;
    }
    EXPECT_GT(durableTotal, 0u);  // the trials did reach durable points
}

}  // namespace
}  // namespace caphub::firmware
