#include "fusion/calibration/still_intervals.h"

#include <algorithm>
#include <cmath>

#include "hal/core/angles.h"

namespace caphub::fusion {

namespace {

using hal::kRadToDeg;

Vec3d meanOf(std::span<const Vec3d> v) {
    Vec3d mean = Vec3d::Zero();
    for (const auto& x : v) {
        mean += x;
    }
    return mean / static_cast<double>(v.size());
}

// The largest per-axis standard deviation of a window around its mean.
double maxStd(std::span<const Vec3d> v, const Vec3d& mean) {
    Vec3d var = Vec3d::Zero();
    for (const auto& x : v) {
        var += (x - mean).cwiseAbs2();
    }
    return std::sqrt(var.maxCoeff() / static_cast<double>(v.size()));
}

// The samples in one window.
std::size_t windowSamples(const StillPositionParams& p, double rateHz) {
    return static_cast<std::size_t>(std::max(2.0, std::round(p.windowS * rateHz)));
}

StillInterval interval(std::span<const Vec3d> acc, std::span<const Vec3d> gyr, std::size_t begin,
                       std::size_t end) {
    StillInterval s;
    s.begin = begin;
    s.end = end;
    s.meanAccMps2 = meanOf(acc.subspan(begin, end - begin));
    s.meanGyrRadS = meanOf(gyr.subspan(begin, end - begin));
    return s;
}

}  // namespace

Result<std::vector<StillInterval>> findStillIntervals(std::span<const Vec3d> acc,
                                                      std::span<const Vec3d> gyr, double rateHz,
                                                      const StillPositionParams& p) {
    if (acc.size() != gyr.size() || !(rateHz > 0)) {
        return Error{EINVAL, "still positions: the accelerometer and gyroscope streams differ"};
    }
    const std::size_t n = windowSamples(p, rateHz);
    std::vector<StillInterval> out;
    bool open = false;
    for (std::size_t start = 0; start + n <= acc.size(); start += n) {
        const auto a = acc.subspan(start, n);
        const auto g = gyr.subspan(start, n);
        const bool still = maxStd(a, meanOf(a)) <= p.maxAccStdMps2 &&
                           maxStd(g, meanOf(g)) * kRadToDeg <= p.maxGyroStdDps;
        if (!still) {
            open = false;
            continue;
        }
        if (open) {
            out.back().end = start + n;
        } else {
            out.push_back(StillInterval{start, start + n});
            open = true;
        }
    }
    for (auto& s : out) {
        s = interval(acc, gyr, s.begin, s.end);
    }
    return out;
}

Result<std::vector<StillInterval>> findHeldPositions(std::span<const Vec3d> acc,
                                                     std::span<const Vec3d> gyr, double rateHz,
                                                     const StillPositionParams& p) {
    auto runs = findStillIntervals(acc, gyr, rateHz, p);
    if (!runs) {
        return runs.error();
    }
    const std::size_t n = windowSamples(p, rateHz);
    const auto needed = static_cast<std::size_t>(std::ceil(p.minStillS * rateHz));
    std::vector<StillInterval> out;
    for (const auto& r : *runs) {
        if (r.size() < needed) {
            continue;
        }
        out.push_back(r.size() >= 4 * n ? interval(acc, gyr, r.begin + n, r.end - n) : r);
    }
    return out;
}

}  // namespace caphub::fusion
