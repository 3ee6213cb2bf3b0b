#include "firmware/export/export.h"

#include <filesystem>

#include <fmt/format.h>
#include <unistd.h>

#include "firmware/export/joint_names.h"
#include "firmware/export/output_file.h"
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
                                      const StageProgressFn& progress, FailureKind* failure) {
    namespace fs = std::filesystem;
    const auto fail = [failure](FailureKind kind, Error e) {
        if (failure != nullptr) {
            *failure = kind;
        }
        return e;
    };
    if (!(options.unitsPerM == 1 || options.unitsPerM == 100)) {
        return fail(FailureKind::Input, Error{EINVAL, "units: expected m or cm"});
    }
    if (options.format == Format::Glb && options.unitsPerM != 1) {
        return fail(FailureKind::Input,
                    Error{EINVAL,
                          "--units cm: glTF is in metres by definition (--units is for bvh "
                          "and csv)"});
    }
    // Where the output goes: over a regular file, or into the one a symbolic link names.
    auto target = regularOutputTarget(outputPath);
    if (!target) {
        return fail(FailureKind::Input, target.error());
    }
    std::error_code ec;
    if (fs::exists(*target, ec) && fs::equivalent(recordingPath, *target, ec)) {
        return fail(FailureKind::Input,
                    Error{EINVAL, fmt::format("-o '{}' is the recording itself", outputPath)});
    }
    const fs::path folder = target->has_parent_path() ? target->parent_path() : fs::path(".");
    if (!fs::is_directory(folder, ec)) {
        return fail(FailureKind::Input,
                    Error{ENOENT, fmt::format("-o '{}': the folder '{}' does not exist", outputPath,
                                              folder.string())});
    }
    if (::access(folder.c_str(), W_OK) != 0) {
        return fail(FailureKind::Input,
                    errnoError(errno, fmt::format("-o '{}': cannot write in '{}'", outputPath,
                                                  folder.string())));
    }
    auto names = jointNamesFor(options.names);
    if (!names) {
        return fail(FailureKind::Input, names.error());
    }
    if (names->stoOnly && options.format != Format::Sto) {
        return fail(FailureKind::Input,
                    Error{EINVAL, fmt::format("--names {}: it names OpenSim model bodies, for "
                                              "--format sto only",
                                              names->setName)});
    }
    auto reader = RecordingReader::open(recordingPath);
    if (!reader) {
        return fail(FailureKind::Input, reader.error());
    }
    const auto fileBytes = fs::file_size(recordingPath, ec);
    auto track = readPoseTrack(**reader, options.track, ec ? 0 : fileBytes, [&](double f) {
        if (progress) {
            progress("reading", f);
        }
    });
    if (!track) {
        // A window or rate the poses do not allow, or no poses at all, is in what was given; a
        // read that failed part-way is not.
        const bool given = track.error().code == EINVAL || track.error().code == ENODATA ||
                           track.error().code == EFBIG;
        return fail(given ? FailureKind::Input : FailureKind::Work,
                    Error{track.error().code,
                          fmt::format("'{}': {}", recordingPath, track.error().message)});
    }

    if (options.format == Format::Sto) {
        if (auto columns = stoColumns(*track, *names, options.stoOrientations); !columns) {
            return fail(FailureKind::Input, Error{EINVAL, fmt::format("'{}': {}", recordingPath,
                                                                      columns.error().message)});
        }
    }

    // Written beside the target, then renamed over it: never a half-written OUT.
    const std::string partial = target->string() + ".part";
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
            written = writeSto(*track, *names, options.stoOrientations, partial, writing);
            break;
        case Format::Glb:
            written = writeGlb(*track, *names, partial, writing);
            break;
    }
    if (!written) {
        fs::remove(partial, ec);
        return fail(FailureKind::Work, written.error());
    }
    // The target may have changed while the export ran: still never rename over anything but a
    // regular file.
    if (auto still = regularOutputTarget(target->string()); !still || *still != *target) {
        fs::remove(partial, ec);
        return fail(FailureKind::Input,
                    still ? Error{EINVAL, fmt::format("'{}' changed during the export; it is "
                                                      "left as it is",
                                                      target->string())}
                          : still.error());
    }
    fs::rename(partial, *target, ec);
    if (ec) {
        // The message is built before anything else can overwrite the error.
        Error e{ec.value(),
                fmt::format("rename '{}' to '{}': {}", partial, target->string(), ec.message())};
        std::error_code ignored;
        fs::remove(partial, ignored);
        return fail(FailureKind::Work, std::move(e));
    }

    ExportSummary s;
    s.frames =
        track->frames.size() + (options.format == Format::Bvh && options.referenceFrame ? 1 : 0);
    s.durationS = track->frames.back().tS - track->frames.front().tS;
    s.rateHz = track->rateHz;
    s.fileBytes = fs::file_size(*target, ec);
    s.poseRecords = track->poseRecords;
    s.malformedPoses = track->malformedPoses;
    s.outOfOrderPoses = track->outOfOrderPoses;
    s.damagedBytes = track->damagedBytes;
    s.damageRanges = track->damageRanges;
    s.tornTailBytes = track->tornTailBytes;
    s.subjectSource = track->subjectSource;
    s.notMeasured = notMeasuredSpans(*track);
    return s;
}

}  // namespace caphub::firmware::exporter
