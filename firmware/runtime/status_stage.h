// The live status of a capture for `caphub status`: once a second (capture clock) a JSON
// document - per-sensor rate, errors, lost and dropped samples, each bus's load, latency
// percentiles over the last samples, the recording's state - replaces the status file
// atomically (written beside it, then renamed), so a reader never sees half a document.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "board/board.h"
#include "firmware/runtime/capture.h"
#include "firmware/runtime/latency_window.h"
#include "firmware/runtime/recorder_stage.h"

namespace caphub::firmware {

class StatusStage final : public PipelineStage {
public:
    // recorder may be null (no recording).
    StatusStage(const board::Board& board, const Capture& capture, const RecorderStage* recorder,
                std::filesystem::path path, Clock& clock);

    void onSample(const SensorSample& s) override;
    void onEvent(const RuntimeEvent& e) override;
    void onTick(Timestamp now) override;
    void finish(Timestamp now) override;

    // The document as it would be written now.
    std::string json(Timestamp now, bool running) const;
    const std::filesystem::path& path() const { return path_; }

private:
    void write(Timestamp now, bool running);

    const board::Board& board_;
    const Capture& capture_;
    const RecorderStage* recorder_;
    std::filesystem::path path_;
    Clock& clock_;
    std::vector<double> plannedLoad_;  // per bus, 0..1
    std::vector<std::uint64_t> samples_;
    std::vector<std::uint64_t> samplesAtLastWrite_;
    std::vector<std::uint64_t> events_;
    Timestamp started_{};
    Timestamp lastWrite_{};
    bool first_ = true;
    LatencyWindow latency_{4096};
    std::string error_;  // why the last write failed, reported once
};

// Where the running hub writes its status, and `caphub status` reads it: $CAPHUB_STATUS, else
// /run/caphub/status.json when /run/caphub exists (the service's runtime directory), else the
// temporary directory's caphub-status.json.
std::filesystem::path defaultStatusPath();

}  // namespace caphub::firmware
