#include "firmware/runtime/fusion_stage.h"

namespace caphub::firmware {

FusionStage::FusionStage(const board::Board& board, RecordingWriter* writer,
                         Calibrations calibrations)
    : latest_(board.sensors.size()),
      valid_(board.sensors.size(), false),
      calibrations_(std::move(calibrations)),
      writer_(writer) {
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
    const auto q = f.quat();
    Eigen::Quaternionf out(q.w, q.x, q.y, q.z);
    out.normalize();
    Latest& now = latest_[static_cast<std::size_t>(s.sensor)];
    now.orientation = out;
    now.specificForceMps2 = c.accMps2.cast<float>();
    now.rateRadS = c.gyrRadS.cast<float>();
    valid_[static_cast<std::size_t>(s.sensor)] = true;
    ++updates_;
    if (writer_ != nullptr && writer_->error() == 0) {
        (void)writer_->writeOrientation(s.sensor, in.t, out);
    }
}

void FusionStage::onEvent(const RuntimeEvent& e) {
    // A sensor that was lost restarts from its reset state: its filter state is stale.
    if (e.kind == RuntimeEvent::Kind::SensorLost && e.sensor >= 0 &&
        static_cast<std::size_t>(e.sensor) < filters_.size()) {
        valid_[static_cast<std::size_t>(e.sensor)] = false;
    }
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
