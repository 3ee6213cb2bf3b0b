#include "firmware/export/export.h"

#include <filesystem>

#include <fmt/format.h>

#include "firmware/export/joint_names.h"
#include "firmware/export/writers.h"
#include "firmware/recording/reader.h"

namespace caphub::firmware::exporter {

std::optional<Format> parseFormat(std::string_view name) {
    if (name == "bvh") {
        return Format::Bvh;
    }
    if (name == "glb") {
        return Format::Glb;
    }
    if (name == "csv") {
        return Format::Csv;
    }
    if (name == "sto") {
        return Format::Sto;
    }
    return std::nullopt;
}

std::string_view formatName(Format f) {
    switch (f) {
        case Format::Bvh:
            return "bvh";
        case Format::Glb:
            return "glb";
        case Format::Csv:
            return "csv";
        case Format::Sto:
            return "sto";
    }
    return "?";
}

Result<ExportSummary> exportRecording(const std::string& recordingPath,
                                      const std::string& outputPath, const ExportOptions& options,
                                      const StageProgressFn& progress) {
    namespace fs = std::filesystem;
    if (!(options.unitsPerM == 1 || options.unitsPerM == 100)) {
        return Error{EINVAL, "units: expected m or cm"};
    }
    if (options.format == Format::Glb && options.unitsPerM != 1) {
        return Error{EINVAL,
                     "--units cm: glTF is in metres by definition (--units is for bvh "
                     "and csv)"};
    }
    std::error_code ec;
    if (fs::exists(outputPath, ec) && fs::equivalent(recordingPath, outputPath, ec)) {
        return Error{EINVAL, fmt::format("-o '{}' is the recording itself", outputPath)};
    }
    auto names = jointNamesFor(options.names);
    if (!names) {
        return names.error();
    }
    auto reader = RecordingReader::open(recordingPath);
    if (!reader) {
        return reader.error();
    }
    const auto fileBytes = fs::file_size(recordingPath, ec);
    auto track = readPoseTrack(**reader, options.track, ec ? 0 : fileBytes, [&](double f) {
        if (progress) {
            progress("reading", f);
        }
    });
    if (!track) {
        return Error{track.error().code,
                     fmt::format("'{}': {}", recordingPath, track.error().message)};
    }

    // Written beside the target, then renamed over it: never a half-written OUT.
    const std::string partial = outputPath + ".part";
    const ProgressFn writing = [&](double f) {
        if (progress) {
            progress("writing", f);
        }
    };
    Result<void> written;
    switch (options.format) {
        case Format::Bvh:
            written = writeBvh(*track, *names, {options.unitsPerM, options.referenceFrame}, partial,
                               writing);
            break;
        case Format::Csv:
            written = writeCsv(*track, *names, options.unitsPerM, partial, writing);
            break;
        case Format::Sto:
            written = writeSto(*track, *names, partial, writing);
            break;
        case Format::Glb:
            written = writeGlb(*track, *names, partial, writing);
            break;
    }
    if (!written) {
        fs::remove(partial, ec);
        return written.error();
    }
    fs::rename(partial, outputPath, ec);
    if (ec) {
        fs::remove(partial, ec);
        return Error{ec.value(), fmt::format("rename to '{}': {}", outputPath, ec.message())};
    }

    ExportSummary s;
    s.frames =
        track->frames.size() + (options.format == Format::Bvh && options.referenceFrame ? 1 : 0);
    s.durationS = track->frames.back().tS - track->frames.front().tS;
    s.rateHz = track->rateHz;
    s.fileBytes = fs::file_size(outputPath, ec);
    s.poseRecords = track->poseRecords;
    s.malformedPoses = track->malformedPoses;
    s.outOfOrderPoses = track->outOfOrderPoses;
    s.damagedBytes = track->damagedBytes;
    s.damageRanges = track->damageRanges;
    s.tornTailBytes = track->tornTailBytes;
    s.subjectSource = track->subjectSource;
    return s;
}

}  // namespace caphub::firmware::exporter
