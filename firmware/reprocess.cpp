#include "firmware/reprocess.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <map>
#include <unordered_map>

#include <fmt/format.h>
#include <toml++/toml.h>

#include "firmware/calibration_file.h"
#include "firmware/runtime/body_stage.h"
#include "fusion/smoother.h"
#include "hal/core/clock.h"

namespace caphub::firmware {

namespace {

// A recording `caphub import` made (its metadata has an [import] table).
bool importedRecording(const std::string& metadata) {
    try {
        return toml::parse(metadata).contains("import");
    } catch (const toml::parse_error&) {
        return false;
    }
}

std::string textOf(const RecordView& v) {
    return std::string(reinterpret_cast<const char*>(v.payload.data()), v.payload.size());
}

bool isBodyCalibrationMetadata(std::string_view toml) {
    return toml.find("[body_calibration]") != std::string_view::npos;
}

// The method of a [body_calibration] metadata text, if it is one that parses.
std::optional<body::CalibrationMethod> methodOf(const std::string& toml) {
    try {
        const toml::table meta = toml::parse(std::string_view(toml), std::string_view("metadata"));
        const auto text = meta["body_calibration"]["text"].value<std::string>();
        if (!text) {
            return std::nullopt;
        }
        auto cal = body::parseBodyCalibration(*text, "body calibration record");
        if (!cal) {
            return std::nullopt;
        }
        return cal->method;
    } catch (const toml::parse_error&) {
        return std::nullopt;
    }
}

std::optional<RuntimeEvent::Kind> runtimeKind(cap::EventKind k) {
    switch (k) {
        case cap::EventKind::SensorOnline:
            return RuntimeEvent::Kind::SensorOnline;
        case cap::EventKind::SensorLost:
            return RuntimeEvent::Kind::SensorLost;
        case cap::EventKind::SensorReset:
            return RuntimeEvent::Kind::SensorReset;
        case cap::EventKind::LineSilent:
            return RuntimeEvent::Kind::LineSilent;
        default:
            return std::nullopt;
    }
}

// A command the Hub recorded that changes the body: "calibrate tpose in 2.0 s", "calibrate npose
// in 0.0 s", "calibrate T+N: T-pose in 3.0 s, N-pose in 8.0 s", "heading reset".
struct BodyCommand {
    enum class Kind { None, TPose, NPose, TPlusN, HeadingReset };
    Kind kind = Kind::None;
    double aS = 0;
    double bS = 0;
};

BodyCommand parseCommand(const std::string& text) {
    BodyCommand c;
    char pose[16] = {};
    if (text == "heading reset") {
        c.kind = BodyCommand::Kind::HeadingReset;
    } else if (std::sscanf(text.c_str(), "calibrate T+N: T-pose in %lf s, N-pose in %lf s", &c.aS,
                           &c.bS) == 2) {
        c.kind = BodyCommand::Kind::TPlusN;
    } else if (std::sscanf(text.c_str(), "calibrate %15s in %lf s", pose, &c.aS) == 2) {
        const std::string p = pose;
        c.kind = p == "tpose"   ? BodyCommand::Kind::TPose
                 : p == "npose" ? BodyCommand::Kind::NPose
                                : BodyCommand::Kind::None;
    }
    return c;
}

// Passes the stages' records on, leaving nothing out.
class ForwardingSink final : public RecordSink {
public:
    explicit ForwardingSink(ReprocessSink& out) : out_(out) {}
    void orientation(int sensor, Timestamp t, const Eigen::Quaternionf& q) override {
        ++orientations;
        out_.orientation(sensor, t, q);
    }
    void pose(Timestamp t, const Eigen::Vector3f& rootM,
              std::span<const Eigen::Quaternionf> jointRotations,
              std::uint32_t notMeasured) override {
        out_.pose(t, rootM, jointRotations, notMeasured);
    }
    void event(Timestamp t, cap::EventKind kind, int sensor, int error,
               std::string_view text) override {
        out_.event(t, kind, sensor, error, text);
    }
    void metadata(Timestamp t, std::string_view toml) override { out_.metadata(t, toml); }
    void marker(Timestamp t, std::string_view label) override { out_.marker(t, label); }
    std::uint64_t orientations = 0;

private:
    ReprocessSink& out_;
};

// The smoothed orientations of every sensor, by sample time, for FusionStage's override.
class SmoothedOrientations {
public:
    struct Entry {
        std::int64_t tNs;
        Eigen::Quaternionf q;
    };
    std::vector<std::vector<Entry>> perSensor;
    std::vector<std::size_t> cursor;

