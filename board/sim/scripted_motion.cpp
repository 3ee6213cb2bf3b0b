#include "board/sim/scripted_motion.h"

#include <algorithm>
#include <cmath>

#include "hal/core/angles.h"

namespace caphub::board::sim {

namespace {

using hal::kDegToRad;
using hal::kPi;

// The tumble: about a fixed horizontal axis at this rate and about the body's x axis at a rate
// whose ratio to it is irrational, so that the field sweeps every direction of the sensor frame.
constexpr double kTumbleYawRadS = 45.0 * kDegToRad;
constexpr double kTumbleRollRadS = 45.0 * kDegToRad / 2.6180339887498949;  // / golden ratio^2

// Where the sensor lies: a table top 1 m above the world origin.
const Vec3d kTablePositionM(0.0, 1.0, 0.0);

Quatd about(const Vec3d& axis, double angleRad) {
    return Quatd(Eigen::AngleAxisd(angleRad, axis));
}

}  // namespace

std::string_view toString(Script s) {
    switch (s) {
        case Script::Rest:
            return "rest";
        case Script::SixPositions:
            return "six positions";
        case Script::FourteenPositions:
            return "fourteen positions";
        case Script::Tumble:
            return "tumble";
    }
    return "?";
}

Quatd ScriptedMotion::position(int k) {
    // The world is Y up: each orientation turns one sensor axis onto +Y.
    switch (k) {
        case 0:  // +z up
            return about(Vec3d::UnitX(), -kPi / 2);
        case 1:  // -z up
            return about(Vec3d::UnitX(), kPi / 2);
        case 2:  // +x up
            return about(Vec3d::UnitZ(), kPi / 2);
        case 3:  // -x up
            return about(Vec3d::UnitZ(), -kPi / 2);
        case 4:  // +y up
            return Quatd::Identity();
        default:  // -y up
            return about(Vec3d::UnitX(), kPi);
    }
}

Vec3d ScriptedMotion::fourteenUp(int k) {
    // Faces and corners alternate, so that the turns between them run about axes spread over
    // the sensor frame (a gyroscope calibration needs turns about every axis).
    static constexpr int kUp[kFourteen][3] = {
        {0, 0, 1},   {1, 1, 1},  {1, 0, 0},  {1, -1, -1}, {0, 0, -1}, {-1, 1, -1}, {0, 1, 0},
        {-1, -1, 1}, {-1, 0, 0}, {1, 1, -1}, {0, -1, 0},  {1, -1, 1}, {-1, 1, 1},  {-1, -1, -1}};
    const int i = std::clamp(k, 0, kFourteen - 1);
    return Vec3d(kUp[i][0], kUp[i][1], kUp[i][2]).normalized();
}

Quatd ScriptedMotion::fourteenPosition(int k) {
    // The world is Y up. A face pointing down has no unique shortest turn; about the world X
    // axis then.
    const Vec3d up = fourteenUp(k);
    if (up.dot(Vec3d::UnitY()) < -0.999) {
        return about(Vec3d::UnitX(), kPi);
    }
    return Quatd::FromTwoVectors(up, Vec3d::UnitY());
}

int ScriptedMotion::positionCount(Script script) {
    switch (script) {
        case Script::SixPositions:
            return 6;
        case Script::FourteenPositions:
            return kFourteen;
        case Script::Rest:
        case Script::Tumble:
            break;
    }
    return 0;
}

Quatd ScriptedMotion::positionOf(Script script, int k) {
    return script == Script::FourteenPositions ? fourteenPosition(k) : position(k);
}

ScriptedMotion::ScriptedMotion(Script script, const ScriptTiming& timing)
    : script_(script), timing_(timing) {
    double seconds = 0;
    switch (script) {
        case Script::Rest:
            seconds = 0;
            break;
        case Script::SixPositions:
        case Script::FourteenPositions: {
            const int n = positionCount(script);
            seconds = n * timing.holdS + (n - 1) * timing.moveS;
            break;
        }
        case Script::Tumble:
            seconds = timing.tumbleS;
            break;
    }
    durationNs_ = static_cast<std::int64_t>(std::llround(seconds * 1e9));
}

void ScriptedMotion::evaluate(board::Segment, std::int64_t tNs, SegmentState& out) const {
    out = SegmentState{};
    out.positionM = kTablePositionM;
    const double t = static_cast<double>(std::clamp<std::int64_t>(tNs, 0, durationNs_)) * 1e-9;
    switch (script_) {
        case Script::Rest:
            out.qWorldSegment = position(0);
            return;
        case Script::SixPositions:
        case Script::FourteenPositions: {
            // Hold k over [k (hold + move), k (hold + move) + hold), then move to k + 1.
            const int last = positionCount(script_) - 1;
            const double cycle = timing_.holdS + timing_.moveS;
            const int k = std::min(last, static_cast<int>(t / cycle));
            const double inCycle = t - k * cycle;
            const Quatd from = positionOf(script_, k);
            if (k == last || inCycle <= timing_.holdS) {
                out.qWorldSegment = from;
                return;
            }
            // A quintic smooth step u(tau) along the shortest turn to the next position: rate
            // and angular acceleration are continuous and zero at both ends.
            const double tau = (inCycle - timing_.holdS) / timing_.moveS;
            const double u = tau * tau * tau * (10 - 15 * tau + 6 * tau * tau);
            const double du = 30 * tau * tau * (1 - tau) * (1 - tau) / timing_.moveS;
            const double ddu =
                60 * tau * (1 - tau) * (1 - 2 * tau) / (timing_.moveS * timing_.moveS);
            const Eigen::AngleAxisd turn(from.conjugate() * positionOf(script_, k + 1));
            const Vec3d v = turn.axis() * turn.angle();  // body frame
            out.qWorldSegment = (from * about(turn.axis(), u * turn.angle())).normalized();
            out.omegaRadS = du * v;
            out.alphaRadS2 = ddu * v;
            return;
        }
        case Script::Tumble: {
            // q = P0 A(t) B(t): A about P0's y axis (horizontal), B about the body's x axis.
            // Body rate B^-1 (wA y) + wB x; its derivative (B^-1 wA y) x (wB x). The turning
            // starts and stops at once (a step in rate), as a hand starting to turn a sensor.
            const bool moving = tNs > 0 && tNs < durationNs_;
            const Quatd a = about(Vec3d::UnitY(), kTumbleYawRadS * t);
            const Quatd b = about(Vec3d::UnitX(), kTumbleRollRadS * t);
            out.qWorldSegment = (position(0) * a * b).normalized();
            if (moving) {
                const Vec3d yawInBody = b.conjugate() * (kTumbleYawRadS * Vec3d::UnitY());
                const Vec3d roll = kTumbleRollRadS * Vec3d::UnitX();
                out.omegaRadS = yawInBody + roll;
                out.alphaRadS2 = yawInBody.cross(roll);
            }
            return;
        }
    }
}

}  // namespace caphub::board::sim
