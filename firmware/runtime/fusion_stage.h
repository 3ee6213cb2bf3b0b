// The pipeline stage that fuses: one orientation filter per sensor, fed each sample at the
// sensor's own rates (the magnetometer only when its reading is fresh) after the sensor's
// calibration, recording every sensor's orientation next to its raw samples.
#pragma once

#include <memory>
#include <optional>
#include <vector>

#include "board/board.h"
#include "firmware/recording/writer.h"
#include "firmware/runtime/capture.h"
#include "fusion/calibration/sensor_calibration.h"
#include "fusion/orientation_filter.h"

namespace caphub::firmware {

class FusionStage final : public PipelineStage {
public:
    using Filter = fusion::OrientationFilter<fusion::FloatTypes>;

    // Per board sensor, the calibration applied to its samples before its filter (none: raw).
    using Calibrations = std::vector<std::optional<fusion::SensorCalibration>>;

    // writer may be null (no recording); calibrations may be empty.
    FusionStage(const board::Board& board, RecordingWriter* writer, Calibrations calibrations = {});

    void onSample(const SensorSample& s) override;
    void onEvent(const RuntimeEvent& e) override;

    // What a sensor's latest sample gave: its orientation (sensor -> ENU) and its calibrated
    // readings (sensor frame).
    struct Latest {
        Eigen::Quaternionf orientation = Eigen::Quaternionf::Identity();
        Eigen::Vector3f specificForceMps2 = Eigen::Vector3f::Zero();
        Eigen::Vector3f rateRadS = Eigen::Vector3f::Zero();
    };
    // A sensor's latest, or null when it has none (no sample yet, or none since it was lost).
    const Latest* latest(int sensor) const;
    std::uint64_t updates() const { return updates_; }
    // Gyroscope clipping episodes of a sensor so far (samples the driver flagged saturated).
    std::uint32_t clipEvents(int sensor) const;
    // What a sensor's filter refused so far: samples not finite or beyond the chips' range, and
    // restarts from a non-finite state (docs/fusion.md, "Input validation"). Zero for no sensor.
    fusion::FilterRejections rejections(int sensor) const;
    // The body's acceleration (ENU, m/s^2) as the body solver tracks it, handed to every filter
    // as its sensor's known linear acceleration (fusion::OrientationFilter::updateAcc) until the
    // next call. Zero (the default): unknown.
    void setBodyAcceleration(const Eigen::Vector3d& enuMps2);

private:
    std::vector<std::unique_ptr<Filter>> filters_;
    std::vector<Latest> latest_;
    std::vector<bool> valid_;
    Calibrations calibrations_;
    fusion::Vec3<float> bodyAccEnu_{};
    RecordingWriter* writer_;
    std::uint64_t updates_ = 0;
};

}  // namespace caphub::firmware