    // From the start again, for another pass over the recording.
    void rewind() { std::fill(cursor.begin(), cursor.end(), 0); }

    Eigen::Quaternionf lookup(const SensorSample& s, const Eigen::Quaternionf& filtered) {
        if (s.sensor < 0 || static_cast<std::size_t>(s.sensor) >= perSensor.size()) {
            return filtered;
        }
        const auto u = static_cast<std::size_t>(s.sensor);
        const auto& list = perSensor[u];
        std::size_t& c = cursor[u];
        const std::int64_t t = toNs(s.sample.t);
        while (c < list.size() && list[c].tNs < t) {
            ++c;
        }
        if (c < list.size() && list[c].tNs == t) {
            return list[c].q;
        }
        return filtered;
    }
};

fusion::FilterParams paramsOf(const board::SensorConfig& s) {
    fusion::FilterParams p;
    p.gyrRateHz = s.achievedOdrHz;
    p.accRateHz = s.achievedOdrHz;
    p.magRateHz = s.magOdrHz > 0 ? s.magOdrHz : s.achievedOdrHz;
    return p;
}

// Per sensor, its samples split where it went out (lost, silent, reset: its filter starts
// again there, as in the capture), each run smoothed over its whole length.
SmoothedOrientations smoothAll(const board::Board& board, const SourceRecording& source,
                               const FusionStage::Calibrations& calibrations,
                               const std::vector<Eigen::Vector3f>& aid, const ReprocessOptions& o) {
    std::size_t sampleIndex = 0;
    const std::size_t n = board.sensors.size();
    struct Run {
        std::vector<fusion::SmootherSample> samples;
        std::vector<std::int64_t> tNs;
    };
    std::vector<std::vector<Run>> runs(n, std::vector<Run>(1));
    for (const auto& it : source.items) {
        if (it.sensor < 0 || static_cast<std::size_t>(it.sensor) >= n) {
            continue;
        }
        const auto u = static_cast<std::size_t>(it.sensor);
        if (it.type == cap::RecordType::Event) {
            if (it.kind == cap::EventKind::SensorLost || it.kind == cap::EventKind::LineSilent ||
                it.kind == cap::EventKind::SensorReset) {
                if (!runs[u].back().samples.empty()) {
                    runs[u].emplace_back();
                }
            }
            continue;
        }
        if (it.type != cap::RecordType::RawSample) {
            continue;
        }
        const std::size_t k = sampleIndex++;
        const hal::ImuSample& in = it.sample;
        fusion::ImuSample raw;
        raw.gyrRadS = in.gyrRadps.cast<double>();
        raw.accMps2 = in.accMps2.cast<double>();
        raw.magUt = in.magUt.cast<double>();
        const auto& cal = u < calibrations.size() ? calibrations[u] : std::nullopt;
        const fusion::ImuSample c = cal ? cal->apply(raw) : raw;
        fusion::SmootherSample s;
        // The causal filter takes samples in float: the same rounding here.
        s.gyrRadS = c.gyrRadS.cast<float>().cast<double>();
        s.accMps2 = c.accMps2.cast<float>().cast<double>();
        s.magUt = c.magUt.cast<float>().cast<double>();
        s.magFresh = (in.flags & hal::ImuSample::kMagFresh) != 0 &&
                     (in.flags & hal::ImuSample::kMagOverflow) == 0;
        s.gyrClipped = (in.flags & hal::ImuSample::kGyrSaturated) != 0;
        if (k < aid.size()) {
            s.linAccEnu = aid[k].cast<double>();
        }
        runs[u].back().samples.push_back(s);
        runs[u].back().tNs.push_back(toNs(in.t));
    }
    SmoothedOrientations out;
    out.perSensor.resize(n);
    out.cursor.assign(n, 0);
    std::size_t done = 0;
    for (std::size_t u = 0; u < n; ++u) {
        const fusion::FilterParams params = paramsOf(board.sensors[u]);
        for (const Run& r : runs[u]) {
            const auto q = fusion::smoothOrientations(r.samples, params, o.smoothing);
            for (std::size_t k = 0; k < q.size(); ++k) {
                out.perSensor[u].push_back({r.tNs[k], q[k].cast<float>()});
            }
        }
        ++done;
        if (o.progress) {
            o.progress("smoothing", static_cast<double>(done) / static_cast<double>(n));
        }
    }
    return out;
}

}  // namespace

Result<SourceRecording> readSourceRecording(RecordingReader& reader) {
    SourceRecording out;
    out.metadata = reader.metadata();
    std::unordered_map<int, Timestamp> latest;  // each sensor's latest raw sample
    RecordView v;
    for (;;) {
        const int r = reader.next(v);
        if (r < 0) {
            return Error{-r, fmt::format("reading the recording: {}", std::strerror(-r))};
        }
        if (r == 0) {
            break;
        }
        SourceRecording::Item it;
        it.type = v.type;
        it.t = v.t;
        switch (v.type) {
            case cap::RecordType::RawSample:
                if (!decodeRawSample(v, it.sensor, it.sample)) {
                    ++out.malformed;
                    continue;
                }
                it.t = it.sample.t;
                if (auto [at, fresh] = latest.try_emplace(it.sensor, it.t); !fresh) {
                    if (it.t <= at->second) {
                        ++out.outOfOrder;
                        continue;
                    }
                    at->second = it.t;
                }
                ++out.samples;
                break;
            case cap::RecordType::Event: {
                if (!decodeEvent(v, it.kind, it.sensor, it.error, it.text)) {
                    ++out.malformed;
                    continue;
                }
                break;
            }
            case cap::RecordType::Metadata:
            case cap::RecordType::Marker:
                it.text = textOf(v);
                break;
            case cap::RecordType::Orientation:
            case cap::RecordType::Pose:
                continue;  // computed anew
        }
        out.items.push_back(std::move(it));
    }
    for (const auto& d : reader.damage()) {
        out.damagedBytes += d.bytes;
    }
    return out;
}

Result<ReprocessSummary> reprocess(const board::Board& board, const SourceRecording& source,
                                   const ReprocessOptions& o, ReprocessSink& out) {
    const auto firstSample =
        std::find_if(source.items.begin(), source.items.end(),
                     [](const auto& it) { return it.type == cap::RecordType::RawSample; });
    if (firstSample == source.items.end()) {
        return Error{EINVAL, "the recording has no raw samples: nothing to reprocess"};
    }
    const Timestamp t0 = firstSample->t;
    Timestamp tLast = t0;
    for (const auto& it : source.items) {
        if (it.type == cap::RecordType::RawSample) {
            tLast = std::max(tLast, it.t);
        }
        if (it.type == cap::RecordType::RawSample &&
            (it.sensor < 0 || static_cast<std::size_t>(it.sensor) >= board.sensors.size())) {
            return Error{EINVAL, fmt::format("a raw sample of sensor {}, but the recording's board "
                                             "has {} sensors",
                                             it.sensor, board.sensors.size())};
        }
    }
    const double durationS = toSeconds(tLast - t0);

    // The sensor calibration: the one given, or the recording's own.
    FusionStage::Calibrations calibrations;
    if (o.sensorCalibrations) {
        calibrations = *o.sensorCalibrations;
    } else {
        try {
            const toml::table meta = toml::parse(std::string_view(source.metadata),
                                                 std::string_view("recording metadata"));
            if (const auto text = meta["calibration"]["text"].value<std::string>()) {
                auto set = parseCalibration(*text, "the recording's calibration");
                if (!set) {
                    return Error{EINVAL, set.error().message};
                }
                calibrations = calibrationsFor(board, *set, nullptr);
            }
        } catch (const toml::parse_error& e) {
            return Error{EINVAL,
                         fmt::format("the recording's metadata is not TOML ({})", e.description())};
        }
    }

    // The body calibration: chosen now, or what the capture did.
    BodyStage::Options bodyOptions;
    bodyOptions.rateHz = o.poseRateHz;
    bodyOptions.dimensions = o.dimensions;
    std::optional<std::pair<double, double>> twoPose;
    const double windowS = toSeconds(bodyOptions.average);
    const auto checkAt = [&](double at) -> Result<void> {
        if (!(at >= 0) || at + windowS > durationS) {
            return Error{EINVAL, fmt::format("--at {:g}: the pose must be held from there for {:g} "
                                             "s within the recording's {:.3f} s",
                                             at, windowS, durationS)};
        }
        return {};
    };
    bool replayCommands = false;
    std::string planned;
    switch (o.calibration.kind) {
        case CalibrationChoice::Kind::None:
            planned = "none: the board's nominal mountings";
            break;
        case CalibrationChoice::Kind::TPose:
        case CalibrationChoice::Kind::NPose: {
            if (o.calibration.atS.size() != 1) {
                return Error{EINVAL, "--calibrate tpose|npose takes one --at"};
            }
            if (auto ok = checkAt(o.calibration.atS[0]); !ok) {
                return ok.error();
            }
            const bool t = o.calibration.kind == CalibrationChoice::Kind::TPose;
            bodyOptions.calibrate = t ? body::ReferencePoseKind::T : body::ReferencePoseKind::N;
            bodyOptions.settle = durationFromSeconds(o.calibration.atS[0]);
            planned =
                fmt::format("{} held from {:.3f} s", t ? "T-pose" : "N-pose", o.calibration.atS[0]);
            break;
        }
        case CalibrationChoice::Kind::TPlusN: {
            if (o.calibration.atS.size() != 2) {
                return Error{EINVAL,
                             "--calibrate tn takes two --at: the T-pose's, then the N-pose's"};
            }
            for (const double at : o.calibration.atS) {
                if (auto ok = checkAt(at); !ok) {
                    return ok.error();
                }
            }
            bodyOptions.calibrate = body::ReferencePoseKind::T;
            bodyOptions.settle = durationFromSeconds(o.calibration.atS[0]);
            twoPose = std::make_pair(o.calibration.atS[0], o.calibration.atS[1]);
            planned = fmt::format("T+N: T-pose held from {:.3f} s, N-pose from {:.3f} s",
                                  o.calibration.atS[0], o.calibration.atS[1]);
            break;
        }
        case CalibrationChoice::Kind::FromRecording: {
            replayCommands = true;
            // `caphub run --calibrate`: a calibration with no command before it, from the start.
            bool command = false;
            bool calibratedEvent = false;
            for (auto it = source.items.begin(); it != source.items.end(); ++it) {
                if (it->type == cap::RecordType::Event && it->kind == cap::EventKind::Command &&
                    parseCommand(it->text).kind != BodyCommand::Kind::None &&
                    parseCommand(it->text).kind != BodyCommand::Kind::HeadingReset) {
                    command = true;
                }
                if (it->type == cap::RecordType::Event && it->kind == cap::EventKind::Calibrated) {
                    calibratedEvent = true;
                    if (command) {
                        break;
                    }
                    std::optional<body::CalibrationMethod> m;
                    for (auto next = it; next != source.items.end(); ++next) {
                        if (next->type == cap::RecordType::Metadata &&
                            isBodyCalibrationMetadata(next->text)) {
                            m = methodOf(next->text);
                            break;
                        }
                    }
                    if (m == body::CalibrationMethod::TPose ||
                        m == body::CalibrationMethod::NPose) {
                        bodyOptions.calibrate = *m == body::CalibrationMethod::TPose
                                                    ? body::ReferencePoseKind::T
                                                    : body::ReferencePoseKind::N;
                        // `caphub import` calibrated in the pose held from the first sample
                        // (docs/import.md), not after the capture's settling time.
                        if (importedRecording(source.metadata)) {
                            bodyOptions.settle = Duration::zero();
                        }
                        planned =
                            fmt::format("the recording's: {} held from {:.3f} s",
                                        *m == body::CalibrationMethod::TPose ? "T-pose" : "N-pose",
                                        toSeconds(bodyOptions.settle));
                    } else {
                        return Error{EINVAL,
                                     "the recording's body calibration cannot be redone from the "
                                     "file (no command says when the poses were held): choose "
                                     "one with --calibrate tpose|npose|tn --at T"};
                    }
                    break;
                }
            }
            if (!calibratedEvent && isBodyCalibrationMetadata(source.metadata)) {
                return Error{EINVAL,
                             "the recording's body calibration was taken before it began (a take "
                             "started after calibrating): choose one with --calibrate "
                             "tpose|npose|tn --at T"};
            }
            if (planned.empty()) {
                planned = command ? "the recording's calibrate commands"
                                  : "none in the recording: the board's nominal mountings";
            }
            break;
        }
    }

    // One pass of the recording through fusion and body: what `caphub run` did, with the
    // choices above. `sink` null: nothing recorded (the smoother's first pass); `beforeSample`:
    // called before each raw sample goes in.
    struct Pass {
        Pass(const board::Board& b, RecordSink* sink, const FusionStage::Calibrations& cals,
             Timestamp start, const BodyStage::Options& bo)
            : fusion(b, sink, cals), clock(start), body(b, fusion, sink, clock, bo) {
            pipeline.add(fusion);
            pipeline.add(body);
        }
        FusionStage fusion;
        SimulatedClock clock;
        BodyStage body;
        Pipeline pipeline;
    };
    const auto run = [&](Pass& pass, ReprocessSink* sinkOut, const char* stage,
                         const std::function<void(std::size_t)>& beforeSample) {
        bool first = true;
        std::size_t index = 0;
        std::size_t sampleIndex = 0;
        const std::size_t total = source.items.size();
        for (const auto& it : source.items) {
            ++index;
            if (o.progress && (index & 0xFFF) == 0) {
                o.progress(stage, static_cast<double>(index) / static_cast<double>(total));
            }
            pass.clock.advanceTo(it.t);
            switch (it.type) {
                case cap::RecordType::RawSample: {
                    if (sinkOut != nullptr) {
                        sinkOut->rawSample(it.sensor, it.sample);
                    }
                    if (beforeSample) {
                        beforeSample(sampleIndex);
                    }
                    ++sampleIndex;
                    pass.pipeline.sample({it.sensor, it.sample});
                    if (first) {
                        first = false;
                        if (twoPose) {
                            pass.body.tracker().startTwoPoseCalibration(
                                t0 + durationFromSeconds(twoPose->first),
                                t0 + durationFromSeconds(twoPose->second));
                        }
                    }
                    break;
                }
                case cap::RecordType::Event: {
                    if (it.kind == cap::EventKind::Calibrated ||
                        it.kind == cap::EventKind::HeadingReset) {
                        break;  // the body stage records its own
                    }
                    if (sinkOut != nullptr) {
                        sinkOut->event(it.t, it.kind, it.sensor, it.error, it.text);
                    }
                    const auto k = runtimeKind(it.kind);
                    if (k && it.sensor >= 0 &&
                        static_cast<std::size_t>(it.sensor) < board.sensors.size()) {
                        pass.pipeline.event({*k, it.sensor, it.t, it.error});
                    }
                    if (it.kind == cap::EventKind::Command) {
                        const BodyCommand c = parseCommand(it.text);
                        body::BodyTracker& tracker = pass.body.tracker();
                        if (c.kind == BodyCommand::Kind::HeadingReset) {
                            tracker.headingResetAt(it.t);
                        } else if (replayCommands && c.kind == BodyCommand::Kind::TPlusN) {
                            tracker.startTwoPoseCalibration(it.t + durationFromSeconds(c.aS),
                                                            it.t + durationFromSeconds(c.bS));
                        } else if (replayCommands && c.kind != BodyCommand::Kind::None) {
                            tracker.startCalibration(c.kind == BodyCommand::Kind::TPose
                                                         ? body::ReferencePoseKind::T
                                                         : body::ReferencePoseKind::N,
                                                     it.t + durationFromSeconds(c.aS));
                        }
                    }
                    break;
                }
                case cap::RecordType::Metadata:
                    if (sinkOut != nullptr && !isBodyCalibrationMetadata(it.text)) {
                        sinkOut->metadata(it.t, it.text);
                    }
                    break;
                case cap::RecordType::Marker:
                    if (sinkOut != nullptr) {
                        sinkOut->marker(it.t, it.text);
                    }
                    break;
                case cap::RecordType::Orientation:
                case cap::RecordType::Pose:
                    break;
            }
        }
        pass.pipeline.finish(pass.clock.now());
    };

    SmoothedOrientations smoothed;
    // A pass that takes the smoothed orientations in place of its filters', from the start of
    // the recording (the lookup walks each sensor's list forward).
    const auto useSmoothed = [&smoothed](Pass& p) {
        smoothed.rewind();
        p.fusion.overrideOrientations(
            [&smoothed](const SensorSample& s, const Eigen::Quaternionf& q) {
                return smoothed.lookup(s, q);
            });
    };
    if (o.smooth) {
        // The causal pass first, for what the body told the filters (the body's acceleration at
        // each sample): the smoother's runs are told the same.
        std::vector<Eigen::Vector3f> aid(source.samples, Eigen::Vector3f::Zero());
        {
            Pass causal(board, nullptr, calibrations, t0, bodyOptions);
            run(causal, nullptr, "causal", [&](std::size_t k) {
                if (k < aid.size()) {
                    aid[k] = causal.fusion.bodyAcceleration().cast<float>();
                }
            });
            // The capture heading from the knees over the whole take (docs/body-calibration.md,
            // "The capture heading from the knees"), for the one calibration the take has.
            const body::BodyTracker& t = causal.body.tracker();
            if (o.kneeHeading && t.calibrations() == 1) {
                bodyOptions.knownHeadingErrorRad = t.kneeHeadingError();
            }
        }
        smoothed = smoothAll(board, source, calibrations, aid, o);
        // The feet's dead reckoning between their still instants, with the smoothed
        // orientations: what each stretch ended with, taken off along it in the output pass
        // (docs/reprocess.md, "The feet between their still instants").
        auto logs = std::make_shared<body::FootStretchLogs>();
        BodyStage::Options feetOptions = bodyOptions;
        feetOptions.footStretches = logs;
        Pass feet(board, nullptr, calibrations, t0, feetOptions);
        useSmoothed(feet);
        run(feet, nullptr, "feet", {});
        logs->use = body::FootStretchUse::Correct;
        bodyOptions.footStretches = logs;
    }
    ForwardingSink sink(out);
    Pass pass(board, &sink, calibrations, t0, bodyOptions);
    if (o.feed != nullptr) {
        pass.body.publishTo(*o.feed);
    }
    for (auto* st : o.stages) {
        pass.pipeline.add(*st);
    }
    if (o.smooth) {
        useSmoothed(pass);
    }
    ReprocessSummary summary;
    summary.durationS = durationS;
    if (bodyOptions.knownHeadingErrorRad) {
        summary.kneeHeadingDeg = *bodyOptions.knownHeadingErrorRad * 180 / std::numbers::pi;
    }
    run(pass, &out, "fusion", {});
    if (o.progress) {
        o.progress("fusion", 1.0);
    }
    const BodyStage& body = pass.body;
    summary.samples = source.samples;
    summary.poses = body.poses();
    summary.orientations = sink.orientations;
    summary.calibrationError = body.calibrationError();
    if (!summary.calibrationError.empty()) {
        summary.calibration = fmt::format("{}: failed ({})", planned, summary.calibrationError);
    } else if (bodyOptions.calibrate && !body.calibrated()) {
        summary.calibration = fmt::format("{}: not done (the recording ended first)", planned);
    } else {
        summary.calibration = planned;
    }
    return summary;
}

}  // namespace caphub::firmware
