#include "firmware/runtime/recorder_stage.h"

#include <ctime>

#include <fmt/format.h>

#include "hal/core/log.h"

namespace caphub::firmware {

namespace {

cap::EventKind toEventKind(RuntimeEvent::Kind k) {
    switch (k) {
        case RuntimeEvent::Kind::SensorOnline:
            return cap::EventKind::SensorOnline;
        case RuntimeEvent::Kind::SensorLost:
            return cap::EventKind::SensorLost;
        case RuntimeEvent::Kind::SensorReset:
            return cap::EventKind::SensorReset;
        case RuntimeEvent::Kind::LineSilent:
            return cap::EventKind::LineSilent;
    }
    return cap::EventKind::SensorLost;
}

}  // namespace

std::string tomlString(const std::string& s) {
    std::string out = "\"";
    for (char c : s) {
        switch (c) {
            case '"':
                out += "\\\"";
                break;
            case '\\':
                out += "\\\\";
                break;
            case '\n':
                out += "\\n";
                break;
            case '\t':
                out += "\\t";
                break;
            default:
                if (static_cast<unsigned char>(c) < 0x20) {
                    out += fmt::format("\\u{:04x}", static_cast<int>(c));
                } else {
                    out += c;
                }
        }
    }
    return out + "\"";
}

void RecorderStage::check(int r) {
    if (r < 0 && !reported_) {
        reported_ = true;
        log::logger(log::Category::Firmware)
            .error(
                "recording '{}' stopped: {}; the capture goes on, the file is readable up to "
                "here",
                writer_->path(), errnoText(r));
    }
}

void RecorderStage::onSample(const SensorSample& s) {
    if (writable()) {
        check(writer_->writeRawSample(s.sensor, s.sample));
    }
}

void RecorderStage::onEvent(const RuntimeEvent& e) {
    if (writable()) {
        check(writer_->writeEvent(e.t, toEventKind(e.kind), e.sensor, e.error, ""));
    }
}

void RecorderStage::onTick(Timestamp) {
    if (writer_ != nullptr && !closed_) {
        check(writer_->maybeSync());
    }
}

void RecorderStage::finish(Timestamp now) {
    if (take_) {
        event(now, cap::EventKind::TakeStopped, -1, 0, "the capture ended");
    }
    closeFile(now, kEndOfCapture);
}

void RecorderStage::closeFile(Timestamp t, std::string_view why) {
    if (writer_ == nullptr || closed_) {
        return;
    }
    // The last record of a recording that ran to its end: a reader tells it from one cut short
    // (a crash, a power cut), which has none, and from one a write error stopped, whose stop
    // event carries the error.
    event(t, cap::EventKind::RecordingStopped, -1, 0, why);
    check(writer_->close());
    closed_ = true;
}

void RecorderStage::orientation(int sensor, Timestamp t, const Eigen::Quaternionf& q) {
    if (writable()) {
        check(writer_->writeOrientation(sensor, t, q));
    }
}

void RecorderStage::pose(Timestamp t, const Eigen::Vector3f& rootM,
                         std::span<const Eigen::Quaternionf> jointRotations,
                         std::uint32_t notMeasured) {
    if (writable()) {
        check(writer_->writePose(t, rootM, jointRotations, notMeasured));
    }
}

void RecorderStage::event(Timestamp t, cap::EventKind kind, int sensor, int error,
                          std::string_view text) {
    if (writable()) {
        check(writer_->writeEvent(t, kind, sensor, error, text));
    }
}

void RecorderStage::metadata(Timestamp t, std::string_view toml) {
    if (writable()) {
        check(writer_->writeMetadata(t, toml));
    }
}

void RecorderStage::marker(Timestamp t, std::string_view label) {
    if (writable()) {
        check(writer_->writeMarker(t, label));
    }
}

std::unique_ptr<RecordingWriter> RecorderStage::beginTake(std::unique_ptr<RecordingWriter> writer,
                                                          Timestamp t, std::string_view name) {
    std::unique_ptr<RecordingWriter> previous = endTake(t);
    writer_ = std::move(writer);
    closed_ = false;
    reported_ = false;
    take_ = true;
    event(t, cap::EventKind::TakeStarted, -1, 0, name);
    return previous;
}

std::unique_ptr<RecordingWriter> RecorderStage::endTake(Timestamp t) {
    if (writer_ == nullptr || closed_) {
        return nullptr;
    }
    event(t, cap::EventKind::TakeStopped, -1, 0, "");
    event(t, cap::EventKind::RecordingStopped, -1, 0, "take stopped");
    take_ = false;
    // Hand what is buffered to the writer's I/O thread now; the caller's close() syncs it.
    check(writer_->maybeSync());
    return std::move(writer_);
}

std::string recordingMetadata(const board::Board& board, const std::string& boardText,
                              const std::string& softwareVersion,
                              const std::string& calibrationPath,
                              const std::string& calibrationText) {
    const std::time_t now = std::time(nullptr);
    char when[32];
    std::strftime(when, sizeof when, "%Y-%m-%dT%H:%M:%SZ", std::gmtime(&now));
    std::string out;
    out += "[recording]\n";
    out += fmt::format("software = {}\n", tomlString(softwareVersion));
    out += fmt::format("started = {}\n", tomlString(when));
    out += "\n[board]\n";
    out += fmt::format("name = {}\n", tomlString(board.name));
    out += fmt::format("path = {}\n", tomlString(board.path.string()));
    out += fmt::format("text = {}\n", tomlString(boardText));
    out += "\n[sensors]\n";
    out += "names = [";
    for (std::size_t i = 0; i < board.sensors.size(); ++i) {
        out += fmt::format("{}{}", i == 0 ? "" : ", ", tomlString(board.sensors[i].name));
    }
    out += "]\nsegments = [";
    for (std::size_t i = 0; i < board.sensors.size(); ++i) {
        out += fmt::format("{}\"{}\"", i == 0 ? "" : ", ",
                           board::segmentName(board.sensors[i].segment));
    }
    out += "]\n";
    // Applied before the filter: the recording's orientations depend on it, its raw samples do
    // not.
    out += calibrationMetadata(calibrationPath, calibrationText);
    return out;
}

std::string calibrationMetadata(const std::string& path, const std::string& text) {
    if (text.empty()) {
        return {};
    }
    return fmt::format("\n[calibration]\npath = {}\ntext = {}\n", tomlString(path),
                       tomlString(text));
}

}  // namespace caphub::firmware
