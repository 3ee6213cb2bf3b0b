// The virtual suit's side of the guided sensor calibration: on a running virtual suit the
// subject must really do the motions (lie still, turn the sensors through the positions, tumble
// them), so each sensor's physical source is wrapped in one that plays, while a calibration
// script is on, the scripted motion of `caphub calibrate` (board/sim/scripted_motion.h) instead
// of the clip: each sensor off the body, the same simulated part (partSeed). Outside a script the
// clip (or rest) goes on as before.
#pragma once

#include <atomic>
#include <memory>
#include <vector>

#include "board/sim/virtual_suit.h"
#include "hal/core/time.h"

namespace caphub::firmware::serve {

class CalibrationMotion {
public:
    // The suit's sensor errors (profile, seed): the scripted parts are the same parts.
    CalibrationMotion(const board::Board& board, board::sim::ErrorProfile profile,
                      std::uint64_t seed);

    // The factory the virtual suit is built with: `inner`'s sources (the clip; none: rest),
    // each wrapped so that a script can take over.
    board::sim::SourceFactory wrap(board::sim::SourceFactory inner);

    // From `start` on the capture clock, every sensor plays the script (time 0 at `start`) until
    // stop(); before `start` the clip goes on.
    void play(board::sim::Script script, const board::sim::ScriptTiming& timing, Timestamp start);
    void stop();

    // The active script's sources, one per board sensor (a source reads it on its bus thread).
    struct Active {
        Timestamp start{};
        std::vector<std::unique_ptr<hal::sim::PhysicalSource>> sources;
    };

private:
    const board::Board& board_;
    board::sim::ErrorProfile profile_;
    std::uint64_t seed_;
    std::shared_ptr<std::atomic<std::shared_ptr<Active>>> active_;
};

}  // namespace caphub::firmware::serve
