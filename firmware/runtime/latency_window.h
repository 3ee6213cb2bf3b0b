// The latencies of the most recent events in a fixed ring (allocated once: adding one costs a
// store), and their percentiles. For the capture's, the body's and the live status's figures.
#pragma once

#include <algorithm>
#include <cstdint>
#include <vector>

#include "hal/core/time.h"

namespace caphub::firmware {

class LatencyWindow {
public:
    explicit LatencyWindow(std::size_t capacity) : ns_(std::max<std::size_t>(capacity, 1)) {}

    void add(Duration d) { ns_[count_++ % ns_.size()] = toNs(d); }

    // How many are in the window (at most its capacity).
    std::size_t size() const { return std::min(count_, ns_.size()); }

    // The value of rank floor(p (n - 1)) among the n in the window, p in [0, 1]; zero when
    // empty. Sorts a copy: for reports, not for every sample.
    Duration percentile(double p) const {
        const std::size_t n = size();
        if (n == 0) {
            return Duration{0};
        }
        std::vector<std::int64_t> v(ns_.begin(), ns_.begin() + static_cast<std::ptrdiff_t>(n));
        const auto k =
            static_cast<std::ptrdiff_t>(std::clamp(p, 0.0, 1.0) * static_cast<double>(n - 1));
        std::nth_element(v.begin(), v.begin() + k, v.end());
        return Duration{v[static_cast<std::size_t>(k)]};
    }

    Duration max() const {
        const std::size_t n = size();
        return n == 0 ? Duration{0}
                      : Duration{*std::max_element(ns_.begin(),
                                                   ns_.begin() + static_cast<std::ptrdiff_t>(n))};
    }

private:
    std::vector<std::int64_t> ns_;
    std::size_t count_ = 0;
};

}  // namespace caphub::firmware
