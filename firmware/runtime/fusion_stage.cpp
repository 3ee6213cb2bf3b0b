#include "firmware/runtime/fusion_stage.h"

namespace caphub::firmware {

FusionStage::FusionStage(const board::Board& board, RecordSink* records, Calibrations calibrations)
    : latest_(board.sensors.size()),
      valid_(board.sensors.size(), false),
      resetPending_(board.sensors.size(), false),
      resets_(board.sensors.size(), 0),
      calibrations_(std::move(calibrations)),
      records_(records) {
    calibrations_.resize(board.sensors.size());
    for (const auto& s : board.sensors) {
        fusion::FilterParams p;
        p.gyrRateHz = s.achievedOdrHz;
        p.accRateHz = s.achievedOdrHz;
        p.magRateHz = s.magOdrHz > 0 ? s.magOdrHz : s.achievedOdrHz;
        filters_.push_back(std::make_unique<Filter>(p));
    }
}

void FusionStage::onSample(const SensorSample& s) {
    if (s.sensor < 0 || static_cast<std::size_t>(s.sensor) >= filters_.size()) {
        return;
    }
    Filter& f = *filters_[static_cast<std::size_t>(s.sensor)];
    const auto& in = s.sample;
    fusion::ImuSample raw;
    raw.gyrRadS = in.gyrRadps.cast<double>();
    raw.accMps2 = in.accMps2.cast<double>();
    raw.magUt = in.magUt.cast<double>();
    const auto& cal = calibrations_[static_cast<std::size_t>(s.sensor)];
    const fusion::ImuSample c = cal ? cal->apply(raw) : raw;
    const bool clipped = (in.flags & hal::ImuSample::kGyrSaturated) != 0;  // set by the driver
    const std::uint32_t rejectedBefore = f.rejections().samples();
    f.updateGyr({static_cast<float>(c.gyrRadS.x()), static_cast<float>(c.gyrRadS.y()),
                 static_cast<float>(c.gyrRadS.z())},
                clipped);
    f.updateAcc({static_cast<float>(c.accMps2.x()), static_cast<float>(c.accMps2.y()),
                 static_cast<float>(c.accMps2.z())},
                bodyAccEnu_);
    if ((in.flags & hal::ImuSample::kMagFresh) != 0 &&
        (in.flags & hal::ImuSample::kMagOverflow) == 0) {
        f.updateMag({static_cast<float>(c.magUt.x()), static_cast<float>(c.magUt.y()),
                     static_cast<float>(c.magUt.z())});
    }
    if (f.rejections().samples() != rejectedBefore) {
        // A glitched read (not finite, beyond the chip's range): the filter dropped it; the body
        // must not see its rate or specific force either. The sensor keeps its last orientation.
        return;
    }
    const auto q = f.quat();
    Eigen::Quaternionf out(q.w, q.x, q.y, q.z);
    out.normalize();
    if (override_) {
        out = override_(s, out);
    }
    Latest& now = latest_[static_cast<std::size_t>(s.sensor)];
    now.orientation = out;
    now.specificForceMps2 = c.accMps2.cast<float>();
    now.rateRadS = c.gyrRadS.cast<float>();
    valid_[static_cast<std::size_t>(s.sensor)] = true;
    resetPending_[static_cast<std::size_t>(s.sensor)] = false;
    ++updates_;
    if (records_ != nullptr) {
        records_->orientation(s.sensor, in.t, out);
    }
}

void FusionStage::onEvent(const RuntimeEvent& e) {
    if (e.sensor < 0 || static_cast<std::size_t>(e.sensor) >= filters_.size()) {
        return;
    }
    const auto i = static_cast<std::size_t>(e.sensor);
    switch (e.kind) {
        case RuntimeEvent::Kind::SensorLost:
        case RuntimeEvent::Kind::LineSilent:
        case RuntimeEvent::Kind::SensorReset: {
            // The sensor is out (or its chip lost its settings): it has no orientation until it
            // is back, and its filter starts again from its first sample then, as at power-on.
            // The gyroscope's bias estimate is the chip's, not the motion's: it is kept.
            if (!valid_[i] && resetPending_[i]) {
                return;  // already out
            }
            valid_[i] = false;
            Filter& f = *filters_[i];
            fusion::FilterState<fusion::FloatTypes> state;
            state.bias = f.bias();
            state.clipEvents = f.clipEvents();
            f.setState(state);
            resetPending_[i] = true;
            ++resets_[i];
            return;
        }
        case RuntimeEvent::Kind::SensorOnline:
            return;
    }
}

std::uint32_t FusionStage::resets(int sensor) const {
    if (sensor < 0 || static_cast<std::size_t>(sensor) >= resets_.size()) {
        return 0;
    }
    return resets_[static_cast<std::size_t>(sensor)];
}

void FusionStage::setBodyAcceleration(const Eigen::Vector3d& enuMps2) {
    bodyAccEnu_ = {static_cast<float>(enuMps2.x()), static_cast<float>(enuMps2.y()),
                   static_cast<float>(enuMps2.z())};
}

std::uint32_t FusionStage::clipEvents(int sensor) const {
    if (sensor < 0 || static_cast<std::size_t>(sensor) >= filters_.size()) {
        return 0;
    }
    return filters_[static_cast<std::size_t>(sensor)]->clipEvents();
}

fusion::FilterRejections FusionStage::rejections(int sensor) const {
    if (sensor < 0 || static_cast<std::size_t>(sensor) >= filters_.size()) {
        return {};
    }
    return filters_[static_cast<std::size_t>(sensor)]->rejections();
}

const FusionStage::Latest* FusionStage::latest(int sensor) const {
    if (sensor < 0 || static_cast<std::size_t>(sensor) >= filters_.size() ||
        !valid_[static_cast<std::size_t>(sensor)]) {
        return nullptr;
    }
    return &latest_[static_cast<std::size_t>(sensor)];
}

}  // namespace caphub::firmware
