// caphub evaluate: the body solver scored against the simulation's ground truth through the whole
// path of `caphub run` on the virtual suit (chip models, drivers, bus workers, FusionStage,
// BodyStage with its T-pose calibration): the per-joint error table of every clip. A
// measurement, not a test: it exits 0 whatever the errors are. A clip that gives not a single
// scored pose is bad input (exit 2), never a table of zeros.
#include <algorithm>
#include <filesystem>
#include <optional>
#include <vector>

#include <fmt/format.h>

#include "board/loader.h"
#include "board/sim/virtual_suit.h"
#include "firmware/calibration_file.h"
#include "firmware/cli/app.h"
#include "firmware/cli/commands.h"
#include "firmware/cli/data_dir.h"
#include "firmware/cli/number_checks.h"
#include "firmware/cli/smooth_heading_option.h"
#include "firmware/cli/suit_options.h"
#include "firmware/evaluation.h"
#include "firmware/export/output_file.h"
#include "hal/core/input_file.h"

namespace caphub::firmware {

namespace {

namespace fs = std::filesystem;

struct EvaluateCliOptions {
    std::vector<std::string> bvh;
    SuitCliOptions suit;
    std::string calibrate = "tpose";
    std::string calibration;
    double poseRateHz = 60;
    std::string skeleton = "clip";
    std::string json;
    std::string magState;
    bool noBodyAiding = false;
    bool noFootInertial = false;
    std::string kneeHeading = "estimate";
    bool noJointHeading = false;
    bool reprocessSmooth = false;
    std::string smoothHeading = "causal";
    bool brief = false;
    std::vector<std::uint64_t> seeds;
};

// A clip whose true root never gets further than this from where it started is "in place": its
// drift is read in cm, not as a share of a path that is mostly sway.
constexpr double kInPlaceM = 0.5;

// One row per clip (the means over its seeds; the height's and the drift's worst seed beside
// them), then the summary: the 17 joints' angle and position error, the root's horizontal drift
// (% of the true path; cm for in-place clips) and its height error (docs/skeleton.md, "Every
// shared clip").
std::string summaryTable(const std::vector<EvaluateResult>& results) {
    std::vector<std::string> clips;
    for (const auto& r : results) {
        if (std::find(clips.begin(), clips.end(), r.clip) == clips.end()) {
            clips.push_back(r.clip);
        }
    }
    std::string out = fmt::format(
        "\nevery clip, mean over its seeds (worst seed in brackets): the 17 joints' angle (deg) "
        "and "
        "position (cm, relative to the root), the true path (m), the root's horizontal drift at "
        "the end (% of the path; cm for a clip in place, the root never {:g} m from its start), "
        "its height error mean "
        "and max (cm)\n"
        "| clip | seeds | angle deg | position cm | path m | drift | height mean cm | height max "
        "cm |\n|---|---|---|---|---|---|---|---|\n",
        kInPlaceM);
    double angle = 0;
    double position = 0;
    double heightMean = 0;
    double heightMax = 0;
    double movingPct = 0;
    double inPlaceCm = 0;
    int moving = 0;
    int inPlace = 0;
    for (const auto& clip : clips) {
        double a = 0;
        double p = 0;
        double path = 0;
        double drift = 0;
        double driftWorst = 0;
        double hm = 0;
        double hmWorst = 0;
        double hx = 0;
        bool walks = false;
        int n = 0;
        for (const auto& r : results) {
            if (r.clip != clip) {
                continue;
            }
            const body::PoseScore& s = r.score;
            a += s.independentMeanAngleDeg;
            p += s.independentMeanPositionM * 100;
            path += s.walkedM;
            // The truth, and so whether it travels, is the same for every seed.
            walks = s.excursionM >= kInPlaceM && s.walkedM > 0;
            const double d = walks ? s.finalDriftM / s.walkedM * 100 : s.finalDriftM * 100;
            drift += d;
            driftWorst = std::max(driftWorst, d);
            hm += s.meanHeightErrorM * 100;
            hmWorst = std::max(hmWorst, s.meanHeightErrorM * 100);
            hx = std::max(hx, s.maxHeightErrorM * 100);
            ++n;
        }
        const double k = n;
        out += fmt::format(
            "| {} | {} | {:.2f} | {:.2f} | {:.2f} | {:.2f} {} ({:.2f}) | {:.2f} ({:.2f}) "
            "| {:.2f} |\n",
            clip, n, a / k, p / k, path / k, drift / k, walks ? "%" : "cm", driftWorst, hm / k,
            hmWorst, hx);
        angle += a / k;
        position += p / k;
        heightMean += hm / k;
        heightMax = std::max(heightMax, hx);
        (walks ? movingPct : inPlaceCm) += drift / k;
        ++(walks ? moving : inPlace);
    }
    const double c = static_cast<double>(clips.size());
    out += fmt::format(
        "summary over {} clips: 17 joints {:.2f} deg / {:.2f} cm; drift {:.2f} % over {} clips "
        "that travel, {:.2f} cm over {} in place; height error {:.2f} cm mean, {:.2f} cm at "
        "worst\n",
        clips.size(), angle / c, position / c, moving > 0 ? movingPct / moving : 0.0, moving,
        inPlace > 0 ? inPlaceCm / inPlace : 0.0, inPlace, heightMean / c, heightMax);
    return out;
}

// With --reprocess-smooth: one row per clip and seed, live against reprocessed-smoothed, and
// the means.
std::string smoothTable(const std::vector<EvaluateResult>& results,
                        const std::vector<std::uint64_t>& seeds) {
    std::string out = fmt::format(
        "\nlive against `caphub reprocess --smooth`: 17-joint mean angle error (deg), root drift "
        "at the end (m)\n{:<34} {:>4} {:>10} {:>10} {:>8} {:>10} {:>10} {:>8}\n",
        "clip", "seed", "live deg", "smooth", "change", "live m", "smooth", "change");
    double la = 0;
    double sa = 0;
    double ld = 0;
    double sd = 0;
    std::size_t n = 0;
    for (std::size_t i = 0; i < results.size(); ++i) {
        const EvaluateResult& r = results[i];
        if (!r.smoothed) {
            continue;
        }
        const auto pct = [](double now, double before) {
            return before > 0 ? fmt::format("{:+.1f}%", (now / before - 1) * 100)
                              : std::string("-");
        };
        out += fmt::format(
            "{:<34} {:>4} {:>10.2f} {:>10.2f} {:>8} {:>10.3f} {:>10.3f} {:>8}\n", r.clip, seeds[i],
            r.score.independentMeanAngleDeg, r.smoothed->independentMeanAngleDeg,
            pct(r.smoothed->independentMeanAngleDeg, r.score.independentMeanAngleDeg),
            r.score.finalDriftM, r.smoothed->finalDriftM,
            pct(r.smoothed->finalDriftM, r.score.finalDriftM));
        la += r.score.independentMeanAngleDeg;
        sa += r.smoothed->independentMeanAngleDeg;
        ld += r.score.finalDriftM;
        sd += r.smoothed->finalDriftM;
        ++n;
    }
    if (n > 0) {
        const double k = static_cast<double>(n);
        out += fmt::format("{:<34} {:>4} {:>10.2f} {:>10.2f} {:>8} {:>10.3f} {:>10.3f} {:>8}\n",
                           "mean", "", la / k, sa / k, fmt::format("{:+.1f}%", (sa / la - 1) * 100),
                           ld / k, sd / k,
                           ld > 0 ? fmt::format("{:+.1f}%", (sd / ld - 1) * 100) : "-");
    }
    return out;
}

int evaluate(const EvaluateCliOptions& c) {
    const auto loaded = loadVirtualSuitBoard(c.suit.board, "caphub evaluate", "the evaluation");
    if (!loaded) {
        return kExitUsage;
    }
    const board::Board& b = *loaded;
    EvaluateOptions o;
    o.map = c.suit.map;
    o.seed = c.suit.seed;
    o.strapDeg = c.suit.strapDeg;
    o.chipDelayS = c.suit.chipDelayMs * 1e-3;
    o.poseRateHz = c.poseRateHz;
    o.aidFilters = !c.noBodyAiding;
    o.footInertial = !c.noFootInertial;
    o.kneeHeading = c.kneeHeading == "off"    ? body::KneeHeadingMode::Off
                    : c.kneeHeading == "live" ? body::KneeHeadingMode::Live
                                              : body::KneeHeadingMode::Estimate;
    o.jointHeading = !c.noJointHeading;
    o.reprocessSmooth = c.reprocessSmooth;
    fusion::setSmoothHeading(o.smoothing, c.smoothHeading);
    o.magState = c.magState;
    const auto profile = suitProfile(c.suit, "caphub evaluate");
    if (!profile) {
        return kExitUsage;
    }
    o.profile = *profile;
    if (c.calibrate == "tpose") {
        o.calibrate = body::ReferencePoseKind::T;
    } else if (c.calibrate == "none") {
        o.calibrate.reset();
    } else if (c.calibrate == "npose") {
        o.calibrate = body::ReferencePoseKind::N;
    } else {
        fmt::print(stderr,
                   "caphub evaluate: --calibrate: expected tpose, npose or none, got '{}'\n",
                   c.calibrate);
        return kExitUsage;
    }
    if (c.skeleton != "clip" && c.skeleton != "board") {
        fmt::print(stderr, "caphub evaluate: --skeleton: expected clip or board, got '{}'\n",
                   c.skeleton);
        return kExitUsage;
    }
    o.measuredSkeleton = c.skeleton == "clip";
    // The sensor calibration file; "{seed}" in its name stands for each seed's own (the
    // virtual suit's parts differ from seed to seed).
    const auto calibrationFor =
        [&](std::uint64_t seed) -> std::optional<FusionStage::Calibrations> {
        std::string path = c.calibration;
        if (const auto at = path.find("{seed}"); at != std::string::npos) {
            path.replace(at, 6, std::to_string(seed));
        }
        auto set = readCalibrationFile(path);
        if (!set) {
            fmt::print(stderr, "caphub evaluate: {}\n", set.error().message);
            return std::nullopt;
        }
        return calibrationsFor(b, *set, nullptr);
    };
    const std::vector<std::uint64_t> seeds =
        c.seeds.empty() ? std::vector<std::uint64_t>{c.suit.seed} : c.seeds;
    // A seed twice would count its run twice in every mean.
    for (std::size_t i = 0; i < seeds.size(); ++i) {
        if (std::find(seeds.begin(), seeds.begin() + static_cast<std::ptrdiff_t>(i), seeds[i]) !=
            seeds.begin() + static_cast<std::ptrdiff_t>(i)) {
            fmt::print(stderr, "caphub evaluate: --seeds: seed {} is given twice\n", seeds[i]);
            return kExitUsage;
        }
    }
    if (!c.calibration.empty()) {
        for (const std::uint64_t seed : seeds) {
            if (!calibrationFor(seed)) {
                return kExitUsage;
            }
        }
    }
    // Every clip is checked before the first (long) run: a file, a BVH its map reads, a body in
    // metres (a mistake in the last of twelve clips used to show after eleven runs).
    for (const auto& path : c.bvh) {
        if (auto ok = checkInputFile(path); !ok) {
            fmt::print(stderr, "caphub evaluate: --bvh: {}\n", ok.error().message);
            return kExitUsage;
        }
        board::sim::ClipOptions clip;
        clip.bvh = path;
        clip.map = c.suit.map;
        if (auto motion = board::sim::clipSources(clip, Timestamp{}); !motion) {
            fmt::print(stderr, "caphub evaluate: {}\n", motion.error().message);
            return kExitUsage;
        }
    }
    // Where the scores go is checked before the first run too: the folder exists, and it is
    // not a file the evaluation reads.
    std::optional<fs::path> jsonTarget;
    if (!c.json.empty()) {
        std::vector<std::string> inputs = c.bvh;
        for (const std::uint64_t seed : seeds) {
            std::string path = c.calibration;
            if (const auto at = path.find("{seed}"); at != std::string::npos) {
                path.replace(at, 6, std::to_string(seed));
            }
            inputs.push_back(path);
        }
        inputs.insert(inputs.end(), {c.suit.board, c.suit.map, c.magState});
        auto target = exporter::claimOutputTarget(c.json, "--json", inputs);
        if (!target) {
            fmt::print(stderr, "caphub evaluate: {}\n", target.error().message);
            return kExitUsage;
        }
        jsonTarget = *target;
    }

    std::vector<EvaluateResult> results;
    std::vector<std::uint64_t> seedOf;
    for (const auto& path : c.bvh) {
        for (const std::uint64_t seed : seeds) {
            o.bvh = path;
            o.seed = seed;
            if (!c.calibration.empty()) {
                auto cals = calibrationFor(seed);
                if (!cals) {
                    return kExitUsage;
                }
                o.sensorCalibrations = std::move(*cals);
            }
            auto r = evaluateClip(b, o);
            if (!r) {
                fmt::print(stderr, "caphub evaluate: {}\n", r.error().message);
                return r.error().code == EINVAL ? kExitUsage : kExitRuntime;
            }
            if (c.brief) {
                const body::PoseScore& s = r->score;
                std::string turns;
                for (const board::sim::ImplausibleTurns& t : r->truthTurns) {
                    turns += fmt::format("{} {} {}",
                                         turns.empty() ? "; the truth turns faster "
                                                         "than a body can:"
                                                       : ",",
                                         t.joint, t.frames);
                }
                fmt::print(
                    "{} seed {}: 17 joints {:.3f} deg / {:.3f} cm, path {:.3f} m, drift "
                    "{:.3f} m, height error {:.3f} m mean / {:.3f} m max{}\n",
                    r->clip, seed, s.independentMeanAngleDeg, s.independentMeanPositionM * 100,
                    s.walkedM, s.finalDriftM, s.meanHeightErrorM, s.maxHeightErrorM, turns);
            } else {
                fmt::print("{}\n", formatEvaluation(*r, b, o));
            }
            std::fflush(stdout);
            results.push_back(std::move(*r));
            seedOf.push_back(seed);
        }
    }
    if (results.size() > 1 || c.brief) {
        fmt::print("{}", summaryTable(results));
    }
    if (c.reprocessSmooth) {
        fmt::print("{}", smoothTable(results, seedOf));
    }
    if (jsonTarget) {
        if (auto w = exporter::writeWholeFile(*jsonTarget, evaluationJson(results, b, o)); !w) {
            fmt::print(stderr, "caphub evaluate: --json: {}\n", w.error().message);
            return kExitRuntime;
        }
        fmt::print("scores written to {}\n", c.json);
    }
    return kExitOk;
}

}  // namespace

void addEvaluateCommand(CLI::App& app, int& exitCode) {
    auto o = std::make_shared<EvaluateCliOptions>();
    CLI::App* cmd = app.add_subcommand(
        "evaluate",
        "Score the body solver against the virtual suit's ground truth through fusion and body");
    cmd->add_option("--bvh", o->bvh, "A motion clip (BVH) to score; repeatable")->required();
    addSuitOptions(*cmd, o->suit);
    cmd->add_option("--calibrate", o->calibrate,
                    "Body calibration in the lead-in's T-pose: tpose, or none (the board's "
                    "nominal mountings)")
        ->capture_default_str();
    cmd->add_option("--calibration", o->calibration,
                    "Sensor calibration file (caphub calibrate) applied before the filters")
        ->check(nonEmptyPath());
    cmd->add_option("--pose-rate", o->poseRateHz, "Poses per second of the body solver")
        ->check(finiteRange(1.0, 1000.0))
        ->capture_default_str();
    cmd->add_option("--skeleton", o->skeleton,
                    "The body's skeleton: clip (measured from the clip, as the subject's own "
                    "lengths would be) or board (the board's [subject] proportions)")
        ->capture_default_str();
    cmd->add_option("--json", o->json, "Also write the scores to this JSON file")
        ->check(nonEmptyPath());
    cmd->add_option("--mag-state", o->magState,
                    "The online hard-iron estimators' sums of the sensors whose magnetometer the "
                    "--calibration file does not correct: read before each clip when the file "
                    "exists, written after it (docs/fusion.md, \"No magnetometer calibration\")")
        ->check(nonEmptyPath());
    cmd->add_flag("--no-body-aiding", o->noBodyAiding,
                  "Do not tell the filters the body's acceleration (from the foot contacts): "
                  "to see what it does");
    cmd->add_flag("--no-foot-inertial", o->noFootInertial,
                  "Do not track the planted foot's slip with its own sensor (the root follows "
                  "the foot contacts alone): to see what it does");
    cmd->add_option("--knee-heading", o->kneeHeading,
                    "The capture heading from the knees' axes: estimate (report what they say), "
                    "live (also correct it once known, mid-capture) or off "
                    "(docs/body-calibration.md)")
        ->check(CLI::IsMember({"off", "estimate", "live"}));
    cmd->add_flag("--no-joint-heading", o->noJointHeading,
                  "Do not set the free (gyroscope-only) headings from the joints' accelerations "
                  "(docs/body-calibration.md, \"Headings from the joints\"): to see what it does");
    cmd->add_flag("--reprocess-smooth", o->reprocessSmooth,
                  "Also reprocess each capture's raw samples with `caphub reprocess --smooth` "
                  "and score it: live against smoothed, a table at the end");
    addSmoothHeadingOption(*cmd, o->smoothHeading, "--reprocess-smooth");
    cmd->add_flag("--brief", o->brief,
                  "One line per clip and seed instead of the per-joint tables; the summary table "
                  "over every clip at the end as always with several runs");
    cmd->add_option("--seeds", o->seeds, "Several seeds (instead of --seed): each clip with each")
        ->delimiter(',')
        ->check(seedNumber());
    cmd->callback([&exitCode, o] { exitCode = evaluate(*o); });
}

}  // namespace caphub::firmware
