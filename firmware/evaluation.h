// The body solver scored through the whole pipeline of the virtual suit: a clip plays on the
// suit's chip models after a T-pose lead-in, every sample goes through the FusionStage and the
// BodyStage of `caphub run`, and each solved pose is scored against the simulation's ground
// truth at its time (fusion/body/pose_score.h). For `caphub evaluate` and its tests.
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "board/board.h"
#include "board/sim/bvh.h"
#include "board/sim/imu_model.h"
#include "board/sim/virtual_suit.h"
#include "firmware/runtime/fusion_stage.h"
#include "fusion/body/body_calibration.h"
#include "fusion/body/knee_heading.h"
#include "fusion/body/pose_score.h"
#include "fusion/smoother.h"
#include "hal/core/error.h"

namespace caphub::firmware {

// How far a body calibration's mountings are from the virtual suit's true (strapped) ones, and
// how far the board's nominal mountings are, in degrees over the board's sensors.
struct MountingErrors {
    double meanDeg = 0;
    double maxDeg = 0;
    double nominalMeanDeg = 0;
    std::vector<double> perSensorDeg;  // in the board's order
};
MountingErrors mountingErrors(
    const body::BodyCalibration& calibration, const board::Board& b,
    const std::function<board::sim::SensorPlacement(const board::SensorConfig&, int)>& placementOf);

struct EvaluateOptions {
    std::filesystem::path bvh;
    std::filesystem::path map;  // empty: detect a built-in joint map
    board::sim::ErrorProfile profile = board::sim::ErrorProfile::Typical;
    std::uint64_t seed = 1;
    double strapDeg = 10;   // the sensors' strapping error scale (board/sim/virtual_suit.h)
    double chipDelayS = 0;  // board::sim::ClipOptions::chipDelayS
    // The body calibration in the lead-in's T-pose; none: the board's nominal mountings.
    std::optional<body::ReferencePoseKind> calibrate = body::ReferencePoseKind::T;
    FusionStage::Calibrations sensorCalibrations;  // per board sensor; may be empty
    double poseRateHz = 60;
    // true: the body stage gets the clip subject's skeleton measured from the clip (as the
    // ideal-orientation evaluation does); false: the board's [subject] proportions.
    bool measuredSkeleton = true;
    // BodyStage::Options::aidFilters: the filters told the body's acceleration.
    bool aidFilters = true;
    // BodyStage::Options::footInertial: the planted foot's slip from its own sensor.
    bool footInertial = true;
    // BodyStage::Options::kneeHeading: the capture heading from the knees' axes.
    body::KneeHeadingMode kneeHeading = body::KneeHeadingMode::Estimate;
    // BodyStage::Options::jointHeading: free headings set from the joints.
    bool jointHeading = true;
    // Also reprocess the capture's raw samples with the non-causal pass (`caphub reprocess
    // --smooth`, firmware/reprocess.h: the same calibration, pose rate and skeleton) and score
    // its poses against the same truth.
    bool reprocessSmooth = false;
    fusion::SmootherOptions smoothing;  // the reprocess's
    // The online hard-iron estimators' state file (docs/fusion.md, "No magnetometer
    // calibration"): one line per sensor, "name" and 19 numbers; read before the run when it
    // exists, written after it. Empty: none.
    std::filesystem::path magState;
};

struct EvaluateResult {
    std::string clip;
    body::PoseScore score;
    std::uint64_t samples = 0;  // sensor samples through the pipeline
    std::uint64_t poses = 0;    // poses the body stage solved (lead-in included)
    double leadInS = 0;         // the T-pose hold and the blend into the clip, not scored
    double clipS = 0;           // the clip's duration: the scored part
    std::string calibration;    // "T-pose", "nominal mountings", ...
    // The calibrated mountings against the sensors' true (strapped) ones, deg; and the board's
    // nominal mountings against the same.
    double mountingErrorMeanDeg = 0;
    double mountingErrorMaxDeg = 0;
    std::vector<double> mountingErrorDeg;  // per board sensor
    double nominalMountingErrorMeanDeg = 0;
    // What the knees' axes say the capture heading is off by at the end (deg; none before the
    // legs moved enough or for a calibration it does not apply to), and whether it was applied.
    std::optional<double> kneeHeadingErrorDeg;
    bool kneeHeadingApplied = false;
    // Per board sensor at the end: its mounting's mode. true: nominal-heading (its heading was
    // free at the calibration and has not been measured since: the rotation about the vertical
    // is the nominal mounting's, the rest from gravity); false: measured.
    std::vector<bool> nominalHeading;
    // Per board sensor: how many times its gyroscope clipped (rates beyond its full scale).
    std::vector<std::uint32_t> gyroClipEvents;
    // The clip's joints that turn faster than a body can (board/sim/bvh.h): where the truth
    // itself is a motion-capture artefact, the errors there are not the solver's.
    std::vector<board::sim::ImplausibleTurns> truthTurns;
    // Per board sensor at the end of the run: its heading source and its online hard-iron
    // estimate (docs/fusion.md, "No magnetometer calibration").
    std::vector<MagMode> magModes;
    std::vector<fusion::HardIronEstimate> magEstimates;
    // Per sensor, its free (gyroscope-only) heading's steps to magnetic north: how many, and the
    // latest's time (s from the start of the capture, the lead-in included) and angle (deg).
    struct HeadingStepFigure {
        std::uint32_t count = 0;
        double atS = 0;
        double angleDeg = 0;
    };
    std::vector<HeadingStepFigure> headingSteps;
    // Per sensor the turn its joints gave its free heading at the end (deg; 0: none, or measured
    // since: body::BodyTracker::jointHeadingTurns).
    std::vector<double> jointHeadingTurnDeg;
    double wallS = 0;
    // With reprocessSmooth: the smoothed poses' score, and the reprocess's computing time.
    std::optional<body::PoseScore> smoothed;
    double smoothWallS = 0;
};

// Errors: a board that is not a virtual suit, a clip that cannot be read or mapped or is too
// short to score a single pose (EINVAL: bad input); a body calibration that fails (EIO).
Result<EvaluateResult> evaluateClip(const board::Board& board, const EvaluateOptions& options);

// The pipeline's facts, then the per-joint table and the root line.
std::string formatEvaluation(const EvaluateResult& r, const board::Board& board,
                             const EvaluateOptions& options);

// Every result as one JSON document.
std::string evaluationJson(const std::vector<EvaluateResult>& results, const board::Board& board,
                           const EvaluateOptions& options);

}  // namespace caphub::firmware
