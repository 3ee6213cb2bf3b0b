#include "firmware/evaluation.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <map>
#include <vector>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include "board/sim/virtual_suit.h"
#include "firmware/reprocess.h"
#include "firmware/runtime/body_stage.h"
#include "firmware/runtime/hub.h"
#include "firmware/runtime/mag_state.h"
#include "fusion/body/kinematics.h"
#include "fusion/body/pose_solver.h"
#include "fusion/body/skeleton.h"

namespace caphub::firmware {

namespace {

namespace bs = board::sim;

// The clip's key frames as true body states, for measuring the subject's skeleton.
std::vector<body::BodyTruth> keyFrames(const bs::Motion& motion) {
    std::vector<body::BodyTruth> keys(static_cast<std::size_t>(motion.frameCount()));
    for (std::size_t f = 0; f < keys.size(); ++f) {
        for (int i = 0; i < body::kSegmentCount; ++i) {
            const auto s = static_cast<board::Segment>(i);
            const auto u = static_cast<std::size_t>(i);
            keys[f].qWorldSegment[u] = motion.keyOrientation(s, static_cast<int>(f));
            keys[f].positionM[u] = motion.keyPositionM(s, static_cast<int>(f));
        }
    }
    return keys;
}

std::string calibrationName(const BodyStage& stage) {
    if (stage.calibration().method == body::CalibrationMethod::None) {
        return "nominal mountings (none)";
    }
    return std::string(body::toString(stage.calibration().method));
}

// The segments the board's sensors measure (docs/sparse.md): the scores are over these.
std::uint32_t measuredSegments(const board::Board& b) {
    body::SegmentMask sensors = 0;
    for (const auto& sc : b.sensors) {
        sensors |= body::bit(sc.segment);
    }
    return body::PoseSolver(sensors).coveredSegments();
}

// Scores each pose the body publishes against the simulation's truth at its time, after the
// lead-in: a stage after the body, emptying its queue of the pose feed on every sample.
class PoseScoringStage final : public PipelineStage {
public:
    PoseScoringStage(const bs::SegmentTrajectory& trajectory, Timestamp start,
                     std::int64_t leadInNs)
        : trajectory_(trajectory), start_(start), leadInNs_(leadInNs) {}
    // The feed keeps its queue as long as it lives (the Hub's, which goes first).
    void follow(PoseFeed& feed) { queue_ = feed.subscribe(); }
    void onSample(const SensorSample&) override { score(); }
    void onEvent(const RuntimeEvent&) override {}
    void finish(Timestamp) override { score(); }
    body::PoseScorer& scorer() { return scorer_; }

private:
    void score() {
        if (!queue_) {
            return;
        }
        while (queue_->pop(frame_)) {
            const std::int64_t tNs = toNs(frame_.t - start_);
            if (tNs < leadInNs_) {
                continue;  // the T-pose hold and the blend: not part of the clip
            }
            for (int i = 0; i < body::kSegmentCount; ++i) {
                const auto u = static_cast<std::size_t>(i);
                trajectory_.evaluate(static_cast<board::Segment>(i), tNs, segment_);
                truth_.qWorldSegment[u] = segment_.qWorldSegment;
                truth_.positionM[u] = segment_.positionM;
                pose_.qLocal[u] = frame_.local[u].cast<double>();
                pose_.qWorld[u] = frame_.world[u].cast<double>();
                pose_.positionM[u] = frame_.positionM[u].cast<double>();
            }
            scorer_.add(pose_, truth_);
        }
    }

