// caphub version and caphub info: what this build is and what it supports.
#include <algorithm>
#include <iterator>
#include <map>
#include <sstream>

#include <fmt/format.h>

#include "board/segment.h"
#include "firmware/cli/app.h"
#include "firmware/cli/commands.h"
#include "firmware/cli/data_dir.h"
#include "firmware/cli/info.h"
#include "firmware/cli/number_checks.h"
#include "firmware/recording/reader.h"
#include "firmware/version.h"
#include "hal/chip_info.h"

namespace caphub::firmware {

std::string versionLine() {
    return fmt::format("caphub {} ({}, {})", kVersion, kGitRevision, kBuildType);
}

namespace {

std::string joinNumbers(std::span<const double> v, const char* unit) {
    std::string out;
    for (double x : v) {
        out += fmt::format("{}{:g}", out.empty() ? "" : ", ", x);
    }
    return out + " " + unit;
}

void printInfo() {
    fmt::print("{}\n", versionLine());
    const auto dir = dataDir();
    fmt::print("data folder: {}\n\n", dir ? dir->string() : "(none found; set CAPHUB_DATA_DIR)");
    fmt::print("chips:\n");
    for (const auto& c : hal::chipCatalog()) {
        fmt::print("  {:<18} {}\n", c.name, c.description);
        fmt::print("  {:<18} rates {}; accel {}; gyro {}; magnetometer {}\n", "", c.odrRule,
                   joinNumbers(c.accelRangesG, "g"), joinNumbers(c.gyroRangesDps, "dps"),
                   joinNumbers(c.magOdrsHz, "Hz"));
    }
    fmt::print("\nsegments ({}):\n", board::kSegmentCount);
    for (const auto& s : board::kSegments) {
        fmt::print("  {:<12} {}\n", s.name, s.description);
    }
}

}  // namespace

Result<RecordingSummary> summarizeRecording(const std::string& path) {
    auto reader = RecordingReader::open(path);
    if (!reader) {
        return Error{EINVAL, reader.error().message};
    }
    RecordingSummary summary;
    std::string& out = summary.text;
    auto& r = **reader;
    std::map<int, std::uint64_t> perType;
    std::map<int, std::uint64_t> perSensor;
    std::map<int, std::pair<Timestamp, Timestamp>> sensorSpan;
    std::vector<std::string> events;
    // Per joint (segment) the spans of poses in which its sensor was out, in capture time.
    struct Gap {
        Timestamp from{};
        Timestamp to{};
        std::uint64_t poses = 0;
    };
    std::map<int, std::vector<Gap>> gaps;
    std::uint32_t lastMask = 0;
    Eigen::Vector3f rootM;
    std::vector<Eigen::Quaternionf> joints;
    Timestamp first = Timestamp::max();
    Timestamp last = Timestamp::min();
    std::uint64_t samplesBack = 0;
    std::uint64_t posesBack = 0;
    Timestamp lastPoseT = Timestamp::min();
    RecordView v;
    int rc = 0;
    while ((rc = r.next(v)) == 1) {
        ++perType[static_cast<int>(v.type)];
        first = std::min(first, v.t);
        last = std::max(last, v.t);
        int sensor = 0;
        hal::ImuSample sample;
        if (decodeRawSample(v, sensor, sample)) {
            ++perSensor[sensor];
            auto [it, fresh] = sensorSpan.emplace(sensor, std::pair{v.t, v.t});
            if (!fresh) {
                // A sample not after the sensor's one before: a range of records written twice
                // or out of order (export and reprocess skip them).
                samplesBack += v.t <= it->second.second ? 1 : 0;
                it->second.second = std::max(it->second.second, v.t);
            }
        }
        std::uint32_t notMeasured = 0;
        if (decodePose(v, rootM, joints, &notMeasured)) {
            posesBack += v.t <= lastPoseT ? 1 : 0;
            lastPoseT = std::max(lastPoseT, v.t);
            for (int j = 0; j < 32; ++j) {
                if ((notMeasured >> j & 1u) == 0) {
                    continue;
                }
                auto& spans = gaps[j];
                if ((lastMask >> j & 1u) == 0 || spans.empty()) {
                    spans.push_back(Gap{v.t, v.t, 0});
                }
                spans.back().to = v.t;
                ++spans.back().poses;
            }
            lastMask = notMeasured;
        }
        if (v.type == cap::RecordType::Marker && events.size() < 50) {
            events.push_back(fmt::format(
                "  {:10.3f} s  marker: {}", toSeconds(v.t - first),
                std::string(reinterpret_cast<const char*>(v.payload.data()), v.payload.size())));
        }
        cap::EventKind kind{};
        int error = 0;
        std::string text;
        if (decodeEvent(v, kind, sensor, error, text) && events.size() < 50) {
            events.push_back(fmt::format("  {:10.3f} s  {}  sensor {}{}{}", toSeconds(v.t - first),
                                         cap::eventName(kind), sensor,
                                         error != 0 ? " (" + errnoText(error) + ")" : "",
                                         text.empty() ? "" : ": " + text));
        }
    }
    if (rc < 0) {
        return Error{-rc, fmt::format("reading '{}': {}", path, errnoText(rc))};
    }
    fmt::format_to(std::back_inserter(out), "recording {} (format version {})\n", path,
                   r.version());
    const double span = first <= last ? toSeconds(last - first) : 0.0;
    fmt::format_to(std::back_inserter(out), "duration {:.3f} s\n", span);
    fmt::format_to(std::back_inserter(out), "\nmetadata:\n");
    std::istringstream meta(r.metadata());
    std::string line;
    std::string table;
    while (std::getline(meta, line)) {
        if (line.rfind('[', 0) == 0) {
            table = line;
        }
        // The embedded files are long: their size stands in for them.
        if (line.rfind("text = ", 0) == 0) {
            line = fmt::format("text = (the {} file, {} bytes)",
                               table == "[calibration]" ? "calibration" : "board", line.size());
        }
        fmt::format_to(std::back_inserter(out), "  {}\n", line);
    }
    fmt::format_to(std::back_inserter(out), "\nrecords:\n");
    for (const auto& [type, n] : perType) {
        fmt::format_to(std::back_inserter(out), "  {:<12} {}\n",
                       cap::typeName(static_cast<cap::RecordType>(type)), n);
    }
    if (!perSensor.empty()) {
        fmt::format_to(std::back_inserter(out), "\n{:<8} {:>9} {:>9}\n", "sensor", "samples",
                       "rate Hz");
        for (const auto& [sensor, n] : perSensor) {
            const auto& [a, b] = sensorSpan[sensor];
            const double s = toSeconds(b - a);
            fmt::format_to(std::back_inserter(out), "{:<8} {:>9} {:>9.1f}\n", sensor, n,
                           s > 0 ? static_cast<double>(n - 1) / s : 0.0);
        }
    }
    if (!events.empty()) {
        fmt::format_to(std::back_inserter(out), "\nevents:\n");
        for (const auto& e : events) {
            fmt::format_to(std::back_inserter(out), "{}\n", e);
        }
    }
    fmt::format_to(std::back_inserter(out),
                   "\nsegments not measured (no sensor on them, or their sensor out; held in the "
                   "poses): {}",
                   gaps.empty() ? "none\n" : "\n");
    for (const auto& [j, spans] : gaps) {
        const std::string name =
            j < board::kSegmentCount
                ? std::string(board::segmentName(static_cast<board::Segment>(j)))
                : fmt::format("joint {}", j);
        for (const auto& g : spans) {
            fmt::format_to(std::back_inserter(out), "  {:<12} {:10.3f} - {:.3f} s ({} poses)\n",
                           name, toSeconds(g.from - first), toSeconds(g.to - first), g.poses);
        }
    }
    const bool none = r.damage().empty() && samplesBack == 0 && posesBack == 0;
    fmt::format_to(std::back_inserter(out), "\ndamage: {}", none ? "none" : "");
    for (const auto& d : r.damage()) {
        fmt::format_to(std::back_inserter(out), "\n  {} bytes at offset {}: {}", d.bytes, d.offset,
                       d.what);
    }
    if (samplesBack > 0 || posesBack > 0) {
        fmt::format_to(std::back_inserter(out),
                       "\n  {} raw sample(s) and {} pose(s) not after the one before them (records "
                       "written twice or out of order: skipped by export and reprocess)",
                       samplesBack, posesBack);
    }
    fmt::format_to(std::back_inserter(out), "\ntorn tail: {} bytes\n", r.tornTailBytes());
    summary.durationS = span;
    summary.damagedRanges = r.damage().size();
    summary.tornTailBytes = r.tornTailBytes();
    for (const auto& [type, n] : perType) {
        summary.records += n;
        if (static_cast<cap::RecordType>(type) == cap::RecordType::Marker) {
            summary.markers = n;
        } else if (static_cast<cap::RecordType>(type) == cap::RecordType::Pose) {
            summary.poses = n;
        }
    }
    return summary;
}

namespace {

int printRecording(const std::string& path) {
    auto summary = summarizeRecording(path);
    if (!summary) {
        fmt::print(stderr, "caphub info: {}\n", summary.error().message);
        return summary.error().code == EINVAL ? kExitUsage : kExitRuntime;
    }
    fmt::print("{}", summary->text);
    return kExitOk;
}

}  // namespace

void addInfoCommands(CLI::App& app, int& exitCode) {
    app.add_subcommand("version", "Print the version of caphub")->callback([&exitCode] {
        fmt::print("{}\n", versionLine());
        exitCode = kExitOk;
    });
    CLI::App* info = app.add_subcommand(
        "info", "Print a recording's summary, or this build's chips, segments and data folder");
    auto file = std::make_shared<std::string>();
    info->add_option("FILE", *file, "A .cap recording to describe")->check(nonEmptyPath());
    info->callback([&exitCode, file] {
        if (file->empty()) {
            printInfo();
            exitCode = kExitOk;
        } else {
            exitCode = printRecording(*file);
        }
    });
}

}  // namespace caphub::firmware
