#include "firmware/cli/import_broad.h"

#include <algorithm>
#include <cmath>
#include <set>

#include <fmt/format.h>

#include "board/loader.h"
#include "firmware/cli/app.h"
#include "firmware/cli/data_dir.h"
#include "firmware/cli/info.h"
#include "firmware/export/partial_output.h"
#include "firmware/io/broad_csv.h"
#include "firmware/reprocess.h"
#include "firmware/runtime/recorder_stage.h"

namespace caphub::firmware {

namespace {

namespace fs = std::filesystem;

bool broadName(const fs::path& p) {
    const std::string n = p.filename().string();
    return n.ends_with(".csv") || n.ends_with(".csv.gz");
}

std::string stemOf(const fs::path& p) {
    std::string n = p.filename().string();
    for (const char* ext : {".gz", ".csv"}) {
        if (n.ends_with(ext) && n.size() > std::string_view(ext).size()) {
            n.resize(n.size() - std::string_view(ext).size());
        }
    }
    return n;
}

// What `caphub sim` writes in a trial's comment line: "caphub-sim CLIP sensor NAME on SEGMENT
// (board BOARD, profile P, seed S)". Empty fields when the name is not of that form.
struct SimTrialName {
    std::string sensor;
    std::string segment;
    std::string board;
};

SimTrialName parseSimTrialName(const std::string& name) {
    SimTrialName out;
    if (!name.starts_with("caphub-sim ")) {
        return out;
    }
    const std::size_t s = name.find(" sensor ");
    const std::size_t on = name.find(" on ", s == std::string::npos ? 0 : s);
    const std::size_t b = name.find(" (board ");
    if (s == std::string::npos || on == std::string::npos || b == std::string::npos || b < on) {
        return out;
    }
    out.sensor = name.substr(s + 8, on - (s + 8));
    out.segment = name.substr(on + 4, b - (on + 4));
    const std::size_t e = name.find(',', b);
    out.board = name.substr(b + 8, e == std::string::npos ? std::string::npos : e - (b + 8));
    return out;
}

// One sensor's stream as imported.
struct Stream {
    fs::path path;
    std::string name;
    board::Segment segment = board::Segment::Pelvis;
    BroadTrial trial;
    std::string boardName;  // from the comment line, may be empty
    std::int64_t lost = 0;  // samples missing in gaps of the time column
    int gaps = 0;
};

// The board text standing for the imported suit: one simulated bus per sensor (no bus budget
// applies), each sensor on its segment at its stream's rate, with the nominal mounting and
// position of the same-named sensor of the source board when there is one (identity otherwise:
// a body calibration finds the mountings).
std::string importedBoardText(const std::vector<Stream>& streams, const board::Board* source,
                              double heightM) {
    std::string b = "schema = 1\nname = \"imported-broad\"\n";
    b += fmt::format(
        "description = {}\n\n",
        tomlString(source != nullptr
                       ? fmt::format("Imported BROAD-layout streams of board '{}'", source->name)
                       : std::string("Imported BROAD-layout streams")));
    b += fmt::format("[subject]\nheight_m = {}\n", heightM);
    if (source != nullptr && source->subject.massKg) {
        b += fmt::format("mass_kg = {}\n", *source->subject.massKg);
    }
    for (std::size_t i = 0; i < streams.size(); ++i) {
        const Stream& st = streams[i];
        b += fmt::format(
            "\n[[bus]]\nname = \"import-{0}\"\ntype = \"sim\"\nprotocol = \"i2c\"\n"
            "clock_hz = 400_000\n\n[[sensor]]\nname = {1}\nsegment = \"{2}\"\n"
            "chip = \"imported\"\nbus = \"import-{0}\"\naddress = 0x68\n"
            "drdy = \"gpiochip0:{0}\"\nodr_hz = {3}\naccel_range_g = 16\ngyro_range_dps = 2000\n",
            i, tomlString(st.name), board::segmentName(st.segment), st.trial.rateHz);
        if (source == nullptr) {
            continue;
        }
        for (const auto& sc : source->sensors) {
            if (sc.name == st.name && sc.segment == st.segment) {
                const Quatd& q = sc.mounting;
                b += fmt::format(
                    "mounting_quat = [{:.17g}, {:.17g}, {:.17g}, {:.17g}]\n"
                    "position_m = [{:.17g}, {:.17g}, {:.17g}]\n",
                    q.w(), q.x(), q.y(), q.z(), sc.positionM.x(), sc.positionM.y(),
                    sc.positionM.z());
            }
        }
    }
    return b;
}

int fail(int code, const std::string& message) {
    fmt::print(stderr, "caphub import: {}\n", message);
    return code;
}

}  // namespace

bool looksLikeBroad(const std::vector<std::string>& inputs) {
    return std::any_of(inputs.begin(), inputs.end(), [](const std::string& s) {
        std::error_code ec;
        return fs::is_directory(s, ec) || broadName(s);
    });
}

BroadInputs expandBroadInputs(const std::vector<std::string>& inputs) {
    BroadInputs out;
    for (const std::string& in : inputs) {
        std::error_code ec;
        if (!fs::is_directory(in, ec)) {
            out.files.emplace_back(in);
            continue;
        }
        std::vector<fs::path> found;
        for (const auto& e : fs::directory_iterator(in, ec)) {
            const std::string stem = stemOf(e.path());
            if (e.is_regular_file() && broadName(e.path()) && stem != "skeleton") {
                found.push_back(e.path());
            }
        }
        if (ec) {
            out.error = fmt::format("{}: cannot list the folder: {}", in, ec.message());
            return out;
        }
        if (found.empty()) {
            out.error = fmt::format(
                "{}: a folder with no .csv or .csv.gz stream in it (caphub sim "
                "--all writes one per sensor)",
                in);
            return out;
        }
        std::sort(found.begin(), found.end());
        out.files.insert(out.files.end(), found.begin(), found.end());
    }
    return out;
}

std::string importedBoardMetadata(const std::string& boardName, const std::string& boardText,
                                  const std::vector<std::string>& names,
                                  const std::vector<board::Segment>& segments) {
    std::string meta = fmt::format("\n[board]\nname = \"{}\"\npath = \"\"\ntext = {}\n", boardName,
                                   tomlString(boardText));
    meta += "\n[sensors]\nnames = [";
    for (std::size_t i = 0; i < names.size(); ++i) {
        meta += fmt::format("{}{}", i == 0 ? "" : ", ", tomlString(names[i]));
    }
    meta += "]\nsegments = [";
    for (std::size_t i = 0; i < segments.size(); ++i) {
        meta += fmt::format("{}\"{}\"", i == 0 ? "" : ", ", board::segmentName(segments[i]));
    }
    meta += "]\n";
    return meta;
}

int runBroadImport(const BroadImportArgs& a) {
    const BroadInputs inputs = expandBroadInputs(a.inputs);
    if (!inputs.error.empty()) {
        return fail(kExitUsage, inputs.error);
    }
    std::vector<Stream> streams;
    std::set<std::string> names;
    std::set<board::Segment> segments;
    for (const fs::path& path : inputs.files) {
        auto trial = readBroadCsv(path);
        if (!trial) {
            return fail(kExitUsage, trial.error().message);
        }
        Stream st;
        st.path = path;
        const SimTrialName sim = parseSimTrialName(trial->name);
        st.name = sim.sensor.empty() ? stemOf(path) : sim.sensor;
        if (const std::string why = board::nameProblem("sensor", st.name); !why.empty()) {
            return fail(kExitUsage,
                        fmt::format("{}: {} ({})", path.string(), why,
                                    sim.sensor.empty() ? "the file's name: rename the file"
                                                       : "the sensor named in its comment line"));
        }
        st.boardName = sim.board;
        if (const auto it = a.segmentOf.find(st.name); it != a.segmentOf.end()) {
            st.segment = it->second;
        } else if (const auto seg = board::findSegment(sim.segment)) {
            st.segment = *seg;
        } else {
            return fail(kExitUsage,
                        fmt::format("{}:1:1: sensor '{}': no segment (the comment line of `caphub "
                                    "sim` says \"on SEGMENT\"; otherwise give --map with {} = "
                                    "\"pelvis\", or the segment it was on, in [sensors])",
                                    path.string(), st.name, st.name));
        }
        if (!names.insert(st.name).second) {
            return fail(kExitUsage,
                        fmt::format("{}: sensor '{}' is given twice", path.string(), st.name));
        }
        if (!segments.insert(st.segment).second) {
            return fail(kExitUsage,
                        fmt::format("{}: sensor '{}' is on {}, which another file's sensor is on "
                                    "(one sensor per segment)",
                                    path.string(), st.name, board::segmentName(st.segment)));
        }
        st.trial = std::move(*trial);
        streams.push_back(std::move(st));
    }
    if (streams.empty()) {
        return fail(kExitUsage, "no streams to import");
    }

    // The source board: --board, else the one the comment lines name, when it is found.
    std::optional<board::Board> source;
    std::string boardNote;
    const std::string boardName = !a.board.empty() ? a.board : streams.front().boardName;
    if (!a.board.empty()) {
        source = loadCommandBoard(a.board);
        if (!source) {
            return kExitUsage;  // its errors are printed
        }
        boardNote = fmt::format("mountings and positions from board '{}'", source->name);
    } else if (!boardName.empty()) {
        std::error_code ec;
        const fs::path p = resolveBoardFile(boardName);
        if (fs::is_regular_file(p, ec)) {
            const board::LoadResult r = board::loadBoardFile(p);
            if (r.ok()) {
                source = *r.board;
                boardNote = fmt::format("mountings and positions from board '{}' ({})",
                                        source->name, p.string());
            }
        }
        if (!source) {
            boardNote = fmt::format(
                "board '{}' not found: identity nominal mountings (give "
                "--board)",
                boardName);
        }
    } else {
        boardNote = "no board named: identity nominal mountings";
    }
    const double heightM = a.heightM ? *a.heightM : source ? source->subject.heightM : 1.75;
    const std::string boardText = importedBoardText(streams, source ? &*source : nullptr, heightM);
    const board::LoadResult loaded = board::loadBoardText(boardText, "imported board");
    if (!loaded.ok()) {
        return fail(kExitRuntime, fmt::format("the board made for the take does not load: {}",
                                              loaded.errors.front().str()));
    }

    // The samples in time order, a gap in a stream's time column (more than 1.5 sample periods)
    // recorded as the sensor lost and back.
    SourceRecording rec;
    struct Pending {
        std::int64_t tNs;
        int sensor;
        int order;  // lost before the sample after the gap, online with it
        SourceRecording::Item item;
    };
    std::vector<Pending> items;
    const auto nsOf = [](double tS) { return 1'000'000'000 + std::llround(tS * 1e9); };
    for (std::size_t i = 0; i < streams.size(); ++i) {
        Stream& st = streams[i];
        const int sensor = static_cast<int>(i);
        const double period = 1.0 / st.trial.rateHz;
        Vec3d lastMag = Vec3d::Zero();
        for (std::size_t k = 0; k < st.trial.samples.size(); ++k) {
            const fusion::ImuSample& s = st.trial.samples[k];
            const std::int64_t tNs = nsOf(s.tS);
            if (k > 0 && s.tS - st.trial.samples[k - 1].tS > 1.5 * period) {
                const double dt = s.tS - st.trial.samples[k - 1].tS;
                const auto missing = std::llround(dt / period) - 1;
                st.lost += std::max<std::int64_t>(missing, 1);
                ++st.gaps;
                SourceRecording::Item lost;
                lost.type = cap::RecordType::Event;
                lost.t = timestampFromNs(nsOf(st.trial.samples[k - 1].tS));
                lost.sensor = sensor;
                lost.kind = cap::EventKind::SensorLost;
                lost.text = fmt::format("{:.3f} s without samples in {} before t = {:.6f}", dt,
                                        st.path.string(), s.tS);
                items.push_back({toNs(lost.t.time_since_epoch()), sensor, 1, lost});
                SourceRecording::Item back;
                back.type = cap::RecordType::Event;
                back.t = timestampFromNs(tNs);
                back.sensor = sensor;
                back.kind = cap::EventKind::SensorOnline;
                items.push_back({tNs, sensor, 0, back});
            }
            SourceRecording::Item it;
            it.type = cap::RecordType::RawSample;
            it.t = timestampFromNs(tNs);
            it.sensor = sensor;
            it.sample.t = it.t;
            it.sample.gyrRadps = s.gyrRadS.cast<float>();
            it.sample.accMps2 = s.accMps2.cast<float>();
            it.sample.magUt = s.magUt.cast<float>();
            // Rows repeat the last magnetometer reading between readings (zeros before the
            // first): a reading is fresh where it changes.
            if (!s.magUt.isZero() && (k == 0 || s.magUt != lastMag)) {
                it.sample.flags |= hal::ImuSample::kMagFresh;
            }
            lastMag = s.magUt;
            items.push_back({tNs, sensor, 1, it});
            ++rec.samples;
        }
    }
    std::stable_sort(items.begin(), items.end(), [](const Pending& x, const Pending& y) {
        if (x.tNs != y.tNs) {
            return x.tNs < y.tNs;
        }
        return x.order != y.order ? x.order < y.order : x.sensor < y.sensor;
    });
    rec.items.reserve(items.size());
    for (Pending& p : items) {
        rec.items.push_back(std::move(p.item));
    }

    std::string meta = "[recording]\n";
    meta += fmt::format("software = {}\n", tomlString(versionLine()));
    meta += "\n[import]\nformat = \"BROAD-layout streams (caphub sim --all)\"\nfiles = [";
    std::int64_t lost = 0;
    for (std::size_t i = 0; i < streams.size(); ++i) {
        meta += fmt::format("{}{}", i == 0 ? "" : ", ", tomlString(streams[i].path.string()));
        lost += streams[i].lost;
    }
    meta += "]\n";
    if (!a.mapPath.empty()) {
        meta += fmt::format("map = {}\n", tomlString(a.mapPath));
    }
    meta += fmt::format("source_board = {}\n", tomlString(boardName));
    meta += fmt::format("lost_samples = {}\n", lost);
    meta += "orientation = \"caphub's filter on the imported samples (as caphub reprocess)\"\n";
    std::vector<std::string> sensorNames;
    std::vector<board::Segment> sensorSegments;
    for (const auto& st : streams) {
        sensorNames.push_back(st.name);
        sensorSegments.push_back(st.segment);
    }
    meta += importedBoardMetadata("imported-broad", boardText, sensorNames, sensorSegments);
    rec.metadata = meta;

    // Orientations and poses: the stages of `caphub run` over the samples, as `caphub reprocess`
    // runs them, the body calibrated in the pose held at the start (or on the nominal mountings).
    ReprocessOptions ro;
    ro.poseRateHz = a.poseRateHz;
    ro.sensorCalibrations = FusionStage::Calibrations(loaded.board->sensors.size());
    if (a.calibrate == "none") {
        ro.calibration.kind = CalibrationChoice::Kind::None;
    } else {
        ro.calibration.kind = a.calibrate == "tpose" ? CalibrationChoice::Kind::TPose
                                                     : CalibrationChoice::Kind::NPose;
        ro.calibration.atS = {0.0};
    }

    // Written as OUT.part and renamed to OUT, never over anything, once complete.
    if (::access(a.output.c_str(), F_OK) == 0) {
        return fail(exitCodeForCreate(EEXIST),
                    fmt::format("cannot create recording '{}': {}", a.output, errnoText(EEXIST)));
    }
    PartialOutput part(a.output + ".part");
    auto writer = RecordingWriter::create(part.path(), meta);
    if (!writer) {
        return fail(exitCodeForCreate(writer.error().code), writer.error().message);
    }
    RecordingWriterSink sink(**writer);
    auto summary = reprocess(*loaded.board, rec, ro, sink);
    const int closed = (*writer)->close();
    if (!summary) {
        return fail(kExitUsage, summary.error().message);
    }
    const int err = sink.firstError != 0 ? sink.firstError : closed;
    if (err != 0) {
        return fail(kExitRuntime, fmt::format("writing '{}': {}", part.path(), errnoText(err)));
    }
    if (auto published = part.publishNew(a.output); !published) {
        return fail(exitCodeForCreate(published.error().code), published.error().message);
    }
    for (const Stream& st : streams) {
        fmt::print("{} ({}): {} samples at {:g} Hz on {}, {} lost in {} gap(s)\n", st.name,
                   st.path.string(), st.trial.samples.size(), st.trial.rateHz,
                   board::segmentName(st.segment), st.lost, st.gaps);
    }
    if (loaded.warnings.size() > 0) {
        fmt::print("note: {}\n", loaded.warnings.front().message);
    }
    fmt::print("{}: {} sensors, {:.3f} s; {}\n", a.output, streams.size(), summary->durationS,
               boardNote);
    fmt::print("{} orientations by caphub's filter, {} poses at {:g} Hz; body calibration: {}\n",
               summary->orientations, summary->poses, a.poseRateHz, summary->calibration);
    return kExitOk;
}

}  // namespace caphub::firmware
