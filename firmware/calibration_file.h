// The calibration file: per-sensor calibration (gyroscope bias, accelerometer offset and scale,
// magnetometer hard and soft iron) in TOML, one table per sensor, read before capture and
// applied to raw samples ahead of the filter.
#pragma once

#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "board/board.h"
#include "fusion/calibration/sensor_calibration.h"
#include "hal/core/error.h"

namespace caphub::firmware {

// Sensor name (as in the board file) -> its calibration.
using CalibrationSet = std::map<std::string, fusion::SensorCalibration>;

inline constexpr int kCalibrationFormat = 1;

// Parses the text of a calibration file; `origin` names it in errors ("file:line:column: ...").
Result<CalibrationSet> parseCalibration(std::string_view text, const std::string& origin);
Result<CalibrationSet> readCalibrationFile(const std::filesystem::path& path);

// The text of a calibration file (values with full double precision, so a read-back is exact).
std::string formatCalibration(const CalibrationSet& set);
// Written whole: PATH.part renamed over PATH when complete (a failed write leaves the file as it
// was); a symbolic link stays one, the file it names replaced.
Result<void> writeCalibrationFile(const std::filesystem::path& path, const CalibrationSet& set);

// The calibration of each board sensor, by name (none where the set has none); the set's names
// that no sensor of the board has are added to `unknown`.
std::vector<std::optional<fusion::SensorCalibration>> calibrationsFor(
    const board::Board& board, const CalibrationSet& set, std::vector<std::string>* unknown);

}  // namespace caphub::firmware
