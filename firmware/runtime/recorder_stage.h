// The pipeline stage that records: raw samples and events into a .cap file, kept durable by the
// writer's sync interval, ended by a "recording stopped" event. A write error (full disk) stops
// the recording, not the capture.
#pragma once

#include <memory>
#include <string_view>

#include "firmware/recording/writer.h"
#include "firmware/runtime/capture.h"

namespace caphub::firmware {

// The text of the "recording stopped" event that ends a recording at the end of the capture.
inline constexpr std::string_view kEndOfCapture = "end of capture";

class RecorderStage final : public PipelineStage {
public:
    explicit RecorderStage(std::unique_ptr<RecordingWriter> writer) : writer_(std::move(writer)) {}

    void onSample(const SensorSample& s) override;
    void onEvent(const RuntimeEvent& e) override;
    void onTick(Timestamp now) override;
    void finish(Timestamp now) override;

    const RecordingWriter& writer() const { return *writer_; }
    RecordingWriter& writer() { return *writer_; }
    // The error that stopped the recording (0: none).
    int error() const { return writer_->error(); }

private:
    void check(int r);

    std::unique_ptr<RecordingWriter> writer_;
    bool reported_ = false;
};

// A TOML basic string (quoted, with the characters TOML requires escaped), for metadata.
std::string tomlString(const std::string& s);

// The metadata of a recording: the board file's text and where it came from, the software
// version and the start time, and the calibration file applied (its path and text; omitted when
// calibrationText is empty), as TOML.
std::string recordingMetadata(const board::Board& board, const std::string& boardText,
                              const std::string& softwareVersion,
                              const std::string& calibrationPath = {},
                              const std::string& calibrationText = {});

}  // namespace caphub::firmware