    const bs::SegmentTrajectory& trajectory_;
    Timestamp start_;
    std::int64_t leadInNs_;
    std::shared_ptr<PoseQueue> queue_;
    body::PoseScorer scorer_{body::PoseScorer::RootOrigin::AtFirstFrame};
    PoseFrame frame_;
    body::Pose pose_;
    body::BodyTruth truth_;
    bs::SegmentState segment_;
};

// Keeps the capture's raw samples and lifecycle events as a recording in memory (a stage after
// the body: what `caphub run --record` would have written of them, in the same order).
class SampleKeepingStage final : public PipelineStage {
public:
    void onSample(const SensorSample& s) override {
        SourceRecording::Item it;
        it.type = cap::RecordType::RawSample;
        it.t = s.sample.t;
        it.sensor = s.sensor;
        it.sample = s.sample;
        recording.items.push_back(it);
        ++recording.samples;
    }
    void onEvent(const RuntimeEvent& e) override {
        SourceRecording::Item it;
        it.type = cap::RecordType::Event;
        it.t = e.t;
        it.sensor = e.sensor;
        it.error = e.error;
        switch (e.kind) {
            case RuntimeEvent::Kind::SensorOnline:
                it.kind = cap::EventKind::SensorOnline;
                break;
            case RuntimeEvent::Kind::SensorLost:
                it.kind = cap::EventKind::SensorLost;
                break;
            case RuntimeEvent::Kind::SensorReset:
                it.kind = cap::EventKind::SensorReset;
                break;
            case RuntimeEvent::Kind::LineSilent:
                it.kind = cap::EventKind::LineSilent;
                break;
        }
        recording.items.push_back(it);
    }
    SourceRecording recording;
};

// Scores the pose records a reprocess writes, as the recording holds them (joint rotations and
// the root), against the truth at their time.
class ScoringSink final : public ReprocessSink {
public:
    ScoringSink(const bs::SegmentTrajectory& trajectory, Timestamp start, std::int64_t leadInNs,
                body::Dimensions dims)
        : trajectory_(trajectory), start_(start), leadInNs_(leadInNs), dims_(dims) {}
    void rawSample(int, const hal::ImuSample&) override {}
    void orientation(int, Timestamp, const Eigen::Quaternionf&) override {}
    void event(Timestamp, cap::EventKind, int, int, std::string_view) override {}
    void metadata(Timestamp, std::string_view) override {}
    void marker(Timestamp, std::string_view) override {}
    void pose(Timestamp t, const Eigen::Vector3f& rootM, std::span<const Eigen::Quaternionf> joints,
              std::uint32_t) override {
        const std::int64_t tNs = toNs(t - start_);
        if (tNs < leadInNs_) {
            return;
        }
        for (int i = 0; i < body::kSegmentCount; ++i) {
            const auto u = static_cast<std::size_t>(i);
            trajectory_.evaluate(static_cast<board::Segment>(i), tNs, segment_);
            truth_.qWorldSegment[u] = segment_.qWorldSegment;
            truth_.positionM[u] = segment_.positionM;
            pose_.qLocal[u] = joints[u].cast<double>();
        }
        body::worldFromLocal(pose_);
        body::forwardKinematics(dims_, rootM.cast<double>(), pose_);
        scorer.add(pose_, truth_);
    }
    body::PoseScorer scorer{body::PoseScorer::RootOrigin::AtFirstFrame};

private:
    const bs::SegmentTrajectory& trajectory_;
    Timestamp start_;
    std::int64_t leadInNs_;
    body::Dimensions dims_;
    body::Pose pose_;
    body::BodyTruth truth_;
    bs::SegmentState segment_;
};

// A sensor whose free heading its joints turned (EvaluateResult::jointHeadingTurnDeg).
bool fromJoints(const EvaluateResult& r, std::size_t sensor) {
    return sensor < r.jointHeadingTurnDeg.size() && r.jointHeadingTurnDeg[sensor] != 0;
}

}  // namespace

MountingErrors mountingErrors(
    const body::BodyCalibration& calibration, const board::Board& b,
    const std::function<board::sim::SensorPlacement(const board::SensorConfig&, int)>&
        placementOf) {
    MountingErrors m;
    if (b.sensors.empty()) {
        return m;
    }
    for (std::size_t i = 0; i < b.sensors.size(); ++i) {
        const auto& sc = b.sensors[i];
        const Quatd truth = placementOf(sc, static_cast<int>(i)).mounting;
        const double e =
            calibration.mounting[static_cast<std::size_t>(sc.segment)].angularDistance(truth) *
            180.0 / hal::kPi;
        m.meanDeg += e;
        m.maxDeg = std::max(m.maxDeg, e);
        m.perSensorDeg.push_back(e);
        m.nominalMeanDeg += sc.mounting.angularDistance(truth) * 180.0 / hal::kPi;
    }
    const double n = static_cast<double>(b.sensors.size());
    m.meanDeg /= n;
    m.nominalMeanDeg /= n;
    return m;
}

Result<EvaluateResult> evaluateClip(const board::Board& b, const EvaluateOptions& o) {
    if (!board::allBusesSimulated(b)) {
        return Error{EINVAL, fmt::format("board '{}' has real buses; the evaluation needs a "
                                         "virtual suit (every bus 'sim', e.g. sim-suit)",
                                         b.name)};
    }
    BodyStage::Options bodyOptions;
    bodyOptions.rateHz = o.poseRateHz;
    bodyOptions.calibrate = o.calibrate;
    bodyOptions.aidFilters = o.aidFilters;
    bodyOptions.footInertial = o.footInertial;
    bodyOptions.kneeHeading = o.kneeHeading;
    bodyOptions.jointHeading = o.jointHeading;

    // The subject holds the calibration pose (the T-pose without one) from the start as long as
    // `caphub run` asks for it (the averaging window and a margin), then blends into the clip. The
    // lead-in is played whatever the calibration, so that every calibration is scored on the same
    // poses.
    SimulatedClock clock(Timestamp{std::chrono::seconds(1)});
    const Timestamp start = clock.now();
    bs::ClipOptions clipOptions;
    clipOptions.bvh = o.bvh;
    clipOptions.map = o.map;
    clipOptions.profile = o.profile;
    clipOptions.seed = o.seed;
    clipOptions.strapErrorDeg = o.strapDeg;
    clipOptions.chipDelayS = o.chipDelayS;
    clipOptions.tposeHoldS = toSeconds(bodyOptions.settle + bodyOptions.average) + 0.5;
    if (o.calibrate) {
        clipOptions.leadInPose = body::referencePose(*o.calibrate);  // the N-pose for npose
    }
    auto clip = bs::clipSources(clipOptions, start);
    if (!clip) {
        return Error{EINVAL, clip.error().message};
    }
    if (o.measuredSkeleton) {
        bodyOptions.dimensions = body::measuredDimensions(keyFrames(*clip->motion));
    }
    auto suit = bs::buildVirtualSuit(b, clock, clip->sources);
    if (!suit) {
        return Error{EINVAL, suit.error().message};
    }

    // The Hub of `caphub run` in stepped mode: the same stages on one thread, deterministic;
    // the scorer is a stage after the body that takes every pose from the feed.
    HubOptions hubOptions;
    hubOptions.mode = Capture::Mode::Stepped;
    hubOptions.calibrations = o.sensorCalibrations;
    hubOptions.body = bodyOptions;
    EvaluateResult r;
    r.clip = o.bvh.filename().string();
    r.truthTurns = clip->truthTurns;
    r.leadInS = static_cast<double>(clip->leadInNs) * 1e-9;
    r.clipS = static_cast<double>(clip->motion->durationNs()) * 1e-9;
    PoseScoringStage scoring(*clip->trajectory, start, clip->leadInNs);
    scoring.scorer().setMeasured(measuredSegments(b));
    hubOptions.stages.push_back(&scoring);
    SampleKeepingStage keeping;
    if (o.reprocessSmooth) {
        hubOptions.stages.push_back(&keeping);
    }
    Hub hub(b, clock, *suit, std::move(hubOptions));
    scoring.follow(hub.poses());
    if (!o.magState.empty()) {
        if (auto loaded = loadMagState(o.magState, b, hub.fusion()); !loaded) {
            return Error{loaded.error().code, "--mag-state: " + loaded.error().message};
        }
    }
    const auto wallStart = std::chrono::steady_clock::now();
    const CaptureStats stats =
        hub.runStepped(Duration{clip->leadInNs + clip->motion->durationNs()});
    r.wallS = std::chrono::duration<double>(std::chrono::steady_clock::now() - wallStart).count();
    r.samples = stats.samples;
    const BodyStage& bodyStage = hub.body();
    const FusionStage& fusion = hub.fusion();
    if (!o.magState.empty()) {
        if (auto saved = writeMagStateFile(o.magState, magStateText(b, magStates(b, fusion)));
            !saved) {
            return Error{saved.error().code, "--mag-state: " + saved.error().message};
        }
    }
    body::PoseScorer& scorer = scoring.scorer();

    if (!bodyStage.calibrationError().empty()) {
        return Error{EIO, "body calibration failed: " + bodyStage.calibrationError()};
    }
    if (!bodyStage.calibrated()) {
        return Error{EIO, "body calibration: the capture ended before the T-pose was averaged"};
    }
    r.poses = bodyStage.poses();
    const auto score = scorer.score();
    if (!score) {
        // Nothing to average: a table of zeros would read as a perfect score.
        return Error{EINVAL,
                     fmt::format("clip '{}' is too short to score: {:.3f} s after the {:.2f} s "
                                 "lead-in gave no pose at {:g} Hz to compare with the truth",
                                 r.clip, r.clipS, r.leadInS, o.poseRateHz)};
    }
    r.score = *score;
    r.score.stanceChanges = bodyStage.solver().rootTracker().stanceChanges();
    r.calibration = calibrationName(bodyStage);
    for (std::size_t i = 0; i < b.sensors.size(); ++i) {
        r.gyroClipEvents.push_back(fusion.clipEvents(static_cast<int>(i)));
        r.magModes.push_back(fusion.magMode(static_cast<int>(i)));
        r.magEstimates.push_back(fusion.magEstimate(static_cast<int>(i)));
        const FusionStage::HeadingStep& step = fusion.headingStep(static_cast<int>(i));
        r.headingSteps.push_back(
            {step.count, toSeconds(step.t - start), step.angleRad * 180.0 / hal::kPi});
    }
    for (const double turn : bodyStage.tracker().jointHeadingTurns()) {
        r.jointHeadingTurnDeg.push_back(turn * 180.0 / hal::kPi);
    }
    const MountingErrors m = mountingErrors(bodyStage.calibration(), b, clip->placement);
    r.mountingErrorMeanDeg = m.meanDeg;
    r.mountingErrorMaxDeg = m.maxDeg;
    r.mountingErrorDeg = m.perSensorDeg;
    r.nominalMountingErrorMeanDeg = m.nominalMeanDeg;
    if (const std::optional<double> knee = bodyStage.tracker().kneeHeadingError()) {
        r.kneeHeadingErrorDeg = *knee * 180.0 / hal::kPi;
    }
    r.kneeHeadingApplied = o.kneeHeading == body::KneeHeadingMode::Live && r.kneeHeadingErrorDeg;
    for (const auto& sc : b.sensors) {
        const body::BodyCalibration& cal = bodyStage.calibration();
        r.nominalHeading.push_back(
            body::has(cal.nominalHeading & cal.freeHeading & cal.mask, body::idx(sc.segment)));
    }

    if (o.reprocessSmooth) {
        // The capture's samples again, as `caphub reprocess --smooth` would take them from its
        // recording: the same calibration (the lead-in's pose, from the same time), pose rate and
        // skeleton.
        ReprocessOptions ro;
        ro.smooth = true;
        ro.smoothing = o.smoothing;
        ro.kneeHeading = o.kneeHeading != body::KneeHeadingMode::Off;
        ro.poseRateHz = o.poseRateHz;
        ro.sensorCalibrations = o.sensorCalibrations;
        ro.dimensions = bodyOptions.dimensions;
        if (o.calibrate) {
            ro.calibration.kind = *o.calibrate == body::ReferencePoseKind::T
                                      ? CalibrationChoice::Kind::TPose
                                      : CalibrationChoice::Kind::NPose;
            ro.calibration.atS = {toSeconds(bodyOptions.settle)};
        } else {
            ro.calibration.kind = CalibrationChoice::Kind::None;
        }
        const body::Dimensions dims = bodyOptions.dimensions
                                          ? *bodyOptions.dimensions
                                          : *body::dimensionsFromSubject(b.subject);
        ScoringSink sink(*clip->trajectory, start, clip->leadInNs, dims);
        sink.scorer.setMeasured(measuredSegments(b));
        const auto smoothStart = std::chrono::steady_clock::now();
        auto done = reprocess(b, keeping.recording, ro, sink);
        r.smoothWallS =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - smoothStart).count();
        if (!done) {
            return Error{EIO, "reprocess --smooth: " + done.error().message};
        }
        if (auto s = sink.scorer.score()) {
            r.smoothed = *s;
        }
    }
    return r;
}

