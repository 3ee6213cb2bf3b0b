#include "firmware/runtime/hub.h"

#include <cctype>
#include <ctime>
#include <future>
#include <numbers>

#include <fmt/format.h>

#include "firmware/runtime/thread_policy.h"
#include "hal/core/log.h"

namespace caphub::firmware {

namespace fs = std::filesystem;

Result<std::string> takeFileName(const std::string& name, std::time_t when) {
    constexpr std::size_t kMaxName = 64;
    if (name.size() > kMaxName) {
        return Error{EINVAL, fmt::format("a take's name has at most {} characters ({} given)",
                                         kMaxName, name.size())};
    }
    for (char c : name) {
        const auto u = static_cast<unsigned char>(c);
        if (!std::isalnum(u) && c != '-' && c != '_' && c != '.') {
            return Error{EINVAL, fmt::format("a take's name may hold letters, digits, '-', '_' "
                                             "and '.'; not {}",
                                             u < 0x20 || u >= 0x7f ? fmt::format("byte 0x{:02x}", u)
                                                                   : fmt::format("'{}'", c))};
        }
    }
    if (name.starts_with('.')) {
        return Error{EINVAL, "a take's name may not start with '.'"};
    }
    char stamp[32];
    std::tm local{};
    localtime_r(&when, &local);
    std::strftime(stamp, sizeof stamp, "%Y%m%d-%H%M%S", &local);
    return name.empty() ? fmt::format("{}.cap", stamp) : fmt::format("{}-{}.cap", stamp, name);
}

Hub::Hub(const board::Board& board, Clock& clock, board::SuitHardware& suit, HubOptions options)
    : board_(board),
      clock_(clock),
      options_(std::move(options)),
      capture_(suit, clock, BusWorker::Options{}, options_.mode),
      recorder_(options_.recordFromStart ? RecorderStage(std::move(options_.recordFromStart))
                                         : RecorderStage()),
      fusion_(board, &recorder_, options_.calibrations),
      body_(board, fusion_, &recorder_, clock, options_.body) {
    capture_.setThreadPolicy(options_.threads);
    body_.publishTo(poses_);
    // The order is the data's: the recorder takes the raw sample before fusion, fusion's
    // orientation before the body, the body's pose before the consumers.
    capture_.addStage(recorder_);
    if (options_.solve) {
        capture_.addStage(fusion_);
        capture_.addStage(body_);
        if (!options_.magStatePath.empty()) {
            // What an earlier run learnt of the uncalibrated magnetometers; a damaged file is
            // said and learnt afresh (its next save replaces it).
            if (auto loaded = loadMagState(options_.magStatePath, board, fusion_); !loaded) {
                magStateLoadError_ = loaded.error().message;
                log::logger(log::Category::Firmware)
                    .warn("magnetometer estimates not loaded, learning afresh: {}",
                          magStateLoadError_);
            }
            magState_ = std::make_unique<MagStateStage>(board, fusion_, options_.magStatePath,
                                                        options_.magStateEvery);
            capture_.addStage(*magState_);
        }
    }
    for (PipelineStage* stage : options_.stages) {
        capture_.addStage(*stage);
    }
    if (!options_.statusPath.empty()) {
        status_ =
            std::make_unique<StatusStage>(board, capture_, &recorder_, options_.statusPath, clock);
        if (options_.solve) {
            status_->setFusion(&fusion_);
        }
        capture_.addStage(*status_);
    }
    if (options_.solve && options_.previewSinks.liveCount() > 0) {
        if (!options_.previewSkin) {
            previewError_ = "no skin to render";
        } else {
            preview_ =
                std::make_unique<PreviewStage>(board, poses_, std::move(*options_.previewSkin),
                                               std::move(options_.previewSinks), options_.preview);
            capture_.addStage(*preview_);
        }
    }
    // The streams' threads run two levels below the bus workers (one below the pipeline): a
    // send never delays a sample or a pose, and normal work never delays a send.
    const ThreadPolicy streamPolicy = options_.threads.lowered(2);
    for (const board::StreamConfig& config : options_.streams) {
        if (!options_.solve) {
            break;  // no poses to stream
        }
        streams_.push_back(std::make_unique<PoseStream>(config, poses_, clock_, [streamPolicy] {
            (void)applyToThisThread(streamPolicy, "caphub-stream");
        }));
    }
}

Hub::~Hub() {
    capture_.requestStop();
    (void)capture_.wait();
    stopStreams();
}

void Hub::startStreams() {
    const Timestamp now = clock_.now();
    for (auto& s : streams_) {
        s->start(now);
    }
}

void Hub::stopStreams() {
    for (auto& s : streams_) {
        s->stop();
    }
}

void Hub::start(Duration duration) {
    started_ = true;
    startStreams();
    capture_.start(duration);
}

CaptureStats Hub::wait() {
    CaptureStats stats = capture_.wait();
    stopStreams();
    return stats;
}

CaptureStats Hub::runStepped(Duration duration) {
    started_ = true;
    startStreams();
    CaptureStats stats = capture_.runStepped(duration);
    stopStreams();
    return stats;
}

CaptureStats Hub::run(Duration duration) {
    if (options_.mode == Capture::Mode::Stepped) {
        return runStepped(duration);
    }
    start(duration);
    return wait();
}

CaptureStats captureSamples(const board::Board& board, Clock& clock, board::SuitHardware& suit,
                            Capture::Mode mode, Duration duration, PipelineStage& stage) {
    HubOptions options;
    options.solve = false;
    options.mode = mode;
    options.stages.push_back(&stage);
    Hub hub(board, clock, suit, std::move(options));
    return hub.run(duration);
}

Result<void> Hub::onPipeline(const char* what, std::function<void(Timestamp)> fn) {
    auto done = std::make_shared<std::promise<void>>();
    std::future<void> finished = done->get_future();
    const bool posted = started_ && capture_.post([fn = std::move(fn), done](Timestamp t) {
        fn(t);
        done->set_value();
    });
    if (!posted) {
        return Error{ESRCH, fmt::format("{}: the capture is not running", what)};
    }
    if (finished.wait_for(options_.commandTimeout) != std::future_status::ready) {
        return Error{ETIMEDOUT, fmt::format("{}: the capture did not carry it out within {:.1f} s",
                                            what, toSeconds(options_.commandTimeout))};
    }
    return {};
}

std::string Hub::metadata() const {
    return recordingMetadata(board_, options_.boardText, options_.softwareVersion,
                             options_.calibrationPath, options_.calibrationText);
}

Result<TakeInfo> Hub::startTake(const std::string& name) {
    std::lock_guard lock(commandMutex_);
    if (options_.recordings.empty()) {
        return Error{EINVAL, "start take: no recordings folder is configured"};
    }
    auto file = takeFileName(name, std::time(nullptr));
    if (!file) {
        return Error{EINVAL, "start take: " + file.error().message};
    }
    std::error_code ec;
    fs::create_directories(options_.recordings, ec);
    if (ec) {
        return Error{ec.value(), fmt::format("start take: cannot create '{}': {}",
                                             options_.recordings.string(), ec.message())};
    }
    // Two takes in one second: the second gets a suffix (the writer never replaces a file).
    fs::path path = options_.recordings / *file;
    for (int k = 2; fs::exists(path, ec) && k < 100; ++k) {
        path = options_.recordings / fmt::format("{}-{}.cap", fs::path(*file).stem().string(), k);
    }
    auto writer = RecordingWriter::create(path.string(), metadata(), options_.writer);
    if (!writer) {
        return Error{writer.error().code, "start take: " + writer.error().message};
    }
    std::unique_ptr<RecordingWriter> previous;
    std::unique_ptr<RecordingWriter> fresh = std::move(*writer);
    auto r = onPipeline("start take", [&](Timestamp t) {
        previous = recorder_.beginTake(std::move(fresh), t, name);
        // A take begun after the body calibration carries it, as one from the start would.
        if (body_.calibrated() && body_.calibration().method != body::CalibrationMethod::None) {
            recorder_.metadata(t, "[body_calibration]\ntext = " +
                                      tomlString(body::toText(body_.calibration())) + "\n");
        }
        recorder_.event(t, cap::EventKind::Command, -1, 0, "start take " + name);
    });
    if (!r) {
        // The pipeline never took the writer: the empty file is removed again.
        if (fresh) {
            (void)fresh->close();
            fs::remove(path, ec);
        }
        return r.error();
    }
    if (previous) {
        (void)previous->close();
        ++takes_;
    }
    take_ = TakeInfo{path, name, 0, 0};
    log::logger(log::Category::Firmware).info("take started: {}", path.string());
    return *take_;
}

Result<TakeInfo> Hub::stopTake() {
    std::lock_guard lock(commandMutex_);
    std::unique_ptr<RecordingWriter> ended;
    auto r = onPipeline("stop take", [&](Timestamp t) {
        recorder_.event(t, cap::EventKind::Command, -1, 0, "stop take");
        ended = recorder_.endTake(t);
    });
    if (!r) {
        return r.error();
    }
    if (!ended) {
        return Error{ENOENT, "stop take: no take is being recorded"};
    }
    const int closeError = ended->close();
    TakeInfo info = take_.value_or(TakeInfo{ended->path(), "", 0, 0});
    info.records = ended->stats().durableRecords;
    info.error = ended->error() != 0 ? ended->error() : closeError;
    take_.reset();
    ++takes_;
    log::logger(log::Category::Firmware)
        .info("take stopped: {} ({} records)", info.path.string(), info.records);
    return info;
}

Result<void> Hub::marker(const std::string& label) {
    std::lock_guard lock(commandMutex_);
    bool recorded = false;
    auto r = onPipeline("marker", [&](Timestamp t) {
        recorded = recorder_.recording();
        recorder_.marker(t, label);
    });
    if (!r) {
        return r;
    }
    if (!recorded) {
        return Error{ENOENT, "marker: no take is being recorded"};
    }
    return {};
}

Result<void> Hub::calibrateBody(body::ReferencePoseKind pose, Duration countdown) {
    if (countdown < Duration{0}) {
        return Error{EINVAL, "calibrate: the countdown cannot be negative"};
    }
    std::lock_guard lock(commandMutex_);
    const char* name = pose == body::ReferencePoseKind::T ? "tpose" : "npose";
    return onPipeline("calibrate", [&](Timestamp t) {
        body_.tracker().startCalibration(pose, t + countdown);
        recorder_.event(t, cap::EventKind::Command, -1, 0,
                        fmt::format("calibrate {} in {:.1f} s", name, toSeconds(countdown)));
    });
}

Result<void> Hub::calibrateBodyTPlusN(Duration tCountdown, Duration nCountdown) {
    if (tCountdown < Duration{0} || nCountdown < Duration{0}) {
        return Error{EINVAL, "calibrate: the countdowns cannot be negative"};
    }
    std::lock_guard lock(commandMutex_);
    return onPipeline("calibrate", [&](Timestamp t) {
        body_.tracker().startTwoPoseCalibration(t + tCountdown, t + nCountdown);
        recorder_.event(t, cap::EventKind::Command, -1, 0,
                        fmt::format("calibrate T+N: T-pose in {:.1f} s, N-pose in {:.1f} s",
                                    toSeconds(tCountdown), toSeconds(nCountdown)));
    });
}

Result<void> Hub::headingReset() {
    std::lock_guard lock(commandMutex_);
    return onPipeline("heading reset", [&](Timestamp t) {
        body_.tracker().headingResetAt(t);
        recorder_.event(t, cap::EventKind::Command, -1, 0, "heading reset");
    });
}

Result<void> Hub::deleteTakeFile(const fs::path& file) {
    std::lock_guard lock(commandMutex_);
    std::error_code ec;
    if (take_ && (take_->path == file || fs::equivalent(take_->path, file, ec))) {
        return Error{EBUSY, "the take is being recorded: stop it first"};
    }
    if (!fs::remove(file, ec) || ec) {
        return Error{ec ? ec.value() : ENOENT,
                     fmt::format("cannot delete '{}': {}", file.filename().string(),
                                 ec ? ec.message() : "it is not there")};
    }
    return {};
}

HubState Hub::state() {
    HubState s;
    if (status_) {
        s.status = status_->latest();
    }
    std::lock_guard lock(commandMutex_);
    s.take = take_;
    s.takesRecorded = takes_;
    // The body's figures are the pipeline's: read there, when it runs.
    (void)onPipeline("state", [&](Timestamp) {
        s.bodyCalibrated = body_.calibrated();
        s.bodyCalibration =
            !body_.calibrationError().empty()
                ? body_.calibrationError()
                : (body_.calibrated() ? std::string(body::toString(body_.calibration().method))
                                      : std::string("not calibrated"));
        s.poses = body_.poses();
        s.calibrationStatus = body_.tracker().calibrationStatus();
        s.headingReset = body_.tracker().headingResetStatus();
        s.poseLatency = body_.latencyWindow();
        s.gyroClipEvents.resize(board_.sensors.size());
        for (std::size_t i = 0; i < board_.sensors.size(); ++i) {
            s.gyroClipEvents[i] = fusion_.clipEvents(static_cast<int>(i));
        }
        s.jointTurnDeg.clear();
        for (const double turn : body_.tracker().jointHeadingTurns()) {
            s.jointTurnDeg.push_back(turn * 180.0 / std::numbers::pi);
        }
        if (const RecordingWriter* w = recorder_.current(); w != nullptr && s.take) {
            s.take->records = w->stats().records;
            s.take->error = w->error();
        }
    });
    return s;
}

}  // namespace caphub::firmware
