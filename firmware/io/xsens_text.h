// Xsens MT Manager text exports (one file per sensor): `//` header lines (the update rate among
// them), a header row, then one row per packet, tab- or comma-separated. Read into SI samples and
// the vendor filter's orientation, with every missing packet (a PacketCounter gap) counted, and
// every malformed cell reported as file:line:column (docs/import.md).
#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "hal/core/error.h"

namespace caphub::firmware {

struct XsensSample {
    std::int64_t packet = 0;  // PacketCounter, unwrapped (16 bits in the file), from the first
    Eigen::Vector3d accMps2 = Eigen::Vector3d::Zero();
    Eigen::Vector3d gyrRadps = Eigen::Vector3d::Zero();
    std::optional<Eigen::Vector3d> mag;  // as written: units normalised to the local field
    // The vendor filter's orientation, sensor -> its earth frame (z up), from Quat_q0..q3 or
    // the rotation matrix Mat[r][c] (a file with both: the quaternion, the matrix checked
    // against it).
    std::optional<Eigen::Quaterniond> qEarthSensor;
};

// A gap in the packet counter: `missing` packets lost before the packet on `line`.
struct XsensGap {
    int line = 0;
    std::int64_t afterPacket = 0;  // the last packet before the gap (unwrapped)
    std::int64_t missing = 0;
};

struct XsensFile {
    std::string path;
    std::string deviceId;  // from the file name: the last '_' field ("..._00B421AF.txt")
    double rateHz = 0;     // "// Update Rate: 100.0Hz"
    char separator = '\t';
    std::uint16_t firstCounter = 0;  // the first row's PacketCounter as written
    std::vector<XsensSample> samples;
    std::vector<XsensGap> gaps;
    std::int64_t lostPackets = 0;
    bool hasMag = false;
    // "quaternion", "matrix", "quaternion and matrix" or "" (none)
    std::string orientationColumns;
};

// The device id an MT Manager file name carries: "MT_012005D6_031-000_00B421AF.txt" ->
// "00B421AF".
std::string xsensDeviceId(const std::filesystem::path& path);

// Errors name the file, line and column: a missing required column (PacketCounter, Acc_X..Z,
// Gyr_X..Z), a row with another number of cells than the header, a cell that is not a number,
// a packet counter that repeats or goes backwards, no update rate, no data row, a row whose
// quaternion and matrix are two different orientations.
Result<XsensFile> readXsensText(const std::filesystem::path& path);

}  // namespace caphub::firmware
