#include "fusion/evaluation.h"

#include <algorithm>
#include <cmath>

#include "hal/core/angles.h"

namespace caphub::fusion {

namespace {

template <typename S>
std::vector<Quatd> runTyped(const std::vector<ImuSample>& samples, int decimation,
                            const FilterParams& params, FilterRejections* rejections) {
    OrientationFilter<S> filter(params);
    std::vector<Quatd> out;
    out.reserve(samples.size());
    Quatd held = Quatd::Identity();
    for (std::size_t i = 0; i < samples.size(); ++i) {
        if (i % static_cast<std::size_t>(decimation) == 0) {
            const ImuSample& s = samples[i];
            using T = S;
            filter.updateGyr(
                fromDoubleVec<typename T::Gyr>(s.gyrRadS.x(), s.gyrRadS.y(), s.gyrRadS.z()));
            filter.updateAcc(
                fromDoubleVec<typename T::Acc>(s.accMps2.x(), s.accMps2.y(), s.accMps2.z()));
            filter.updateMag(fromDoubleVec<typename T::Mag>(s.magUt.x(), s.magUt.y(), s.magUt.z()));
            const auto q = filter.quat();
            held = Quatd(toDouble(q.w), toDouble(q.x), toDouble(q.y), toDouble(q.z)).normalized();
        }
        out.push_back(held);
    }
    if (rejections != nullptr) {
        *rejections = filter.rejections();
    }
    return out;
}

}  // namespace

std::vector<Quatd> runFilter(const std::vector<ImuSample>& samples, double rateHz, int decimation,
                             FilterVariant variant, FilterParams params,
                             FilterRejections* rejections) {
    decimation = std::max(1, decimation);
    const double fedHz = rateHz / decimation;
    params.gyrRateHz = fedHz;
    params.accRateHz = fedHz;
    params.magRateHz = fedHz;
    if (variant == FilterVariant::Fixed) {
        return runTyped<FixedTypes>(samples, decimation, params, rejections);
    }
    return runTyped<FloatTypes>(samples, decimation, params, rejections);
}

SampleErrors broadSampleErrors(const Quatd& est, const Quatd& opt) {
    const Quatd e = (est.normalized() * opt.normalized().conjugate()).normalized();
    const double w = std::abs(e.w());
    SampleErrors out;
    out.totalRad = 2.0 * std::acos(std::clamp(w, 0.0, 1.0));
    out.headingRad = 2.0 * std::atan2(std::abs(e.z()), w);
    out.inclinationRad =
        2.0 * std::acos(std::clamp(std::sqrt(e.w() * e.w() + e.z() * e.z()), 0.0, 1.0));
    return out;
}

BroadErrors broadMetric(const std::vector<Quatd>& estimate, const std::vector<Quatd>& truth,
                        const std::vector<bool>& movement) {
    using hal::kRadToDeg;
    double sumT = 0.0;
    double sumH = 0.0;
    double sumI = 0.0;
    std::size_t n = 0;
    const std::size_t count = std::min({estimate.size(), truth.size(), movement.size()});
    for (std::size_t i = 0; i < count; ++i) {
        const Quatd& o = truth[i];
        if (!movement[i] || !std::isfinite(o.w()) || !std::isfinite(o.x()) ||
            !std::isfinite(o.y()) || !std::isfinite(o.z())) {
            continue;
        }
        const SampleErrors e = broadSampleErrors(estimate[i], o);
        sumT += e.totalRad * e.totalRad;
        sumH += e.headingRad * e.headingRad;
        sumI += e.inclinationRad * e.inclinationRad;
        ++n;
    }
    BroadErrors r;
    r.samples = n;
    if (n > 0) {
        r.totalDeg = std::sqrt(sumT / static_cast<double>(n)) * kRadToDeg;
        r.headingDeg = std::sqrt(sumH / static_cast<double>(n)) * kRadToDeg;
        r.inclinationDeg = std::sqrt(sumI / static_cast<double>(n)) * kRadToDeg;
    }
    return r;
}

}  // namespace caphub::fusion
