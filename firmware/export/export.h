// `caphub export` without the command line: a recording's poses to BVH, glb, CSV or .sto
// (docs/exports.md). The output is written beside the target and renamed into place, so a
// failed export leaves no half-written file.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <string_view>

#include "firmware/export/pose_track.h"
#include "firmware/export/writers.h"
#include "hal/core/error.h"

namespace caphub::firmware::exporter {

enum class Format { Bvh, Glb, Csv, Sto };

std::optional<Format> parseFormat(std::string_view name);
std::string_view formatName(Format f);

struct ExportOptions {
    Format format = Format::Bvh;
    TrackOptions track;
    std::string names = "hanim";                                 // hanim, cmu, unity or a map file
    double unitsPerM = 1;                                        // bvh and csv: 1 (m) or 100 (cm)
    bool referenceFrame = false;                                 // bvh: the T-pose as frame 0
    StoOrientations stoOrientations = StoOrientations::Sensors;  // sto: whose orientations
};

struct ExportSummary {
    std::size_t frames = 0;  // written, the reference frame included
    double durationS = 0;    // of the exported frames
    double rateHz = 0;
    std::uint64_t fileBytes = 0;
    // From the reading: what was skipped.
    std::uint64_t poseRecords = 0;
    std::uint64_t malformedPoses = 0;
    std::uint64_t outOfOrderPoses = 0;
    std::uint64_t damagedBytes = 0;
    std::uint64_t damageRanges = 0;
    std::uint64_t tornTailBytes = 0;
    std::string subjectSource;
    // Segments not measured in the exported frames (held at their last measured rotation).
    std::vector<NotMeasuredSpan> notMeasured;
};

// Progress: the stage ("reading", "writing") and its fraction done in [0, 1].
using StageProgressFn = std::function<void(std::string_view, double)>;

// What made an export fail: something it was given (an option, the recording or names file:
// missing, not a file, malformed, without poses; an output path it may not write: `caphub export`
// exits 2), or the work itself (reading or writing failed part-way: exits 1).
enum class FailureKind { Input, Work };

// Everything given is checked before the first byte is written; the output goes to OUT.part
// beside the file it replaces, renamed over it only when complete (docs/exports.md).
Result<ExportSummary> exportRecording(const std::string& recordingPath,
                                      const std::string& outputPath, const ExportOptions& options,
                                      const StageProgressFn& progress = {},
                                      FailureKind* failure = nullptr);

}  // namespace caphub::firmware::exporter
