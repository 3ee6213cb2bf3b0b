// caphub reprocess: a recording's raw samples through sensor calibration, fusion and body again
// (firmware/reprocess.h), with the body calibration, the sensor calibration and the pose rate
// chosen after the fact, and optionally the non-causal pass (--smooth); written to a new
// recording beside the target (.part) and renamed over it when complete (docs/reprocess.md).
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <toml++/toml.h>
#include <unistd.h>

#include "board/loader.h"
#include "firmware/calibration_file.h"
#include "firmware/cli/app.h"
#include "firmware/cli/commands.h"
#include "firmware/cli/info.h"
#include "firmware/cli/number_checks.h"
#include "firmware/cli/smooth_heading_option.h"
#include "firmware/cli/terminal_progress.h"
#include "firmware/export/output_file.h"
#include "firmware/export/partial_output.h"
#include "firmware/recording/reader.h"
#include "firmware/recording/writer.h"
#include "firmware/reprocess.h"
#include "hal/core/input_file.h"

namespace caphub::firmware {

namespace {

namespace fs = std::filesystem;

struct ReprocessArgs {
    std::string recording;
    std::string output;
    std::string calibrate;  // tpose, npose, tn, none; empty: the recording's
    std::vector<double> at;
    std::string calibration;
    double poseRateHz = 60;
    bool smooth = false;
    std::string smoothHeading = "causal";
    bool noKneeHeading = false;
};

// The new recording's header: the source's metadata, the sensor calibration replaced when
// another was given, and a [reprocess] table saying what was done. Nothing that changes from
// run to run (no clock time): the same input gives the same file.
Result<std::string> reprocessedMetadata(const std::string& source, const ReprocessArgs& a,
                                        const std::string& calibrationText,
                                        const std::string& calibrationDone) {
    toml::table meta;
    try {
        meta = toml::parse(std::string_view(source), std::string_view("recording metadata"));
    } catch (const toml::parse_error& e) {
        return Error{EINVAL,
                     fmt::format("the recording's metadata is not TOML ({})", e.description())};
    }
    if (!a.calibration.empty()) {
        meta.insert_or_assign("calibration",
                              toml::table{{"path", a.calibration}, {"text", calibrationText}});
    }
    // A take begun after a body calibration carries it in its header: the new one comes as a
    // record, like any calibration made during a capture.
    meta.erase("body_calibration");
    toml::table r{{"source", fs::path(a.recording).filename().string()},
                  {"software", versionLine()},
                  {"smooth", a.smooth},
                  {"smooth_heading", a.smooth ? a.smoothHeading : std::string("")},
                  {"knee_heading", a.smooth && !a.noKneeHeading},
                  {"pose_rate_hz", a.poseRateHz},
                  {"body_calibration", calibrationDone}};
    meta.insert_or_assign("reprocess", std::move(r));
    std::ostringstream out;
    out << meta << "\n";
    return out.str();
}

std::optional<board::Board> boardOf(const std::string& metadata, std::string& why) {
    std::string text;
    try {
        const toml::table meta =
            toml::parse(std::string_view(metadata), std::string_view("recording metadata"));
        if (const auto t = meta["board"]["text"].value<std::string>()) {
            text = *t;
        }
    } catch (const toml::parse_error& e) {
        why = fmt::format("the recording's metadata is not TOML ({})", e.description());
        return std::nullopt;
    }
    if (text.empty()) {
        why = "the recording carries no board file (its sensors' rates and segments)";
        return std::nullopt;
    }
    board::LoadResult loaded = board::loadBoardText(text, "recording's board file");
    if (!loaded.ok()) {
        why = fmt::format("the recording's board file does not load ({})",
                          loaded.errors.empty() ? "?" : loaded.errors.front().str());
        return std::nullopt;
    }
    return std::move(loaded.board);
}

int runReprocess(const ReprocessArgs& a) {
    const auto fail = [](int code, const std::string& msg) {
        fmt::print(stderr, "caphub reprocess: {}\n", msg);
        return code;
    };
    ReprocessOptions o;
    o.poseRateHz = a.poseRateHz;
    o.smooth = a.smooth;
    o.kneeHeading = !a.noKneeHeading;
    fusion::setSmoothHeading(o.smoothing, a.smoothHeading);
    o.calibration.atS = a.at;
    if (a.calibrate.empty()) {
        if (!a.at.empty()) {
            return fail(kExitUsage, "--at needs --calibrate tpose|npose|tn");
        }
    } else if (a.calibrate == "none") {
        o.calibration.kind = CalibrationChoice::Kind::None;
        if (!a.at.empty()) {
            return fail(kExitUsage, "--calibrate none takes no --at");
        }
    } else {
        const bool tn = a.calibrate == "tn";
        o.calibration.kind = a.calibrate == "tpose"   ? CalibrationChoice::Kind::TPose
                             : a.calibrate == "npose" ? CalibrationChoice::Kind::NPose
                                                      : CalibrationChoice::Kind::TPlusN;
        if (a.at.size() != (tn ? 2u : 1u)) {
            return fail(kExitUsage,
                        tn ? "--calibrate tn needs two --at: when the T-pose was held, then the "
                             "N-pose (seconds from the recording's first sample)"
                           : fmt::format("--calibrate {} needs one --at: when the pose was held "
                                         "(seconds from the recording's first sample)",
                                         a.calibrate));
        }
    }
    if (auto ok = checkInputFile(a.recording); !ok) {
        return fail(kExitUsage, ok.error().message);
    }
    auto target = exporter::regularOutputTarget(a.output);
    if (!target) {
        return fail(kExitUsage, target.error().message);
    }
    std::error_code ec;
    if (fs::exists(*target, ec) && fs::equivalent(*target, a.recording, ec)) {
        return fail(kExitUsage, fmt::format("-o '{}' is the recording being reprocessed: write "
                                            "the result to another file",
                                            a.output));
    }
    auto reader = RecordingReader::open(a.recording);
    if (!reader) {
        return fail(kExitUsage, reader.error().message);
    }
    std::string why;
    const auto board = boardOf((*reader)->metadata(), why);
    if (!board) {
        return fail(kExitUsage, fmt::format("{}: {}", a.recording, why));
    }
    std::string calibrationText;
    if (!a.calibration.empty()) {
        auto text = readInputFile(a.calibration, 1 << 20);
        if (!text) {
            return fail(kExitUsage, text.error().message);
        }
        auto set = parseCalibration(*text, a.calibration);
        if (!set) {
            return fail(kExitUsage, set.error().message);
        }
        std::vector<std::string> unknown;
        o.sensorCalibrations = calibrationsFor(*board, *set, &unknown);
        if (!unknown.empty()) {
            fmt::print(stderr,
                       "caphub reprocess: {}: sensor '{}' is not on the recording's board; "
                       "ignored\n",
                       a.calibration, unknown.front());
        }
        calibrationText = *text;
    }
    const auto wallStart = std::chrono::steady_clock::now();
    TerminalProgress progress("caphub reprocess", 10);
    progress("reading", 0);
    auto source = readSourceRecording(**reader);
    if (!source) {
        progress.done();
        return fail(kExitRuntime, fmt::format("{}: {}", a.recording, source.error().message));
    }
    o.progress = [&](std::string_view stage, double f) { progress(stage, f); };

    // Written beside the target, then renamed over it: never a half-written OUT.
    const std::string partial = target->string() + ".part";
    if (fs::is_regular_file(fs::symlink_status(partial, ec))) {
        fs::remove(partial, ec);  // a stale one from an interrupted run
    }
    PartialOutput part(partial);  // removed on Ctrl-C or SIGTERM; SIGXFSZ a write error
    // The header needs the calibration applied, known only at the end: a placeholder run first
    // would double the time, so the header says what was asked and the summary what was done.
    const std::string asked =
        a.calibrate.empty() ? "as recorded" : fmt::format("{}{}", a.calibrate, [&] {
            std::string s;
            for (const double t : a.at) {
                s += fmt::format(" at {:g} s", t);
            }
            return s;
        }());
    auto meta = reprocessedMetadata(source->metadata, a, calibrationText, asked);
    if (!meta) {
        progress.done();
        return fail(kExitUsage, fmt::format("{}: {}", a.recording, meta.error().message));
    }
    auto writer = RecordingWriter::create(partial, *meta);
    if (!writer) {
        progress.done();
        return fail(exitCodeForCreate(writer.error().code), writer.error().message);
    }
    RecordingWriterSink sink(**writer);
    auto summary = reprocess(*board, *source, o, sink);
    const int closed = (*writer)->close();
    progress.done();
    const auto removePartial = [&] {
        std::error_code ignored;
        fs::remove(partial, ignored);
    };
    if (!summary) {
        removePartial();
        return fail(kExitUsage, fmt::format("{}: {}", a.recording, summary.error().message));
    }
    const int err = sink.firstError != 0 ? sink.firstError : closed;
    if (err != 0) {
        removePartial();
        return fail(kExitRuntime,
                    fmt::format("writing '{}': {}", partial, std::strerror(err < 0 ? -err : err)));
    }
    // The target may have changed while this ran: still never rename over anything but a
    // regular file.
    if (auto still = exporter::regularOutputTarget(target->string()); !still || *still != *target) {
        removePartial();
        return fail(kExitUsage, still ? fmt::format("'{}' changed while reprocessing", a.output)
                                      : still.error().message);
    }
    fs::rename(partial, *target, ec);
    if (ec) {
        const std::string msg =
            fmt::format("rename '{}' to '{}': {}", partial, target->string(), ec.message());
        removePartial();
        return fail(kExitRuntime, msg);
    }
    part.published();
    const double wallS =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - wallStart).count();
    if (source->damagedBytes > 0 || source->malformed > 0 || source->outOfOrder > 0) {
        fmt::print(stderr,
                   "caphub reprocess: the recording is damaged: {} bytes skipped, {} malformed "
                   "record(s), {} raw sample(s) not after their sensor's previous one; "
                   "reprocessed what was readable\n",
                   source->damagedBytes, source->malformed, source->outOfOrder);
    }
    fmt::print("{}: {} samples ({:.3f} s), {} orientations, {} poses at {:g} Hz{}\n", a.output,
               summary->samples, summary->durationS, summary->orientations, summary->poses,
               a.poseRateHz, a.smooth ? ", smoothed" : "");
    fmt::print("body calibration: {}\n", summary->calibration);
    if (summary->kneeHeadingDeg) {
        fmt::print("capture heading from the knees' axes over the take: turned {:+.2f} deg\n",
                   *summary->kneeHeadingDeg);
    }
    fmt::print("{:.2f} s of computing: {:.0f}x real time\n", wallS,
               wallS > 0 ? summary->durationS / wallS : 0.0);
    return kExitOk;
}

}  // namespace

