#include "fusion/calibration/field_vote.h"

#include <algorithm>
#include <cmath>

namespace caphub::fusion {

namespace {

double median(std::vector<double> v) {
    const std::size_t mid = v.size() / 2;
    std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(mid), v.end());
    const double upper = v[mid];
    if (v.size() % 2 == 1) {
        return upper;
    }
    return 0.5 *
           (upper + *std::max_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(mid)));
}

}  // namespace

FieldVote::FieldVote(std::size_t sensors, std::size_t expected, const FieldVoteOptions& options)
    : options_(options), readings_(sensors), expected_(expected) {}

void FieldVote::add(std::size_t sensor, double normUt, double angleToUpRad, double tS) {
    if (sensor >= readings_.size() || readings_[sensor].seen || !std::isfinite(normUt) ||
        !std::isfinite(angleToUpRad) || !std::isfinite(tS)) {
        return;
    }
    readings_[sensor] = {true, normUt, angleToUpRad};
    ++seen_;
    if (!firstS_) {
        firstS_ = tS;
    }
    close(tS);
}

void FieldVote::close(double tS) {
    if (counted_ || !firstS_) {
        return;
    }
    if (seen_ >= expected_ || tS - *firstS_ >= options_.windowS) {
        count();
    }
}

void FieldVote::count() {
    counted_ = true;
    std::vector<double> norms;
    std::vector<double> angles;
    for (const Reading& r : readings_) {
        if (r.seen) {
            norms.push_back(r.normUt);
            angles.push_back(r.angleRad);
        }
    }
    if (norms.empty()) {
        return;
    }
    medianNorm_ = median(norms);
    medianAngle_ = median(angles);
    std::size_t agreeing = 0;
    for (const Reading& r : readings_) {
        agreeing += r.seen && withinMedians(r) ? 1 : 0;
    }
    agreed_ = 2 * agreeing >= norms.size();
}

bool FieldVote::withinMedians(const Reading& r) const {
    return r.normUt >= options_.minEarthUt && r.normUt <= options_.maxEarthUt &&
           std::abs(r.normUt - medianNorm_) <= options_.normTolerance * medianNorm_ &&
           std::abs(r.angleRad - medianAngle_) <= options_.dipToleranceRad;
}

std::optional<bool> FieldVote::trusted(std::size_t sensor) const {
    if (!counted_ || sensor >= readings_.size() || !readings_[sensor].seen) {
        return std::nullopt;
    }
    return agreed_ && withinMedians(readings_[sensor]);
}

}  // namespace caphub::fusion
