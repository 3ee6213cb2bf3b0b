// The Hub: the composition root of a running capture. From a board, its clock and its suit
// (real buses or the virtual suit, built by the caller) it builds the bus workers, the pipeline
// and its stages (recorder, fusion, body, status, preview), and takes commands into the running
// capture from any thread: start and stop a take (each its own .cap file), a marker, and a query
// of the live state. A command is carried out on the pipeline thread between two batches of
// samples and recorded in the take as an event; anything that may wait for the disk (creating a
// take's file, closing it) is done on the commanding thread, never on the pipeline's.
#pragma once

#include <filesystem>
#include <memory>
#include <mutex>
#include <optional>
#include <string>

#include "board/board.h"
#include "board/hardware.h"
#include "firmware/recording/writer.h"
#include "firmware/runtime/body_stage.h"
#include "firmware/runtime/capture.h"
#include "firmware/runtime/fusion_stage.h"
#include "firmware/runtime/mag_state.h"
#include "firmware/runtime/pose_feed.h"
#include "firmware/runtime/preview_stage.h"
#include "firmware/runtime/recorder_stage.h"
#include "firmware/runtime/status_stage.h"
#include "firmware/stream/pose_stream.h"
#include "hal/core/error.h"

namespace caphub::firmware {

struct HubOptions {
    FusionStage::Calibrations calibrations;  // per board sensor; may be empty
    BodyStage::Options body;
    // Where takes are written; their metadata (recordingMetadata) holds these texts.
    std::filesystem::path recordings;
    std::string boardText;
    std::string softwareVersion;
    std::string calibrationPath;
    std::string calibrationText;
    WriterOptions writer;
    // One recording from the start of the capture to its end (`caphub run --record`), besides
    // or instead of takes; may be null.
    std::unique_ptr<RecordingWriter> recordFromStart;
    std::filesystem::path statusPath;  // empty: no status stage
    // Where the online magnetometer estimates are kept between runs (docs/fusion.md,
    // "Persistence"): read before the capture, saved every magStateEvery of its clock and at its
    // end. Empty: not kept.
    std::filesystem::path magStatePath;
    Duration magStateEvery = std::chrono::seconds(60);
    ThreadPolicy threads;
    // The preview (optional): the skin and the sinks it renders into.
    std::optional<render::Skin> previewSkin;
    render::SinkSet previewSinks;
    PreviewStage::Options preview;
    // More stages, run after the body (and before status and preview): consumers that must see
    // every pose on the pipeline thread (an evaluation scoring each pose against the truth,
    // from a queue of the pose feed that it empties on each sample). Not owned.
    std::vector<PipelineStage*> stages;
    // Live streams of the poses (docs/streams.md): each its own thread, started with the
    // capture and stopped at its end.
    std::vector<board::StreamConfig> streams;
    // Threaded (a capture in real time) or stepped (the virtual suit on a stepped clock:
    // deterministic, as fast as the machine allows; run with runStepped()).
    Capture::Mode mode = Capture::Mode::Threaded;
    // False: the samples only - no fusion, no body (and so no poses, preview or streams), for
    // the commands that want the raw samples of a capture through their own stages
    // (calibrate, selftest, sim).
    bool solve = true;
    // The longest a command waits for the pipeline thread to carry it out.
    Duration commandTimeout = std::chrono::seconds(5);
};

// A take: what was recorded, where.
struct TakeInfo {
    std::filesystem::path path;
    std::string name;
    std::uint64_t records = 0;  // in the file (after stop: every record, made durable)
    int error = 0;              // -errno that stopped it early (0: none)
};

// What the hub is doing, for a query: the status (the latest snapshot, at most a second old),
// the take being recorded, the body's calibration.
struct HubState {
    StatusSnapshot status;
    std::optional<TakeInfo> take;
    std::uint64_t takesRecorded = 0;
    bool bodyCalibrated = false;
    std::string bodyCalibration;                // the method, or why it failed
    body::CalibrationStatus calibrationStatus;  // the latest request and how far it got
    body::HeadingResetStatus headingReset;      // the latest heading reset asked for
    std::uint64_t poses = 0;
    // The body's latency window (data-ready -> pose written), a copy: percentiles off the pipeline.
    LatencyWindow poseLatency{1};
    // Per board sensor: gyroscope clipping episodes so far (saturation).
    std::vector<std::uint32_t> gyroClipEvents;
    // Per board sensor: the turn (deg) its joints gave its free heading since the body
    // calibration (body::BodyTracker::jointHeadingTurns; 0: none).
    std::vector<double> jointTurnDeg;
};

class Hub {
public:
    Hub(const board::Board& board, Clock& clock, board::SuitHardware& suit, HubOptions options);
    ~Hub();
    Hub(const Hub&) = delete;
    Hub& operator=(const Hub&) = delete;

