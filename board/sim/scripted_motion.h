// Scripted motions of a sensor off the body, for calibrating on the virtual suit: lying still,
// turned through six positions (each axis up and down) or fourteen (each face and each corner
// up), or tumbled slowly through every direction. A rigid body at a fixed place on a table; smooth,
// so that the gyro and accelerometer signals the IMU model derives from it are physical.
#pragma once

#include <cstdint>
#include <string_view>

#include "board/sim/motion.h"

namespace caphub::board::sim {

enum class Script {
    Rest,               // level (z up), facing north
    SixPositions,       // +z, -z, +x, -x, +y, -y up in turn, each held, moved smoothly between
    FourteenPositions,  // the six faces and the eight corners of the sensor's box up in turn,
                        // faces and corners alternating, each held, moved smoothly between
    Tumble,             // turning about a horizontal axis and about the body's x axis at once
};

std::string_view toString(Script s);

struct ScriptTiming {
    double holdS = 3.0;     // positions: time still in each position
    double moveS = 1.5;     // positions: time to turn from one position to the next
    double tumbleS = 60.0;  // tumble: its length
};

// The sensor frame is the segment frame (mounting identity, no lever arm): evaluate() gives the
// same state for every segment. Time 0 is the script's start; before it and after its end the
// first and last orientation are held.
class ScriptedMotion final : public SegmentTrajectory {
public:
    ScriptedMotion(Script script, const ScriptTiming& timing);

    void evaluate(board::Segment s, std::int64_t tNs, SegmentState& out) const override;
    std::int64_t durationNs() const { return durationNs_; }

    // The orientation sensor -> world of the six positions, in order.
    static Quatd position(int k);
    // The fourteen positions: the sensor-frame direction that points up in each, in order, and
    // the orientation sensor -> world that turns it up.
    static constexpr int kFourteen = 14;
    static Vec3d fourteenUp(int k);
    static Quatd fourteenPosition(int k);
    // The number of held positions of a script (0 for rest and tumble) and the orientation of
    // position k.
    static int positionCount(Script script);
    static Quatd positionOf(Script script, int k);

private:
    Script script_;
    ScriptTiming timing_;
    std::int64_t durationNs_ = 0;
};

}  // namespace caphub::board::sim
