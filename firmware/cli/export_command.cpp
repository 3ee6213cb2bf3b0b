// caphub export: a recording's poses to BVH, binary glTF, CSV or OpenSim .sto
// (firmware/export, docs/exports.md), with progress on a terminal and a one-line summary.
#include <cmath>
#include <memory>
#include <optional>
#include <string>

#include <fmt/format.h>
#include <unistd.h>

#include "board/segment.h"
#include "firmware/cli/app.h"
#include "firmware/cli/commands.h"
#include "firmware/cli/number_checks.h"
#include "firmware/cli/terminal_progress.h"
#include "firmware/export/export.h"
#include "firmware/export/output_file.h"
#include "firmware/export/partial_output.h"

namespace caphub::firmware {

namespace {

struct ExportArgs {
    std::string recording;
    std::string output;
    std::string format;
    std::string names = "hanim";
    std::string units = "m";
    std::optional<double> rateHz;
    std::optional<double> fromS;
    std::optional<double> toS;
    bool referenceFrame = false;
    std::string orientations;  // sto: sensors (default) or segments
};

std::string sizeText(std::uint64_t bytes) {
    if (bytes >= (1u << 20)) {
        return fmt::format("{:.1f} MiB", static_cast<double>(bytes) / (1 << 20));
    }
    if (bytes >= (1u << 10)) {
        return fmt::format("{:.1f} KiB", static_cast<double>(bytes) / (1 << 10));
    }
    return fmt::format("{} bytes", bytes);
}

int runExport(const ExportArgs& a) {
    using namespace exporter;
    ExportOptions o;
    o.format = *parseFormat(a.format);  // CLI11 checked it
    o.names = a.names;
    o.unitsPerM = a.units == "cm" ? 100 : 1;
    o.referenceFrame = a.referenceFrame;
    o.track.rateHz = a.rateHz;
    o.track.fromS = a.fromS;
    o.track.toS = a.toS;
    if (a.referenceFrame && o.format != Format::Bvh) {
        fmt::print(stderr, "caphub export: --reference-frame is for bvh only\n");
        return kExitUsage;
    }
    if (!a.orientations.empty() && o.format != Format::Sto) {
        fmt::print(stderr, "caphub export: --orientations is for sto only\n");
        return kExitUsage;
    }
    o.stoOrientations =
        a.orientations == "segments" ? StoOrientations::Segments : StoOrientations::Sensors;

    // Ctrl-C or SIGTERM during the export removes the part it writes beside the target first.
    std::optional<PartialOutput> part;
    if (auto target = regularOutputTarget(a.output)) {
        part.emplace(target->string() + ".part");
    }
    TerminalProgress progress("caphub export", 8);
    FailureKind failure = FailureKind::Work;
    auto summary = exportRecording(
        a.recording, a.output, o, [&](std::string_view stage, double f) { progress(stage, f); },
        &failure);
    progress.done();
    if (!summary) {
        fmt::print(stderr, "caphub export: {}\n", summary.error().message);
        return failure == FailureKind::Input ? kExitUsage : kExitRuntime;
    }
    if (part) {
        part->published();  // renamed over the target
    }
    const ExportSummary& s = *summary;
    if (s.damagedBytes > 0 || s.malformedPoses > 0 || s.outOfOrderPoses > 0) {
        fmt::print(stderr,
                   "caphub export: the recording is damaged: skipped {} bytes in {} damaged "
                   "range(s), {} malformed and {} out-of-order pose record(s); exported the {} "
                   "good pose records (gaps interpolated)\n",
                   s.damagedBytes, s.damageRanges, s.malformedPoses, s.outOfOrderPoses,
                   s.poseRecords);
    }
    if (!s.notMeasured.empty()) {
        // Held at their last measured rotation in the file: said here for every format, and
        // listed in the file where the format has room (CSV's not_measured column, glb's
        // animation extras).
        std::string spans;
        for (const auto& span : s.notMeasured) {
            spans += fmt::format("{}{} {:.3f}-{:.3f} s", spans.empty() ? "" : ", ",
                                 board::segmentName(span.segment), span.fromS, span.toS);
        }
        fmt::print(stderr,
                   "caphub export: segments not measured (no sensor on them, or their sensor out; "
                   "held at their last "
                   "measured rotation): {}\n",
                   spans);
    }
    if (s.subjectSource.rfind("default", 0) == 0 && o.format != Format::Glb &&
        o.format != Format::Sto) {
        fmt::print(stderr, "caphub export: segment lengths: {}\n", s.subjectSource);
    }
    fmt::print("{}: {} frames, {:.3f} s at {:g} Hz, {} ({})\n", a.output, s.frames, s.durationS,
               s.rateHz, sizeText(s.fileBytes), formatName(o.format));
    return kExitOk;
}

}  // namespace

void addExportCommand(CLI::App& app, int& exitCode) {
    auto a = std::make_shared<ExportArgs>();
    CLI::App* cmd =
        app.add_subcommand("export", "Export a recording to BVH, glTF (.glb), CSV or OpenSim .sto");
    cmd->add_option("REC", a->recording, "A .cap recording with pose records")->required();
    cmd->add_option("--format", a->format, "Output format")
        ->required()
        ->check(CLI::IsMember({"bvh", "glb", "csv", "sto"}));
    cmd->add_option("-o,--output", a->output, "The file to write")
        ->required()
        ->check(nonEmptyPath());
    cmd->add_option("--rate", a->rateHz, "Frames per second (default: the recording's pose rate)")
        ->check(finitePositive());
    cmd->add_option("--names", a->names,
                    "Joint names: hanim, cmu, unity, opensim (sto: OpenSim model bodies), or a "
                    "TOML map file (segment = \"name\")")
        ->check(nonEmptyPath())
        ->capture_default_str();
    cmd->add_option("--units", a->units, "Length unit of bvh and csv")
        ->check(CLI::IsMember({"m", "cm"}))
        ->capture_default_str();
    cmd->add_option("--from", a->fromS, "Start, seconds from the first pose")
        ->check(finiteNonNegative());
    cmd->add_option("--to", a->toS, "End, seconds from the first pose")->check(finiteNonNegative());
    cmd->add_option("--orientations", a->orientations,
                    "sto: the sensors' orientations (default; what OpenSense expects) or the "
                    "segments'")
        ->check(CLI::IsMember({"sensors", "segments"}));
    cmd->add_flag("--reference-frame", a->referenceFrame,
                  "bvh: prepend the reference pose (T-pose) as the first frame");
    cmd->callback([&exitCode, a] { exitCode = runExport(*a); });
}

}  // namespace caphub::firmware
