// The live status of a capture for `caphub status` (and the hub's state query): once a second
// (capture clock) the pipeline thread takes a snapshot of its counters - per-sensor rate, errors,
// lost and dropped samples, each bus's load, the latest latencies, the recording's state - and
// hands it to the stage's own thread, which builds the JSON document and replaces the status
// file atomically (written beside it, then renamed), so a reader never sees half a document and
// the pipeline never formats text or touches the disk.
#pragma once

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "board/board.h"
#include "firmware/runtime/capture.h"
#include "firmware/runtime/fusion_stage.h"
#include "firmware/runtime/latency_window.h"
#include "firmware/runtime/latest_writer.h"
#include "firmware/runtime/recorder_stage.h"

namespace caphub::firmware {

// What the status says, as data.
struct StatusSnapshot {
    struct Sensor {
        std::string name;
        std::string segment;
        bool online = false;
        std::uint64_t samples = 0;
        double rateHz = 0;  // since the previous snapshot
        double configuredHz = 0;
        std::uint64_t readErrors = 0;
        std::uint64_t dropped = 0;
        std::uint64_t lost = 0;
        std::uint64_t events = 0;
        // Where its heading comes from (key(MagMode)); empty: no fusion in this capture.
        std::string heading;
        // A gyroscope-only heading: how far its online estimate has come.
        std::optional<FusionStage::MagLearning> headingLearning;
    };
    struct Bus {
        std::string name;
        double plannedLoad = 0;  // 0..1
        bool counted = false;    // the bus counts its transfers
        std::uint64_t transactions = 0;
        std::uint64_t bytes = 0;
        std::uint64_t errors = 0;
    };
    struct Recording {
        std::uint64_t records = 0;
        std::uint64_t bytes = 0;
        std::uint64_t durableRecords = 0;
        std::uint64_t syncs = 0;
        std::string error;  // empty: none
    };
    std::string board;
    bool running = false;
    double uptimeS = 0;
    std::vector<Sensor> sensors;
    std::vector<Bus> buses;
    LatencyWindow latency{1};  // data-ready -> pipeline, the latest samples
    std::optional<Recording> recording;
};

// The JSON document of a snapshot (what `caphub status` prints).
std::string statusJson(const StatusSnapshot& s);

class StatusStage final : public PipelineStage {
public:
    // recorder may be null (no recording).
    StatusStage(const board::Board& board, const Capture& capture, const RecorderStage* recorder,
                std::filesystem::path path, Clock& clock);
    ~StatusStage() override;

    void onSample(const SensorSample& s) override;
    void onEvent(const RuntimeEvent& e) override;
    void onTick(Timestamp now) override;
    // The capture's fusion, for each sensor's heading mode (null: none). Before the capture.
    void setFusion(const FusionStage* fusion) { fusion_ = fusion; }
    // Writes the last document (running: false) and waits for it to be written.
    void finish(Timestamp now) override;

    // The latest snapshot handed to the writer (any thread).
    StatusSnapshot latest() const;
    const std::filesystem::path& path() const { return path_; }
    // Documents written so far (any thread).
    std::uint64_t written() const;

private:
    StatusSnapshot snapshot(Timestamp now, bool running) const;
    void publish(Timestamp now, bool running);
    void writeFile(const std::string& text);

    const board::Board& board_;
    const Capture& capture_;
    const RecorderStage* recorder_;
    const FusionStage* fusion_ = nullptr;
    std::filesystem::path path_;
    Clock& clock_;
    // The pipeline thread's side.
    std::vector<double> plannedLoad_;  // per bus, 0..1
    std::vector<std::uint64_t> samples_;
    std::vector<std::uint64_t> samplesAtLastWrite_;
    std::vector<std::uint64_t> events_;
    Timestamp started_{};
    Timestamp lastWrite_{};
    bool first_ = true;
    LatencyWindow latency_{4096};
    // The writer thread's side.
    std::string error_;                    // why the last write failed, reported once
    LatestWriter<StatusSnapshot> writer_;  // last: its thread writes with the members above
};

// Where the running hub writes its status, and `caphub status` reads it: $CAPHUB_STATUS, else
// /run/caphub/status.json when /run/caphub exists (the service's runtime directory), else the
// temporary directory's caphub-status.json.
std::filesystem::path defaultStatusPath();

}  // namespace caphub::firmware