std::string formatEvaluation(const EvaluateResult& r, const board::Board& b,
                             const EvaluateOptions& o) {
    std::string out = fmt::format(
        "clip {}: {:.2f} s scored after a {:.2f} s T-pose lead-in; board '{}' ({} sensors), "
        "profile {}, seed {}, straps {:g} deg, skeleton {}\n",
        r.clip, r.clipS, r.leadInS, b.name, b.sensors.size(), bs::toString(o.profile), o.seed,
        o.strapDeg, o.measuredSkeleton ? "measured from the clip" : "from the board's subject");
    out += fmt::format(
        "pipeline: {} samples through fusion and body ({:.1f} s of computing); {} poses at {:g} "
        "Hz, {} scored\n",
        r.samples, r.wallS, r.poses, o.poseRateHz, r.score.frames);
    out += fmt::format(
        "body calibration: {}; mountings off the true (strapped) ones by {:.2f} deg mean, {:.2f} "
        "deg max (the board's nominal ones: {:.2f} deg mean)\n\n",
        r.calibration, r.mountingErrorMeanDeg, r.mountingErrorMaxDeg,
        r.nominalMountingErrorMeanDeg);
    if (r.kneeHeadingErrorDeg) {
        out.insert(out.size() - 1,
                   fmt::format("capture heading from the knees' axes: off by {:+.2f} deg ({})\n",
                               *r.kneeHeadingErrorDeg,
                               r.kneeHeadingApplied ? "corrected when known"
                                                    : "not applied: --knee-heading live does"));
    }
    {
        // The mountings far off (a heading that was free or unchecked at the calibration).
        std::string far;
        for (std::size_t i = 0; i < r.mountingErrorDeg.size() && i < b.sensors.size(); ++i) {
            if (r.mountingErrorDeg[i] > 10.0) {
                far += fmt::format("{}{} {:.1f}", far.empty() ? "" : ", ", b.sensors[i].name,
                                   r.mountingErrorDeg[i]);
            }
        }
        if (!far.empty()) {
            out.insert(out.size() - 1, fmt::format("mountings more than 10 deg off: {}\n", far));
        }
        // By mode, when any came from the nominal heading (docs/body-calibration.md, "Free
        // headings"), turned since from the joints or not: the rest were measured.
        std::array<std::vector<std::string>, 3> names;
        std::array<double, 3> sum{};
        std::array<double, 3> worst{};
        for (std::size_t i = 0;
             i < r.nominalHeading.size() && i < r.mountingErrorDeg.size() && i < b.sensors.size();
             ++i) {
            const std::size_t k = !r.nominalHeading[i] ? 2 : fromJoints(r, i) ? 1 : 0;
            names[k].push_back(b.sensors[i].name);
            sum[k] += r.mountingErrorDeg[i];
            worst[k] = std::max(worst[k], r.mountingErrorDeg[i]);
        }
        if (!names[0].empty() || !names[1].empty()) {
            auto part = [&](std::size_t k, std::string_view mode) {
                return names[k].empty()
                           ? fmt::format("0 {}", mode)
                           : fmt::format("{} {} {:.2f} deg mean, {:.2f} deg max", names[k].size(),
                                         mode, sum[k] / static_cast<double>(names[k].size()),
                                         worst[k]);
            };
            out.insert(
                out.size() - 1,
                fmt::format("mountings by mode: {} ({}); {} ({}); {}\n", part(0, "nominal-heading"),
                            fmt::join(names[0], " "), part(1, "from the joints"),
                            fmt::join(names[1], " "), part(2, "measured")));
        }
    }
    std::string clipped;
    for (std::size_t i = 0; i < r.gyroClipEvents.size() && i < b.sensors.size(); ++i) {
        if (r.gyroClipEvents[i] > 0) {
            clipped +=
                fmt::format("{}{} ({} time{})", clipped.empty() ? "" : ", ", b.sensors[i].name,
                            r.gyroClipEvents[i], r.gyroClipEvents[i] == 1 ? "" : "s");
        }
    }
    {
        // The magnetometers' heading sources at the end, counted by mode.
        std::map<std::string, std::vector<std::string>> byMode;
        for (std::size_t i = 0; i < r.magModes.size() && i < b.sensors.size(); ++i) {
            byMode[toString(r.magModes[i])].push_back(b.sensors[i].name);
        }
        std::string modes;
        for (const auto& [mode, names] : byMode) {
            modes += fmt::format("{}{} {}", modes.empty() ? "" : ", ", names.size(), mode);
            if (mode != toString(MagMode::Calibrated) && names.size() < 6) {
                modes += fmt::format(" ({})", fmt::join(names, " "));
            }
        }
        if (!modes.empty()) {
            out.insert(out.size() - 1, fmt::format("magnetometers at the end: {}\n", modes));
        }
        // When each free heading was measured and stepped to magnetic north (and which never were
        // though free at the end).
        std::string steps;
        for (std::size_t i = 0; i < r.headingSteps.size() && i < b.sensors.size(); ++i) {
            const auto& st = r.headingSteps[i];
            if (st.count > 0) {
                steps += fmt::format("{}{} {:.1f} s ({:+.1f} deg{})", steps.empty() ? "" : ", ",
                                     b.sensors[i].name, st.atS, st.angleDeg,
                                     st.count > 1 ? fmt::format(", {} steps", st.count) : "");
            }
        }
        // Why a heading is still free at the end: the estimate's figures (docs/fusion.md).
        std::string freeWhy;
        for (std::size_t i = 0; i < r.magModes.size() && i < b.sensors.size(); ++i) {
            if (r.magModes[i] != MagMode::Estimating || i >= r.magEstimates.size()) {
                continue;
            }
            const fusion::HardIronEstimate& e = r.magEstimates[i];
            freeWhy += fmt::format(
                "{}{} ({})", freeWhy.empty() ? "" : ", ", b.sensors[i].name,
                !e.valid ? std::string("too few readings")
                         : fmt::format("{}spread {:.3f}, residual {:.1f} %, field {:.1f} uT",
                                       e.good ? "good, heading error not yet steady: " : "",
                                       e.spread, e.residualPct, e.fieldNormUt));
        }
        if (!freeWhy.empty()) {
            out.insert(out.size() - 1,
                       fmt::format("gyroscope-only at the end, the estimate: {}\n", freeWhy));
        }
        // What the joints turned the free headings by (docs/body-calibration.md, "Headings from
        // the joints").
        std::string turns;
        int turned = 0;
        for (std::size_t i = 0; i < r.jointHeadingTurnDeg.size() && i < b.sensors.size(); ++i) {
            if (r.jointHeadingTurnDeg[i] != 0) {
                turns += fmt::format("{}{} {:+.1f}", turns.empty() ? "" : ", ", b.sensors[i].name,
                                     r.jointHeadingTurnDeg[i]);
                ++turned;
            }
        }
        if (turned > 0) {
            out.insert(out.size() - 1,
                       fmt::format("free headings set from the joints ({} sensors, deg): {}\n",
                                   turned, turns));
        }
        if (!steps.empty()) {
            // The stepped sensors' mountings: what the re-expression gave them.
            double sum = 0;
            double worst = 0;
            int n = 0;
            for (std::size_t i = 0; i < r.headingSteps.size() && i < r.mountingErrorDeg.size();
                 ++i) {
                if (r.headingSteps[i].count > 0) {
                    sum += r.mountingErrorDeg[i];
                    worst = std::max(worst, r.mountingErrorDeg[i]);
                    ++n;
                }
            }
            out.insert(out.size() - 1,
                       fmt::format("gyroscope-only headings stepped to magnetic (s from the start, "
                                   "lead-in included): {}; their {} mountings {:.2f} deg mean, "
                                   "{:.2f} deg max off the true ones\n",
                                   steps, n, n > 0 ? sum / n : 0.0, worst));
        }
    }
    if (!clipped.empty()) {
        out.insert(out.size() - 1,
                   fmt::format("gyroscope clipped (a rate beyond its full scale; the filter lost "
                               "an unknown rotation there): {}\n",
                               clipped));
    }
    if (!r.truthTurns.empty()) {
        std::string turns;
        for (const bs::ImplausibleTurns& t : r.truthTurns) {
            turns +=
                fmt::format("{}{} {} time{} (up to {:.0f} deg)", turns.empty() ? "" : ", ", t.joint,
                            t.frames, t.frames == 1 ? "" : "s", t.maxTurnRad * 180.0 / hal::kPi);
        }
        out.insert(out.size() - 1,
                   fmt::format("the clip's truth turns joints faster than a body can (beyond "
                               "10,000 deg/s from one frame to the next: a motion-capture "
                               "artefact; the errors there are the clip's): {}\n",
                               turns));
    }
    if (o.profile != bs::ErrorProfile::Ideal && o.sensorCalibrations.empty()) {
        out.insert(out.size() - 1,
                   "note: no --calibration: the chips' biases and the magnetometers' hard and "
                   "soft iron are uncorrected, so the filters' headings (and the T-pose "
                   "calibration) are off; `caphub calibrate gyro|accel|mag` makes the file\n");
    }
    out += body::formatScoreTable(r.score);
    if (r.smoothed) {
        const auto change = [](double now, double before) {
            return before > 0 ? fmt::format("{:+.1f} %", (now / before - 1) * 100)
                              : std::string("-");
        };
        out += fmt::format(
            "\nreprocessed --smooth ({:.2f} s of computing, {:.0f}x real time): 17-joint mean "
            "angle {:.2f} deg (live {:.2f}, {}), root drift at the end {:.3f} m (live {:.3f}, {}), "
            "max drift {:.3f} m (live {:.3f})\n",
            r.smoothWallS, r.smoothWallS > 0 ? (r.leadInS + r.clipS) / r.smoothWallS : 0.0,
            r.smoothed->independentMeanAngleDeg, r.score.independentMeanAngleDeg,
            change(r.smoothed->independentMeanAngleDeg, r.score.independentMeanAngleDeg),
            r.smoothed->finalDriftM, r.score.finalDriftM,
            change(r.smoothed->finalDriftM, r.score.finalDriftM), r.smoothed->maxDriftM,
            r.score.maxDriftM);
        out += "\n" + body::formatScoreTable(*r.smoothed);
    }
    return out;
}

