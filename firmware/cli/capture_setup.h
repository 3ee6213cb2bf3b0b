// What a command that runs a live Hub (`caphub run`, `caphub serve`) builds before it: the
// clock, the suit (the hub's buses, or the virtual suit playing a clip), the sensor calibrations
// and the board file's text for the recordings' metadata; and the stop signals.
#pragma once

#include <array>
#include <csignal>
#include <functional>
#include <memory>
#include <optional>
#include <string>

#include <CLI/CLI.hpp>

#include "board/board.h"
#include "board/hardware.h"
#include "board/sim/virtual_suit.h"
#include "firmware/runtime/capture.h"
#include "firmware/runtime/fusion_stage.h"
#include "firmware/runtime/hub.h"
#include "fusion/body/body_calibration.h"
#include "hal/core/clock.h"
#include "hal/core/error.h"

namespace caphub::firmware {

struct CaptureSetupOptions {
    // Virtual suit only: the motion (empty: the shipped walking clip), its joint map, the sensor
    // errors and their seed; standing still instead of a clip; simulated seconds per second.
    std::string bvh;
    std::string map;
    std::string profile = "typical";
    std::uint64_t seed = 1;
    bool rest = false;
    double speed = 1.0;
    // The virtual subject first holds this pose for holdS seconds (a calibration at the start).
    std::optional<body::ReferencePoseKind> leadInPose;
    double holdS = 0;
    // A sensor calibration file (empty: none).
    std::string calibration;
    // Virtual suit: wraps the sources it is built with (the guided sensor calibration of
    // `caphub serve` plays its scripted motions through them); none: as they are.
    std::function<board::sim::SourceFactory(board::sim::SourceFactory)> wrapSources;
};

struct CaptureSetup {
    bool sim = false;
    std::unique_ptr<Clock> clock;
    std::optional<board::SuitHardware> suit;
    // Virtual suit: where each sensor truly sits (for the mountings' errors); may be empty.
    std::function<board::sim::SensorPlacement(const board::SensorConfig&, int)> placementOf;
    std::string motionText = "at rest";  // what the virtual suit plays
    FusionStage::Calibrations calibrations;
    std::string calibrationText;  // the calibration file, as recorded in the metadata
    std::string boardText;        // the board file, as recorded in the metadata
};

// The virtual suit's options of a live command (--speed, --bvh, --map, --profile, --seed,
// --rest) into o.
void addVirtualSuitOptions(CLI::App& cmd, CaptureSetupOptions& o);

// Errors: EINVAL for what the user gave (a profile, a clip, a calibration file), anything else
// for the suit that would not open. Warnings (a calibration for a sensor not on the board, no
// clip found) are logged.
Result<CaptureSetup> buildCaptureSetup(const board::Board& b, const CaptureSetupOptions& o);

// The preview of a live Hub into these sinks at `fps`: the default skin loaded and both put into
// the Hub's options. A sink that could not be opened, or a skin that cannot be loaded, is printed
// ("caphub run: preview ...") and the capture goes on without it.
void attachPreview(HubOptions& ho, render::SinkSet sinks, double fps, std::string_view command);

// SIGINT, SIGTERM and SIGHUP (a closed terminal, unless ignored at the start) stop the capture
// cleanly (its recordings complete, the status file says it ended), also when they come before it
// started: install before creating what must be closed, arm once the Hub exists.
class StopSignals {
public:
    static constexpr std::array<int, 3> kStopping{SIGINT, SIGTERM, SIGHUP};

    StopSignals();
    ~StopSignals();
    StopSignals(const StopSignals&) = delete;
    StopSignals& operator=(const StopSignals&) = delete;
    // From now on a signal stops this capture; one that came already stops it at once.
    void arm(Capture& capture);
    // A signal came.
    static bool signalled();

private:
    std::array<struct sigaction, kStopping.size()> previous_{};
};

}  // namespace caphub::firmware
