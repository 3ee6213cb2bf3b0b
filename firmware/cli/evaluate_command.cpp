// caphub evaluate: the body solver scored against the simulation's ground truth through the whole
// path of `caphub run` on the virtual suit (chip models, drivers, bus workers, FusionStage,
// BodyStage with its T-pose calibration): the per-joint error table of every clip. A
// measurement, not a test: it exits 0 whatever the errors are. A clip that gives not a single
// scored pose is bad input (exit 2), never a table of zeros.
#include <filesystem>
#include <fstream>
#include <vector>

#include <fmt/format.h>

#include "board/loader.h"
#include "firmware/calibration_file.h"
#include "firmware/cli/app.h"
#include "firmware/cli/commands.h"
#include "firmware/cli/data_dir.h"
#include "firmware/cli/suit_options.h"
#include "firmware/evaluation.h"
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
};

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
    o.poseRateHz = c.poseRateHz;
    o.aidFilters = !c.noBodyAiding;
    o.footInertial = !c.noFootInertial;
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
    if (!c.calibration.empty()) {
        auto set = readCalibrationFile(c.calibration);
        if (!set) {
            fmt::print(stderr, "caphub evaluate: {}\n", set.error().message);
            return kExitUsage;
        }
        o.sensorCalibrations = calibrationsFor(b, *set, nullptr);
    }
    // Every clip is checked before the first (long) run.
    for (const auto& path : c.bvh) {
        if (auto ok = checkInputFile(path); !ok) {
            fmt::print(stderr, "caphub evaluate: --bvh: {}\n", ok.error().message);
            return kExitUsage;
        }
    }

    std::vector<EvaluateResult> results;
    for (const auto& path : c.bvh) {
        o.bvh = path;
        auto r = evaluateClip(b, o);
        if (!r) {
            fmt::print(stderr, "caphub evaluate: {}\n", r.error().message);
            return r.error().code == EINVAL ? kExitUsage : kExitRuntime;
        }
        fmt::print("{}\n", formatEvaluation(*r, b, o));
        results.push_back(std::move(*r));
    }
    if (!c.json.empty()) {
        std::ofstream out(c.json, std::ios::trunc);
        out << evaluationJson(results, b, o);
        out.close();
        if (!out) {
            fmt::print(stderr, "caphub evaluate: --json: cannot write '{}'\n", c.json);
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
                    "Sensor calibration file (caphub calibrate) applied before the filters");
    cmd->add_option("--pose-rate", o->poseRateHz, "Poses per second of the body solver")
        ->check(CLI::Range(1.0, 1000.0))
        ->capture_default_str();
    cmd->add_option("--skeleton", o->skeleton,
                    "The body's skeleton: clip (measured from the clip, as the subject's own "
                    "lengths would be) or board (the board's [subject] proportions)")
        ->capture_default_str();
    cmd->add_option("--json", o->json, "Also write the scores to this JSON file");
    cmd->add_option("--mag-state", o->magState,
                    "The online hard-iron estimators' sums of the sensors whose magnetometer the "
                    "--calibration file does not correct: read before each clip when the file "
                    "exists, written after it (docs/fusion.md, \"No magnetometer calibration\")");
    cmd->add_flag("--no-body-aiding", o->noBodyAiding,
                  "Do not tell the filters the body's acceleration (from the foot contacts): "
                  "to see what it does");
    cmd->add_flag("--no-foot-inertial", o->noFootInertial,
                  "Do not track the planted foot's slip with its own sensor (the root follows "
                  "the foot contacts alone): to see what it does");
    cmd->callback([&exitCode, o] { exitCode = evaluate(*o); });
}

}  // namespace caphub::firmware
