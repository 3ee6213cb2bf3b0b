// The bit-identity check of the fixed-point filter: a shipped BROAD excerpt in, the raw int32
// state (quaternion and gyroscope bias) after every sample out, hashed with FNV-1a 64. Shared by
// the golden test and by caphub_fixed_golden, the tool that writes the golden hashes on x86-64.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "fusion/evaluation.h"
#include "hal/core/error.h"

namespace caphub::fusion::golden {

// Paths relative to tests/data (tests/data/README.md, "fusion/").
inline constexpr const char* kInputName = "fusion/24_tapping_excerpt.csv.gz";
inline constexpr const char* kGoldenName = "fusion/fixed_golden.txt";
// The excerpt's sample rate (its comment line): the filter's three rates.
inline constexpr double kRateHz = 285.714286;
// A checkpoint hash every this many samples, so that a mismatch says where the runs part.
inline constexpr std::size_t kCheckpointSamples = 256;
// Raw int32 values per sample: quaternion w, x, y, z (Q30), then bias x, y, z (Q30 rad/s).
inline constexpr std::size_t kValuesPerSample = 7;

// Reads a gzip or plain CSV with the columns t,gyr_x,gyr_y,gyr_z,acc_x,acc_y,acc_z,mag_x,mag_y,
// mag_z (more columns are ignored); '#' lines and the header line are skipped. Errors name the
// file, the line and what was expected there.
Result<std::vector<ImuSample>> readExcerpt(const std::string& path);

// Runs OrientationFilter<FixedTypes> at kRateHz over the samples (gyroscope, accelerometer,
// magnetometer update per sample) and returns kValuesPerSample raw values per sample.
std::vector<std::int32_t> runFixedRaw(const std::vector<ImuSample>& samples);

// FNV-1a, 64-bit: offset basis 0xcbf29ce484222325, prime 0x100000001b3.
class Fnv1a64 {
public:
    void addByte(std::uint8_t b) {
        hash_ ^= b;
        hash_ *= 0x100000001b3ULL;
    }
    // Little-endian bytes of the two's complement value, whatever the host's byte order.
    void addInt32(std::int32_t v);
    void addBytes(const std::string& s);
    std::uint64_t value() const { return hash_; }

private:
    std::uint64_t hash_ = 0xcbf29ce484222325ULL;
};

// One line of the golden file: the hash of the first `samples` samples' raw state.
struct Checkpoint {
    std::size_t samples = 0;
    std::uint64_t hash = 0;
    friend bool operator==(const Checkpoint&, const Checkpoint&) = default;
};

// Checkpoints every kCheckpointSamples samples and one at the end (raw: runFixedRaw's output).
std::vector<Checkpoint> checkpoints(const std::vector<std::int32_t>& raw);

// The golden file: '#' comment lines, then "hash SAMPLES HEX16" lines in increasing order.
std::string formatGolden(const std::vector<Checkpoint>& points, const std::string& comment);
Result<std::vector<Checkpoint>> readGolden(const std::string& path);

}  // namespace caphub::fusion::golden
