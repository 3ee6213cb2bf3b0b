// caphub import: other systems' recordings into a .cap with raw samples (docs/import.md):
// Xsens MT Manager text exports, one file per sensor, with a small mapping file from sensor id
// to segment and the subject's height; and caphub's own per-sensor streams in the BROAD layout
// (`caphub sim --all`, firmware/cli/import_broad.*).
#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <toml++/toml.h>

#include "board/loader.h"
#include "firmware/calibration_file.h"
#include "firmware/cli/app.h"
#include "firmware/cli/commands.h"
#include "firmware/cli/import_broad.h"
#include "firmware/cli/info.h"
#include "firmware/cli/number_checks.h"
#include "firmware/export/partial_output.h"
#include "firmware/io/xsens_text.h"
#include "firmware/recording/writer.h"
#include "firmware/runtime/recorder_stage.h"
#include "fusion/body/body_tracker.h"
#include "hal/core/input_file.h"

namespace caphub::firmware {

namespace {

struct ImportArgs {
    std::vector<std::string> files;
    std::string map;
    std::string output;
    double magFieldUt = 50;
    // The pose held at the start: npose, tpose or none; empty: npose for Xsens, none for BROAD.
    std::string calibrate;
    double poseRateHz = 60;
    std::string format = "auto";  // auto, xsens, broad
    std::string board;            // BROAD: the board the streams were simulated on
};

// The mapping file: `height_m = 1.80` (optional) and a [sensors] table of device id = segment.
struct ImportMap {
    std::optional<double> heightM;
    std::map<std::string, board::Segment> segmentOf;
};

Result<ImportMap> readImportMap(const std::string& path, bool needSensors) {
    auto text = readInputFile(path);
    if (!text) {
        return text.error();
    }
    toml::table root;
    try {
        root = toml::parse(*text, path);
    } catch (const toml::parse_error& e) {
        return Error{EINVAL, fmt::format("{}:{}:{}: {}", path, e.source().begin.line,
                                         e.source().begin.column, e.description())};
    }
    ImportMap m;
    const auto where = [&](const toml::node& n) {
        return fmt::format("{}:{}:{}", path, n.source().begin.line, n.source().begin.column);
    };
    for (const auto& [key, node] : root) {
        if (key.str() == "height_m") {
            const auto h = node.value<double>();
            if (!h || !(*h >= 0.5 && *h <= 2.5)) {
                return Error{EINVAL,
                             fmt::format("{}: height_m: expected the subject's height in metres, "
                                         "0.5-2.5",
                                         where(node))};
            }
            m.heightM = *h;
        } else if (key.str() == "sensors") {
            const auto* t = node.as_table();
            if (t == nullptr) {
                return Error{EINVAL, fmt::format("{}: sensors: expected a table of sensor id = "
                                                 "\"segment\"",
                                                 where(node))};
            }
            std::map<board::Segment, std::string> used;
            for (const auto& [id, seg] : *t) {
                const auto name = seg.value<std::string>();
                const auto s = name ? board::findSegment(*name) : std::nullopt;
                if (!s) {
                    return Error{EINVAL,
                                 fmt::format("{}: sensors.{}: expected a segment name (pelvis, "
                                             "l_thigh, r_calf, ... board/segment.h)",
                                             where(seg), id.str())};
                }
                if (auto [it, fresh] = used.emplace(*s, std::string(id.str())); !fresh) {
                    return Error{EINVAL, fmt::format("{}: sensors.{}: segment '{}' is already "
                                                     "sensor {}'s (one sensor per segment)",
                                                     where(seg), id.str(), *name, it->second)};
                }
                m.segmentOf.emplace(std::string(id.str()), *s);
            }
        } else {
            return Error{EINVAL, fmt::format("{}: unknown key '{}' (expected height_m and "
                                             "[sensors])",
                                             where(node), key.str())};
        }
    }
    if (m.segmentOf.empty() && needSensors) {
        return Error{EINVAL, fmt::format("{}: no [sensors] table (sensor id = \"segment\")", path)};
    }
    return m;
}

// A board file standing for the imported suit: one simulated bus per sensor at 3.4 MHz (the
// bus budget fits the imported chip's 10 kHz there; at 400 kHz a 2 kHz take did not), the sensors
// on their segments at the file's rate, nominal mountings unknown (identity): a body calibration
// finds them.
std::string importedBoardText(const std::vector<XsensFile>& files,
                              const std::vector<board::Segment>& segments, double heightM) {
    std::string b;
    b += "schema = 1\nname = \"imported-xsens\"\n";
    b += "description = \"Imported from Xsens MT Manager text exports\"\n\n";
    b += fmt::format("[subject]\nheight_m = {}\n", heightM);
    for (std::size_t i = 0; i < files.size(); ++i) {
        b += fmt::format(
            "\n[[bus]]\nname = \"import-{0}\"\ntype = \"sim\"\nprotocol = \"i2c\"\n"
            "clock_hz = 3_400_000\n\n[[sensor]]\nname = {1}\nsegment = \"{2}\"\n"
            "chip = \"imported\"\nbus = \"import-{0}\"\naddress = 0x68\n"
            "drdy = \"gpiochip0:{0}\"\nodr_hz = {3}\naccel_range_g = 16\ngyro_range_dps = 2000\n",
            i, tomlString(files[i].deviceId), board::segmentName(segments[i]), files[i].rateHz);
    }
    return b;
}

int runXsensImport(const ImportArgs& a);

int runImport(const ImportArgs& given) {
    ImportArgs a = given;
    const bool broad = a.format == "broad" || (a.format == "auto" && looksLikeBroad(a.files));
    if (!broad) {
        if (a.map.empty()) {
            fmt::print(stderr,
                       "caphub import: Xsens text exports need --map (sensor id = segment); "
                       "docs/import.md\n");
            return kExitUsage;
        }
        if (!a.board.empty()) {
            fmt::print(stderr, "caphub import: --board is for BROAD-layout streams only\n");
            return kExitUsage;
        }
        if (a.calibrate.empty()) {
            a.calibrate = "npose";
        }
        return runXsensImport(a);
    }
    BroadImportArgs b;
    b.inputs = a.files;
    b.output = a.output;
    b.board = a.board;
    b.calibrate = a.calibrate.empty() ? "none" : a.calibrate;
    b.poseRateHz = a.poseRateHz;
    if (!a.map.empty()) {
        auto map = readImportMap(a.map, false);
        if (!map) {
            fmt::print(stderr, "caphub import: {}\n", map.error().message);
            return kExitUsage;
        }
        b.segmentOf = map->segmentOf;
        b.heightM = map->heightM;
        b.mapPath = a.map;
    }
    return runBroadImport(b);
}

int runXsensImport(const ImportArgs& a) {
    auto map = readImportMap(a.map, true);
    if (!map) {
        fmt::print(stderr, "caphub import: {}\n", map.error().message);
        return kExitUsage;
    }
    std::vector<XsensFile> files;
    std::vector<board::Segment> segments;
    std::set<std::string> ids;
    for (const auto& path : a.files) {
        auto f = readXsensText(path);
        if (!f) {
            fmt::print(stderr, "caphub import: {}\n", f.error().message);
            return kExitUsage;
        }
        const auto it = map->segmentOf.find(f->deviceId);
        if (it == map->segmentOf.end()) {
            fmt::print(stderr,
                       "caphub import: {}: sensor {} has no segment in {} (add {} = \"r_calf\", "
                       "or the segment it was on, to its [sensors])\n",
                       path, f->deviceId, a.map, f->deviceId);
            return kExitUsage;
        }
        if (!ids.insert(f->deviceId).second) {
            fmt::print(stderr, "caphub import: {}: sensor {} is given twice\n", path, f->deviceId);
            return kExitUsage;
        }
        if (!files.empty() && std::abs(f->rateHz - files.front().rateHz) > 1e-9) {
            fmt::print(stderr, "caphub import: {}: {:g} Hz, but {} is {:g} Hz: one rate per take\n",
                       path, f->rateHz, files.front().path, files.front().rateHz);
            return kExitUsage;
        }
        segments.push_back(it->second);
        files.push_back(std::move(*f));
    }

    const std::string boardText = importedBoardText(files, segments, map->heightM.value_or(1.75));
    const board::LoadResult loaded = board::loadBoardText(boardText, "imported board");
    if (!loaded.ok()) {
        fmt::print(stderr, "caphub import: the board made for the take does not load: {}\n",
                   loaded.errors.front().str());
        return kExitRuntime;
    }
    std::string meta;
    meta += "[recording]\n";
    meta += fmt::format("software = {}\n", tomlString(versionLine()));
    meta += "\n[import]\n";
    meta += "format = \"Xsens MT Manager text export\"\n";
    meta += "files = [";
    for (std::size_t i = 0; i < files.size(); ++i) {
        meta += fmt::format("{}{}", i == 0 ? "" : ", ", tomlString(files[i].path));
    }
    meta += "]\n";
    meta += fmt::format("map = {}\n", tomlString(a.map));
    meta += fmt::format("rate_hz = {}\n", files.front().rateHz);
    meta +=
        fmt::format("mag_scale_ut = {}  # the files' magnetometer units x this\n", a.magFieldUt);
    meta += "orientation = \"the vendor filter's, taken as sensor -> ENU\"\n";
    std::int64_t lost = 0;
    for (const auto& f : files) {
        lost += f.lostPackets;
    }
    meta += fmt::format("lost_samples = {}\n", lost);
    std::vector<std::string> names;
    for (const auto& f : files) {
        names.push_back(f.deviceId);
    }
    meta += importedBoardMetadata("imported-xsens", boardText, names, segments);
    // MT Manager exports calibrated readings (the factory's calibration; the magnetometer's too,
    // normalised to the local field): the recording says so, as a calibration file that leaves
    // them as they are. Without it a reprocess took each magnetometer as raw, so a sensor whose
    // raw heading it could not check got its mounting from the nominal heading, and the knee
    // between two sensors that had the same field turned by tens of degrees.
    CalibrationSet vendorCalibration;
    for (const auto& name : names) {
        fusion::SensorCalibration c;
        c.hasMag = true;
        vendorCalibration[name] = c;
    }
    meta += calibrationMetadata("(the vendor's: the files' readings are calibrated)",
                                formatCalibration(vendorCalibration));

    // One time base: the packet counters of an Awinda take count the same packets; a file
    // starting later starts later in the take. The take starts 1 s into the capture clock.
    const double rate = files.front().rateHz;
    const std::uint16_t firstOfAll = files.front().firstCounter;
    struct Item {
        std::int64_t tNs;
        int sensor;
        std::size_t index;
    };
    std::vector<Item> items;
    std::vector<std::int64_t> offset(files.size());
    for (std::size_t i = 0; i < files.size(); ++i) {
        const auto d = static_cast<std::uint16_t>(files[i].firstCounter - firstOfAll);
        offset[i] = d < 32768 ? d : static_cast<std::int64_t>(d) - 65536;
    }
    const std::int64_t least = *std::min_element(offset.begin(), offset.end());
    const auto timeOf = [&](std::size_t i, std::int64_t packet) {
        return 1'000'000'000 +
               std::llround(static_cast<double>(offset[i] - least + packet) * 1e9 / rate);
    };
    for (std::size_t i = 0; i < files.size(); ++i) {
        for (std::size_t k = 0; k < files[i].samples.size(); ++k) {
            items.push_back({timeOf(i, files[i].samples[k].packet), static_cast<int>(i), k});
        }
    }
    std::stable_sort(items.begin(), items.end(), [](const Item& x, const Item& y) {
        return x.tNs != y.tNs ? x.tNs < y.tNs : x.sensor < y.sensor;
    });

    // Written as OUT.part and renamed to OUT, never over anything, once complete.
    if (::access(a.output.c_str(), F_OK) == 0) {
        fmt::print(stderr, "caphub import: cannot create recording '{}': {}\n", a.output,
                   errnoText(EEXIST));
        return exitCodeForCreate(EEXIST);
    }
    PartialOutput part(a.output + ".part");
    auto writer = RecordingWriter::create(part.path(), meta);
    if (!writer) {
        fmt::print(stderr, "caphub import: {}\n", writer.error().message);
        return exitCodeForCreate(writer.error().code);
    }
    auto& w = **writer;
    int rc = 0;
    std::vector<std::size_t> nextGap(files.size(), 0);

    // Poses from the vendor's orientations, as the body stage of `caphub run` solves them: a
    // body calibration in the pose held at the start (averaged over 1 s from the first sample),
    // then one pose per grid point at the pose rate. Every file needs its orientation columns.
    const bool withPoses = std::all_of(files.begin(), files.end(), [](const XsensFile& f) {
        return !f.orientationColumns.empty();
    });
    std::vector<body::TrackedSensor> tracked;
    for (const auto& s : loaded.board->sensors) {
        tracked.push_back({s.segment, s.mounting, s.positionM});
    }
    body::BodyTrackerOptions to;
    to.rateHz = a.poseRateHz;
    to.solveUncalibrated = a.calibrate == "none";
    to.aidFilters = false;  // the vendor's filter is not aided
    body::BodyTracker tracker(body::Skeleton(*body::dimensionsFromSubject(loaded.board->subject)),
                              tracked, to);
    bool started = false;
    std::array<Eigen::Quaternionf, body::kSegmentCount> joints;
    joints.fill(Eigen::Quaternionf::Identity());
    std::uint64_t poses = 0;
    std::string calibrationNote = "none";
    for (const Item& it : items) {
        const XsensFile& f = files[static_cast<std::size_t>(it.sensor)];
        const XsensSample& s = f.samples[it.index];
        // A gap before this sample: the sensor was out from its last packet to this one.
        auto& g = nextGap[static_cast<std::size_t>(it.sensor)];
        if (g < f.gaps.size() && f.gaps[g].afterPacket + f.gaps[g].missing + 1 == s.packet) {
            const std::string text = fmt::format("{} packet(s) missing in {} before line {}",
                                                 f.gaps[g].missing, f.path, f.gaps[g].line);
            rc = rc != 0 ? rc
                         : w.writeEvent(timestampFromNs(timeOf(static_cast<std::size_t>(it.sensor),
                                                               f.gaps[g].afterPacket)),
                                        cap::EventKind::SensorLost, it.sensor, 0, text);
            rc = rc != 0 ? rc
                         : w.writeEvent(timestampFromNs(it.tNs), cap::EventKind::SensorOnline,
                                        it.sensor, 0, "");
            ++g;
        }
        hal::ImuSample sample;
        sample.t = timestampFromNs(it.tNs);
        sample.accMps2 = s.accMps2.cast<float>();
        sample.gyrRadps = s.gyrRadps.cast<float>();
        if (s.mag) {
            sample.magUt = (*s.mag * a.magFieldUt).cast<float>();
            sample.flags |= hal::ImuSample::kMagFresh;
        }
        rc = rc != 0 ? rc : w.writeRawSample(it.sensor, sample);
        if (s.qEarthSensor) {
            rc = rc != 0 ? rc
                         : w.writeOrientation(it.sensor, sample.t, s.qEarthSensor->cast<float>());
        }
        if (!withPoses || rc != 0) {
            continue;
        }
        if (!started) {
            started = true;
            if (a.calibrate != "none") {
                tracker.startCalibration(a.calibrate == "tpose" ? body::ReferencePoseKind::T
                                                                : body::ReferencePoseKind::N,
                                         sample.t);
            }
        }
        body::SensorUpdate u;
        u.sensor = it.sensor;
        u.t = sample.t;
        u.qEnuSensor = s.qEarthSensor->cast<float>();
        u.specificForceMps2 = sample.accMps2;
        u.rateRadS = sample.gyrRadps;
        const body::TrackerEvents events = tracker.update(u);
        if (events.calibrationFailed) {
            calibrationNote = "failed: " + events.message;
        }
        if (events.calibrated) {
            const body::BodyCalibration& cal = tracker.calibration();
            calibrationNote = fmt::format("{} pose at {:.3f} s", body::toString(cal.method),
                                          toSeconds(sample.t.time_since_epoch()) - 1.0);
            rc = w.writeEvent(sample.t, cap::EventKind::Calibrated, -1, 0,
                              fmt::format("body calibration: {} pose, {} segments (at import)",
                                          body::toString(cal.method), std::popcount(cal.mask)));
            rc = rc != 0 ? rc
                         : w.writeMetadata(sample.t, "[body_calibration]\ntext = " +
                                                         tomlString(body::toText(cal)) + "\n");
        }
        while (rc == 0) {
            const std::optional<Timestamp> due = tracker.due(sample.t);
            if (!due) {
                break;
            }
            const body::TrackedPose& p = tracker.solveAt(*due);
            const std::uint32_t notMeasured = ~p.valid & ((1u << body::kSegmentCount) - 1);
            for (std::size_t j = 0; j < joints.size(); ++j) {
                joints[j] = p.pose->qLocal[j].cast<float>();
            }
            rc = w.writePose(p.t, p.pose->positionM[0].cast<float>(), joints, notMeasured);
            ++poses;
        }
    }
    const int closed = w.close();
    if (rc != 0 || closed != 0) {
        fmt::print(stderr, "caphub import: writing '{}': {}\n", part.path(),
                   errnoText(rc != 0 ? rc : closed));
        return kExitRuntime;
    }
    if (auto published = part.publishNew(a.output); !published) {
        fmt::print(stderr, "caphub import: {}\n", published.error().message);
        return exitCodeForCreate(published.error().code);
    }
    for (std::size_t i = 0; i < files.size(); ++i) {
        const auto& f = files[i];
        fmt::print("{} ({}): {} samples at {:g} Hz on {}{}, {} lost in {} gap(s){}\n", f.deviceId,
                   f.path, f.samples.size(), f.rateHz, board::segmentName(segments[i]),
                   f.hasMag ? "" : " (no magnetometer)", f.lostPackets, f.gaps.size(),
                   f.orientationColumns.empty()
                       ? ", no orientation"
                       : fmt::format(", orientation ({})", f.orientationColumns));
    }
    fmt::print(
        "{}: {} sensors, {:.3f} s\n", a.output, files.size(),
        static_cast<double>(items.empty() ? 0 : items.back().tNs - items.front().tNs) * 1e-9);
    if (withPoses) {
        fmt::print("poses: {} at {:g} Hz from the vendor's orientations; body calibration: {}\n",
                   poses, a.poseRateHz, calibrationNote);
    } else {
        fmt::print("poses: none (a file has no orientation columns)\n");
    }
    return kExitOk;
}

}  // namespace

void addImportCommand(CLI::App& app, int& exitCode) {
    auto a = std::make_shared<ImportArgs>();
    CLI::App* cmd = app.add_subcommand(
        "import",
        "Import recordings into a .cap: Xsens MT Manager text exports, or caphub's own "
        "BROAD-layout streams (caphub sim --all)");
    cmd->add_option("FILES", a->files,
                    "The sensors' files, one per sensor (BROAD: or the folder holding them)")
        ->required();
    cmd->add_option("--map", a->map,
                    "TOML: height_m = H and a [sensors] table of sensor id = \"segment\" "
                    "(required for Xsens; BROAD: overrides the files' segments)")
        ->check(nonEmptyPath());
    cmd->add_option("--format", a->format,
                    "xsens, broad, or auto (broad for a folder or .csv/.csv.gz files)")
        ->check(CLI::IsMember({"auto", "xsens", "broad"}))
        ->capture_default_str();
    cmd->add_option("--board", a->board,
                    "BROAD: the board the streams were simulated on (nominal mountings and "
                    "positions); default: the one their comment lines name");
    cmd->add_option("-o,--output", a->output, "The .cap to write (not overwritten)")
        ->required()
        ->check(nonEmptyPath());
    cmd->add_option("--mag-field-ut", a->magFieldUt,
                    "The local field in uT: magnetometer units normalised to it are scaled by it")
        ->check(finiteRange(1.0, 1000.0))
        ->capture_default_str();
    cmd->add_option("--calibrate", a->calibrate,
                    "Poses: the pose the subject holds for the first second (npose, tpose), or "
                    "none (nominal mountings); default npose for Xsens, none for BROAD")
        ->check(CLI::IsMember({"npose", "tpose", "none"}));
    cmd->add_option("--pose-rate", a->poseRateHz, "Poses per second")
        ->check(finiteRange(1.0, 1000.0))
        ->capture_default_str();
    cmd->callback([&exitCode, a] { exitCode = runImport(*a); });
}

}  // namespace caphub::firmware
