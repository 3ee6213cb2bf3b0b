// The .cap recording format (docs/recording-format.md): a versioned header with metadata, then
// framed records (sync marker, type, length, time, payload, CRC-32C), all little-endian.
#pragma once

#include <array>
#include <cstdint>
#include <cstring>
#include <span>
#include <string_view>

namespace caphub::firmware::cap {

inline constexpr std::array<std::uint8_t, 8> kMagic = {0x89, 'C', 'A', 'P', 0x0D, 0x0A, 0x1A, 0x0A};
// Version 2 adds the pose's flags and its mask of joints not measured; readers read 1 and 2.
inline constexpr std::uint16_t kVersion = 2;
inline constexpr std::uint16_t kOldestReadableVersion = 1;
inline constexpr std::size_t kHeaderFixedBytes = 20;  // magic, version, flags, length, CRC

inline constexpr std::array<std::uint8_t, 4> kSync = {0xC4, 0x7A, 0x2B, 0x91};
inline constexpr std::size_t kRecordHeaderBytes = 20;  // sync, type, flags, reserved, length, t
inline constexpr std::size_t kRecordOverheadBytes = kRecordHeaderBytes + 4;  // + CRC
inline constexpr std::uint32_t kMaxPayloadBytes = 1u << 20;

enum class RecordType : std::uint8_t {
    RawSample = 1,    // one IMU sample of one sensor
    Orientation = 2,  // one sensor's fused orientation
    Pose = 3,         // the body: root position and joint rotations
    Event = 4,        // sensor lost/found, calibration done, ...
    Metadata = 5,     // TOML text that updates the header's (e.g. a new calibration)
    Marker = 6,       // a user's marker, with a label
};

bool isKnownType(std::uint8_t type);
std::string_view typeName(RecordType type);

enum class EventKind : std::uint8_t {
    SensorOnline = 1,
    SensorLost = 2,
    SensorReset = 3,
    LineSilent = 4,
    Calibrated = 5,
    RecordingStopped = 6,  // e.g. the disk is full
    TakeStarted = 7,       // the take this file holds began (text: its name)
    TakeStopped = 8,       // the take ended as asked (the file's last record)
    HeadingReset = 9,      // the body's heading was reset (text: what was done)
    Command = 10,          // a command reached the running capture (text: which, and its result)
};

std::string_view eventName(EventKind kind);

// Little-endian field access.
inline void put16(std::uint8_t* p, std::uint16_t v) {
    p[0] = static_cast<std::uint8_t>(v);
    p[1] = static_cast<std::uint8_t>(v >> 8);
}
inline void put32(std::uint8_t* p, std::uint32_t v) {
    for (int i = 0; i < 4; ++i) {
        p[i] = static_cast<std::uint8_t>(v >> (8 * i));
    }
}
inline void put64(std::uint8_t* p, std::uint64_t v) {
    for (int i = 0; i < 8; ++i) {
        p[i] = static_cast<std::uint8_t>(v >> (8 * i));
    }
}
inline void putF32(std::uint8_t* p, float v) {
    std::uint32_t u = 0;
    std::memcpy(&u, &v, 4);
    put32(p, u);
}
inline std::uint16_t get16(const std::uint8_t* p) {
    return static_cast<std::uint16_t>(p[0] | (p[1] << 8));
}
inline std::uint32_t get32(const std::uint8_t* p) {
    std::uint32_t v = 0;
    for (int i = 3; i >= 0; --i) {
        v = (v << 8) | p[i];
    }
    return v;
}
inline std::uint64_t get64(const std::uint8_t* p) {
    std::uint64_t v = 0;
    for (int i = 7; i >= 0; --i) {
        v = (v << 8) | p[i];
    }
    return v;
}
inline float getF32(const std::uint8_t* p) {
    const std::uint32_t u = get32(p);
    float v = 0;
    std::memcpy(&v, &u, 4);
    return v;
}

// Payload sizes.
inline constexpr std::size_t kRawSampleBytes = 44;
inline constexpr std::size_t kOrientationBytes = 20;
inline constexpr std::size_t kPoseFixedBytes = 16;  // joint count, flags, root position
// Pose flags: a u32 mask of the joints not measured in this pose follows the joints.
inline constexpr std::uint16_t kPoseHasNotMeasured = 1;
inline constexpr std::size_t kEventFixedBytes = 8;

}  // namespace caphub::firmware::cap