std::string evaluationJson(const std::vector<EvaluateResult>& results, const board::Board& b,
                           const EvaluateOptions& o) {
    // Clip and board names are file names: quoted with the few escapes JSON needs.
    const auto quoted = [](const std::string& s) {
        std::string q = "\"";
        for (const char c : s) {
            if (c == '"' || c == '\\') {
                q += '\\';
                q += c;
            } else if (static_cast<unsigned char>(c) < 0x20) {
                q += fmt::format("\\u{:04x}", static_cast<int>(c));
            } else {
                q += c;
            }
        }
        return q + "\"";
    };
    std::string out = fmt::format(
        "{{\n  \"board\": {},\n  \"profile\": \"{}\",\n  \"seed\": {},\n  \"strap_deg\": {},\n"
        "  \"pose_rate_hz\": {},\n  \"measured_skeleton\": {},\n  \"clips\": [",
        quoted(b.name), bs::toString(o.profile), o.seed, o.strapDeg, o.poseRateHz,
        o.measuredSkeleton ? "true" : "false");
    for (std::size_t c = 0; c < results.size(); ++c) {
        const EvaluateResult& r = results[c];
        const body::PoseScore& s = r.score;
        // Per sensor: its mounting's error and mode (docs/body-calibration.md, "Free headings").
        std::string mountings;
        for (std::size_t i = 0; i < b.sensors.size() && i < r.mountingErrorDeg.size(); ++i) {
            const bool nominal = i < r.nominalHeading.size() && r.nominalHeading[i];
            mountings += fmt::format(
                "{}\n        {{\"sensor\": {}, \"error_deg\": {:.6f}, \"mode\": \"{}\", "
                "\"joint_turn_deg\": {:.6f}}}",
                i == 0 ? "" : ",", quoted(b.sensors[i].name), r.mountingErrorDeg[i],
                !nominal           ? "measured"
                : fromJoints(r, i) ? "from-joints"
                                   : "nominal-heading",
                i < r.jointHeadingTurnDeg.size() ? r.jointHeadingTurnDeg[i] : 0.0);
        }
        out += fmt::format(
            "{}\n    {{\n      \"clip\": {},\n      \"calibration\": {},\n"
            "      \"samples\": {},\n      \"poses\": {},\n      \"scored_poses\": {},\n"
            "      \"lead_in_s\": {:.6f},\n      \"clip_s\": {:.6f},\n"
            "      \"mounting_error_mean_deg\": {:.6f},\n      \"mounting_error_max_deg\": "
            "{:.6f},\n"
            "      \"nominal_mounting_error_mean_deg\": {:.6f},\n"
            "      \"mountings\": [{}\n      ],\n"
            "      \"mean_angle_deg\": {:.6f},\n      \"mean_position_m\": {:.6f},\n"
            "      \"walked_m\": {:.6f},\n      \"final_drift_m\": {:.6f},\n"
            "      \"max_drift_m\": {:.6f},\n      \"stance_changes\": {},\n"
            "      \"mean_height_error_m\": {:.6f},\n      \"max_height_error_m\": {:.6f},\n"
            "      \"independent_mean_angle_deg\": {:.6f},\n"
            "      \"independent_mean_position_m\": {:.6f},\n"
            "      \"measured_joints\": {},\n      \"measured_independent_joints\": {},\n"
            "      \"root_translation_measured\": {},\n      \"joints\": [",
            c == 0 ? "" : ",", quoted(r.clip), quoted(r.calibration), r.samples, r.poses, s.frames,
            r.leadInS, r.clipS, r.mountingErrorMeanDeg, r.mountingErrorMaxDeg,
            r.nominalMountingErrorMeanDeg, mountings, s.meanAngleDeg, s.meanPositionM, s.walkedM,
            s.finalDriftM, s.maxDriftM, s.stanceChanges, s.meanHeightErrorM, s.maxHeightErrorM,
            s.independentMeanAngleDeg, s.independentMeanPositionM, s.measuredJoints,
            s.measuredIndependentJoints, body::rootTranslationMeasured(s.measured));
        for (int i = 0; i < body::kSegmentCount; ++i) {
            const auto u = static_cast<std::size_t>(i);
            out += fmt::format(
                "{}\n        {{\"joint\": \"{}\", \"segment\": \"{}\", \"angle_deg\": {:.6f}, "
                "\"position_m\": {:.6f}, \"measured\": {}}}",
                i == 0 ? "" : ",", body::joints()[u].name,
                board::segmentName(static_cast<board::Segment>(i)), s.angleDeg[u], s.positionM[u],
                ((s.measured >> i) & 1U) != 0);
        }
        out += "\n      ],\n      \"independent_joints\": [";
        for (std::size_t j = 0; j < body::independentJoints().size(); ++j) {
            out += fmt::format(
                "{}\n        {{\"joint\": \"{}\", \"angle_deg\": {:.6f}, \"position_m\": {:.6f}, "
                "\"measured\": {}}}",
                j == 0 ? "" : ",", body::independentJoints()[j].name, s.independentAngleDeg[j],
                s.independentPositionM[j], body::independentJointMeasured(s.measured, j));
        }
        out += "\n      ],\n      \"truth_implausible_turns\": {";
        for (std::size_t i = 0; i < r.truthTurns.size(); ++i) {
            out += fmt::format("{}{}: {}", i == 0 ? "" : ", ", quoted(r.truthTurns[i].joint),
                               r.truthTurns[i].frames);
        }
        out += "},\n      \"gyro_clipped\": {";
        for (std::size_t i = 0; i < r.gyroClipEvents.size() && i < b.sensors.size(); ++i) {
            out += fmt::format("{}{}: {}", i == 0 ? "" : ", ", quoted(b.sensors[i].name),
                               r.gyroClipEvents[i]);
        }
        out += "}\n    }";
    }
    out += "\n  ]\n}\n";
    return out;
}

}  // namespace caphub::firmware
