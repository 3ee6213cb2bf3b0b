// Reading and writing IMU recordings in the layout of the BROAD data set (gzip'd or plain CSV):
// replay input for the orientation filter, and the format the virtual suit will write.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "fusion/evaluation.h"
#include "hal/core/error.h"
#include "hal/core/quaternion.h"

namespace caphub::firmware {

// One trial. truth/movement are empty when the file has no ground-truth columns.
struct BroadTrial {
    std::string name;     // from the comment line, else the file stem
    double rateHz = 0.0;  // from the comment line (sampling_rate_hz=...), else from t
    std::vector<fusion::ImuSample> samples;
    std::vector<Quatd> truth;  // w x y z, NaN where the markers were not visible
    std::vector<bool> movement;
    bool hasTruth() const { return !truth.empty(); }
};

// Reads a BROAD-layout file: an optional `#` comment line (trial name, sampling_rate_hz=R),
// the header, then one row per sample. The header is either the 10 IMU columns
// t,gyr_x..z,acc_x..z,mag_x..z or those plus opt_w,opt_x,opt_y,opt_z,movement. Every error names
// the file and line and what was expected.
Result<BroadTrial> readBroadCsv(const std::filesystem::path& path);

// Writes the layout readBroadCsv reads (with truth columns when the trial has them); gzip'd when
// `gzip` says so (by default: when the path ends in .gz). Only over a regular file or where
// none is: never through a symbolic link, never into a FIFO or a device.
Result<void> writeBroadCsv(const std::filesystem::path& path, const BroadTrial& trial);
Result<void> writeBroadCsv(const std::filesystem::path& path, const BroadTrial& trial, bool gzip);

}  // namespace caphub::firmware
