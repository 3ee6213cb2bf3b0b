// The capture heading from the knees' hinge axes. A body calibration takes the subject's
// heading (the capture world's +Z, docs/body-calibration.md) as the circular mean of the
// sensors' forward axes through their nominal mountings: off by the mean of the straps' turns
// about the vertical, 1-2 deg on the virtual suit. Every segment's orientation in the capture
// world is then its true one turned by that angle in the frame of the turn (a conjugation), the
// legs swing in planes turned by it, and the root's path turns with them: on the shared walking
// clips the whole of the drift is such a turn (0.2-1.8 deg, docs/skeleton.md). The knee is close
// to a hinge: the shank turns against the thigh about the knee's axis, the segment's left axis
// (x), whatever the hip and the pelvis do. Measured in the shank's segment frame through its
// mounting, that axis comes out turned about the segment's long axis (vertical in the T-pose) by
// the capture heading's error.
#pragma once

#include <array>
#include <cstdint>
#include <optional>

#include "fusion/body/kinematics.h"
#include "hal/core/angles.h"

namespace caphub::body {

// What a body tracker does with it: nothing, an estimate to report, or also the correction once
// the estimate is known (mid-capture).
enum class KneeHeadingMode : std::uint8_t { Off, Estimate, Live };

struct KneeHeadingOptions {
    // A sample counts while the knee turns faster than this (rad/s): standing, the relative rate
    // is the sensors' noise and bias.
    double minRateRadS = 1.0;
    // Samples of each knee before an answer: about a second of walking's knee motion at 100 Hz.
    int minSamples = 100;
    // The turn must be about one axis: the largest eigenvalue of the rates' moments at least
    // this share of their sum (a hinge; walking's knees give 0.99).
    double minPlanarity = 0.95;
    // The two knees must agree within this (rad); otherwise a strap of its own, not the capture
    // heading, turns one of them.
    double maxDisagreementRad = 4.0 * hal::kDegToRad;
    // A heading error beyond this (rad) is not a strap's mean: no answer.
    double maxErrorRad = 10.0 * hal::kDegToRad;
};

class KneeHeading {
public:
    explicit KneeHeading(const KneeHeadingOptions& options = {}) : options_(options) {}

    void reset();
    // One sample of a knee (0 left, 1 right): the shank's rate relative to the thigh's, in the
    // shank's segment frame (rad/s).
    void add(int knee, const Vec3d& relativeRateSegment);
    // The capture heading's error (rad, about up: the heading to add), once both knees have
    // turned enough about one axis each and agree; none before.
    std::optional<double> headingErrorRad() const;
    // Each knee's answer so far (rad), for reports; none while it has too few samples or no
    // single axis.
    std::optional<double> kneeErrorRad(int knee) const;

private:
    KneeHeadingOptions options_;
    std::array<Eigen::Matrix3d, 2> moments_{Eigen::Matrix3d::Zero(), Eigen::Matrix3d::Zero()};
    std::array<int, 2> samples_{};
};

}  // namespace caphub::body
