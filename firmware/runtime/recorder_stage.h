// The pipeline stage that records: raw samples and events into a .cap file, kept durable by the
// writer's sync interval, and what the other stages compute (orientations, poses, calibration)
// through its RecordSink side: the only writer of records. A capture records one file from start
// to end (`caphub run --record`), or takes: each its own file, begun and ended by commands while
// the capture runs; between takes nothing is written. Every file ends with a "recording stopped"
// event. A write error (full disk) stops the take, not the capture.
#pragma once

#include <memory>
#include <string_view>

#include "firmware/recording/writer.h"
#include "firmware/runtime/capture.h"
#include "firmware/runtime/record_sink.h"

namespace caphub::firmware {

// The text of the "recording stopped" event that ends a recording at the end of the capture.
inline constexpr std::string_view kEndOfCapture = "end of capture";

class RecorderStage final : public PipelineStage, public RecordSink {
public:
    // Records nothing until a take begins.
    RecorderStage() = default;
    // Records into writer from the start of the capture to its end.
    explicit RecorderStage(std::unique_ptr<RecordingWriter> writer) : writer_(std::move(writer)) {}

    void onSample(const SensorSample& s) override;
    void onEvent(const RuntimeEvent& e) override;
    void onTick(Timestamp now) override;
    void finish(Timestamp now) override;

    void orientation(int sensor, Timestamp t, const Eigen::Quaternionf& q) override;
    void pose(Timestamp t, const Eigen::Vector3f& rootM,
              std::span<const Eigen::Quaternionf> jointRotations,
              std::uint32_t notMeasured) override;
    void event(Timestamp t, cap::EventKind kind, int sensor, int error,
               std::string_view text) override;
    void metadata(Timestamp t, std::string_view toml) override;
    void marker(Timestamp t, std::string_view label) override;

    // Takes, on the pipeline thread. The writer is created by the caller (opening a file and
    // writing its header may wait for the disk: not on the pipeline thread); its first record
    // is a "take started" event named `name`. A take already running is ended first and
    // returned.
    std::unique_ptr<RecordingWriter> beginTake(std::unique_ptr<RecordingWriter> writer, Timestamp t,
                                               std::string_view name);
    // Ends the take being recorded with a "take stopped" event and hands its writer back, to be
    // closed (flushed and synced) by the caller off the pipeline thread; null when none runs.
    std::unique_ptr<RecordingWriter> endTake(Timestamp t);

    // The take being recorded (after the capture: the last one, closed), or null.
    const RecordingWriter* current() const { return writer_.get(); }
    bool recording() const { return writer_ != nullptr && !closed_; }
    // The one recording of a capture that records from its start (it has one).
    const RecordingWriter& writer() const { return *writer_; }
    // The error that stopped the current take (0: none, or no take).
    int error() const { return writer_ ? writer_->error() : 0; }

private:
    bool writable() const { return writer_ != nullptr && !closed_ && writer_->error() == 0; }
    // Ends the file with a "recording stopped" event and closes it.
    void closeFile(Timestamp t, std::string_view why);
    void check(int r);

    std::unique_ptr<RecordingWriter> writer_;
    bool closed_ = false;
    bool take_ = false;  // the writer holds a take begun by beginTake()
    bool reported_ = false;
};

// A TOML basic string (quoted, with the characters TOML requires escaped), for metadata.
std::string tomlString(const std::string& s);

// The metadata's [calibration] section: the calibration file applied before the filters, where
// it came from and its text (empty when the text is).
std::string calibrationMetadata(const std::string& path, const std::string& text);

// The metadata of a recording: the board file's text and where it came from, the software
// version and the start time, and the calibration file applied (its path and text; omitted when
// calibrationText is empty), as TOML.
std::string recordingMetadata(const board::Board& board, const std::string& boardText,
                              const std::string& softwareVersion,
                              const std::string& calibrationPath = {},
                              const std::string& calibrationText = {});

}  // namespace caphub::firmware
