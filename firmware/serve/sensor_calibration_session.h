// The guided sensor calibration of `caphub serve`: one procedure at a time - the gyroscopes at
// rest, the accelerometers in six (or fourteen) held positions, the magnetometers turned through
// every direction - on the live capture. It tells the person what to do and how far it got,
// collects the raw samples it needs from the Hub through a SampleTap (never holding up the
// pipeline), computes the calibration with the steps `caphub calibrate` uses
// (firmware/sensor_calibration_steps.h), reports a quality figure per sensor, and merges the
// result into the calibration file in the hub's state folder (the format `caphub calibrate`
// writes), which `caphub serve` applies at its next start. On the virtual suit it also makes the
// subject do the motions (CalibrationMotion).
#pragma once

#include <filesystem>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

#include <nlohmann/json.hpp>

#include "board/board.h"
#include "firmware/serve/calibration_motion.h"
#include "firmware/serve/sample_tap.h"
#include "hal/core/clock.h"
#include "hal/core/error.h"

namespace caphub::firmware::serve {

enum class SensorCalibrationKind { Gyro, Accel, Mag };

struct SensorCalibrationRequest {
    SensorCalibrationKind kind = SensorCalibrationKind::Gyro;
    int positions = 6;   // accel: 6 (per-axis scale and offset) or 14 (also cross-axis, gyro axes)
    double holdS = 3.0;  // accel: each position held this long
    double moveS = 1.5;  // accel: turning to the next one
    double durationS = 0;  // gyro, mag: how long to measure (0: 5 s, 30 s)
    double leadS = 3.0;    // seconds to get ready before measuring (the virtual suit: 0.5 s)
};

// Parses {"kind": "gyro"|"accel"|"mag", "positions": 6|14, "hold_s", "move_s", "duration_s"};
// errors name the key.
Result<SensorCalibrationRequest> parseSensorCalibrationRequest(const nlohmann::ordered_json& j);

class SensorCalibrationSession {
public:
    // `file`: where the calibration is kept (merged: other kinds and sensors stay); `inForce`:
    // the calibration file the running capture applies (empty: none); `motion`: the virtual
    // suit's (null on the hub's buses).
    SensorCalibrationSession(const board::Board& board, Clock& clock, SampleTap& tap,
                             std::shared_ptr<CalibrationMotion> motion, std::filesystem::path file,
                             std::string inForce);
    ~SensorCalibrationSession();
    SensorCalibrationSession(const SensorCalibrationSession&) = delete;
    SensorCalibrationSession& operator=(const SensorCalibrationSession&) = delete;

    // Starts a procedure. EBUSY while one runs, EINVAL for a bad request.
    Result<void> start(SensorCalibrationRequest request);
    // Ends a running procedure without saving anything.
    void cancel();
    // {"in_force", "file", "saved", "virtual_suit", "procedure": {kind, stage, progress,
    // instruction, step, ... result}} (docs/serve.md).
    nlohmann::ordered_json status() const;

private:
    void run(SensorCalibrationRequest request);
    void setStage(const std::string& stage, double progress, const std::string& instruction,
                  const std::string& step);

    const board::Board& board_;
    Clock& clock_;
    SampleTap& tap_;
    std::shared_ptr<CalibrationMotion> motion_;
    std::filesystem::path file_;
    std::string inForce_;

    mutable std::mutex mutex_;
    nlohmann::ordered_json procedure_;  // null: none run yet
    std::string saved_;                 // the file written by a procedure since the start
    bool running_ = false;
    bool cancel_ = false;
    std::thread worker_;
};

}  // namespace caphub::firmware::serve
