// Whether a magnetometer read raw may be taken as it is, from the first readings of the whole
// suit. One reading of one sensor cannot tell: a chip's zero-field offset or a magnetised strap
// adds a vector of up to a few hundred uT, and the sum is of the earth's size (22-67 uT) often
// enough by chance (2-4 of 17 sensors on the virtual suit's typical profile), with a heading tens
// of degrees off that changes as the sensor turns. Every sensor of a suit is in one place and
// reads one earth field, though: the same magnitude, and the same angle to the vertical (the dip).
// An offset of any size moves both unless it is nearly across the field, so sensors whose first
// readings agree with each other's are right or nearly so, and one that disagrees is not. The
// vote takes the medians of the first readings (those in the first windowS, or of every sensor
// expected, whichever comes first) as the suit's field; where at least half the sensors are
// within the tolerances of both, each of those is trusted; otherwise none is (the medians are
// no field). A sensor whose first reading comes later is held to the medians found. What it
// cannot see: an offset across the field and horizontal turns the heading at first order and the
// magnitude and dip only at second (a 5 uT one turns a 20 uT horizontal field by 14 deg and
// moves them by 0.5 % and 1.6 deg), so a raw heading it trusts is still checked against the
// strap at a body calibration and by the online estimate once the sensor has turned.
// docs/fusion.md, "No magnetometer calibration".
#pragma once

#include <cstddef>
#include <optional>
#include <vector>

namespace caphub::fusion {

struct FieldVoteOptions {
    double windowS = 0.5;  // s after the first reading of any sensor, then the vote is counted
    // The earth's field anywhere (uT): a reading outside is an offset whatever the others read.
    double minEarthUt = 22.0;
    double maxEarthUt = 67.0;
    // Agreement with the medians: the chips' scale and soft iron (a few per cent per element)
    // and an indoor field's change over a body's size stay within these.
    double normTolerance = 0.10;      // fraction of the median magnitude
    double dipToleranceRad = 0.0873;  // 5 deg
};

class FieldVote {
public:
    // expected: the sensors that will vote (those read raw); the vote is counted once each has
    // (or at the window's end).
    FieldVote(std::size_t sensors, std::size_t expected, const FieldVoteOptions& options = {});

    // A sensor's first reading: the field's magnitude (uT) and its angle to the sensor's up (rad,
    // from the accelerometer's vertical), at tS (s). Later readings of the same sensor are
    // ignored.
    void add(std::size_t sensor, double normUt, double angleToUpRad, double tS);
    // Counts the vote once the window has passed at tS (s), or every expected sensor is in.
    void close(double tS);
    bool counted() const { return counted_; }
    // Whether the sensor's raw reading is trusted: none before the vote is counted or before
    // the sensor's first reading.
    std::optional<bool> trusted(std::size_t sensor) const;
    // The suit's field as counted (medians), when at least half agreed.
    std::optional<double> fieldUt() const {
        return agreed_ ? std::optional(medianNorm_) : std::nullopt;
    }
    std::optional<double> angleToUpRad() const {
        return agreed_ ? std::optional(medianAngle_) : std::nullopt;
    }

private:
    struct Reading {
        bool seen = false;
        double normUt = 0;
        double angleRad = 0;
    };
    // Of the earth's size and within the tolerances of the medians.
    bool withinMedians(const Reading& r) const;
    void count();

    FieldVoteOptions options_;
    std::vector<Reading> readings_;
    std::size_t expected_;
    std::size_t seen_ = 0;
    std::optional<double> firstS_;
    bool counted_ = false;
    bool agreed_ = false;
    double medianNorm_ = 0;
    double medianAngle_ = 0;
};

}  // namespace caphub::fusion