    // Starts capturing; runs until requestStop() or `duration` of capture-clock time.
    void start(Duration duration = Duration{0});
    // Safe from a signal handler.
    void requestStop() { capture_.requestStop(); }
    // Blocks until the capture has ended (a take still running is ended and closed).
    CaptureStats wait();
    // Stepped mode: the whole capture on the calling thread, for `duration` of the clock.
    CaptureStats runStepped(Duration duration);
    // The whole capture for `duration` of its clock, in either mode (threaded: start() and
    // wait(); stepped: runStepped()).
    CaptureStats run(Duration duration);

    // Commands, from any thread; each returns once the pipeline has carried it out.
    // A new take in the recordings folder, named with the date, time and `name` (letters,
    // digits, '-', '_', '.'; at most 64); a take already running is stopped first.
    Result<TakeInfo> startTake(const std::string& name = {});
    // Ends the take being recorded: its file is complete and durable when this returns.
    Result<TakeInfo> stopTake();
    // A marker with a label in the take being recorded (none: an error).
    Result<void> marker(const std::string& label);
    // Body calibration in a reference pose the subject holds from `countdown` after now (the
    // orientations are averaged over the body's window from then); the result comes later, in
    // state() and as a "calibrated" event.
    Result<void> calibrateBody(body::ReferencePoseKind pose, Duration countdown = Duration{0});
    // T+N: the T-pose held from tCountdown after now, the N-pose from nCountdown after now.
    Result<void> calibrateBodyTPlusN(Duration tCountdown, Duration nCountdown);
    // Turns the capture's world about up so that the subject faces forward as now.
    Result<void> headingReset();
    // Deletes a take's file, unless it is the take being recorded (EBUSY); in turn with the
    // commands, so that a take being started is never deleted under its writer.
    Result<void> deleteTakeFile(const std::filesystem::path& file);
    HubState state();

    Capture& capture() { return capture_; }
    FusionStage& fusion() { return fusion_; }
    BodyStage& body() { return body_; }
    // Every pose the body solves, for consumers off the pipeline thread (streams, the control
    // plane): the latest, or a queue of every one.
    PoseFeed& poses() { return poses_; }
    RecorderStage& recorder() { return recorder_; }
    StatusStage* status() { return status_.get(); }
    PreviewStage* preview() { return preview_.get(); }
    // The live streams, in the order configured: their counters and latency (after wait()).
    const std::vector<std::unique_ptr<PoseStream>>& streams() const { return streams_; }
    // Why the preview is off although sinks were given (empty: it is on, or none was asked).
    const std::string& previewError() const { return previewError_; }
    // The saving of the magnetometer estimates (null: magStatePath not given), and why the saved
    // ones were not loaded (empty: they were, or there were none: a first run).
    const MagStateStage* magState() const { return magState_.get(); }
    const std::string& magStateLoadError() const { return magStateLoadError_; }

private:
    // Runs fn on the pipeline thread and waits for it: an error when the capture is not running
    // or did not get to it in time.
    Result<void> onPipeline(const char* what, std::function<void(Timestamp)> fn);
    std::string metadata() const;
    void startStreams();
    void stopStreams();

    const board::Board& board_;
    Clock& clock_;
    HubOptions options_;
    Capture capture_;
    RecorderStage recorder_;
    FusionStage fusion_;
    BodyStage body_;
    PoseFeed poses_;
    std::unique_ptr<StatusStage> status_;
    std::unique_ptr<PreviewStage> preview_;
    std::string previewError_;
    std::unique_ptr<MagStateStage> magState_;
    std::string magStateLoadError_;
    std::vector<std::unique_ptr<PoseStream>> streams_;
    std::mutex commandMutex_;       // one command at a time
    std::optional<TakeInfo> take_;  // guarded by commandMutex_
    std::uint64_t takes_ = 0;
    bool started_ = false;
};

// The samples and events of a capture of `duration` (of its clock), handed to `stage`: a Hub
// that does not solve (HubOptions::solve false), threaded or stepped. For the commands that
// measure the raw samples (calibrate, selftest, sim).
CaptureStats captureSamples(const board::Board& board, Clock& clock, board::SuitHardware& suit,
                            Capture::Mode mode, Duration duration, PipelineStage& stage);

// A take's file name: "YYYYmmdd-HHMMSS[-name].cap" in local time; an error for a name with
// other characters than letters, digits, '-', '_' and '.', or longer than 64.
Result<std::string> takeFileName(const std::string& name, std::time_t when);

}  // namespace caphub::firmware