void addReprocessCommand(CLI::App& app, int& exitCode) {
    auto a = std::make_shared<ReprocessArgs>();
    CLI::App* cmd = app.add_subcommand(
        "reprocess",
        "Run calibration, fusion and body again on a recording's raw samples into a new one");
    cmd->add_option("REC", a->recording, "A .cap recording with raw samples")->required();
    cmd->add_option("-o,--output", a->output, "The recording to write")
        ->required()
        ->check(nonEmptyPath());
    cmd->add_option("--calibrate", a->calibrate,
                    "Body calibration: tpose, npose or tn (T-pose then N-pose) held at --at, or "
                    "none (nominal mountings); default: what the recording did")
        ->check(CLI::IsMember({"tpose", "npose", "tn", "none"}));
    cmd->add_option("--at", a->at,
                    "When the calibration pose was held: seconds from the first sample "
                    "(tn: give it twice)")
        ->check(finiteNonNegative());
    cmd->add_option("--calibration", a->calibration,
                    "Sensor calibration file (caphub calibrate) instead of the recording's")
        ->check(nonEmptyPath());
    cmd->add_option("--pose-rate", a->poseRateHz, "Poses per second")
        ->check(finiteRange(1.0, 1000.0))
        ->capture_default_str();
    auto* smooth = cmd->add_flag("--smooth", a->smooth,
                                 "Non-causal pass over the whole take: forward-backward "
                                 "orientations, and the capture heading from the knees' axes over "
                                 "the whole take (docs/reprocess.md)");
    addSmoothHeadingOption(*cmd, a->smoothHeading, "--smooth");
    cmd->add_flag("--no-knee-heading", a->noKneeHeading,
                  "With --smooth, keep the calibration's capture heading (do not correct it from "
                  "the knees' axes)")
        ->needs(smooth);
    cmd->callback([&exitCode, a] { exitCode = runReprocess(*a); });
}

}  // namespace caphub::firmware
