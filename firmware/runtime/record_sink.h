// Where the stages put what they compute for the recording (orientations, poses, calibration
// events and metadata): the recorder, the only writer of records, which sends them to the take
// being recorded, or nowhere between takes. Called on the pipeline thread.
#pragma once

#include <cstdint>
#include <span>
#include <string_view>

#include <Eigen/Geometry>

#include "firmware/recording/format.h"
#include "hal/core/time.h"

namespace caphub::firmware {

class RecordSink {
public:
    virtual ~RecordSink() = default;
    virtual void orientation(int sensor, Timestamp t, const Eigen::Quaternionf& q) = 0;
    // notMeasured: bit j set when joint j's segment has a sensor that gave no reading for this
    // pose (lost, silent, resetting): its rotation is held, not measured.
    virtual void pose(Timestamp t, const Eigen::Vector3f& rootM,
                      std::span<const Eigen::Quaternionf> jointRotations,
                      std::uint32_t notMeasured) = 0;
    virtual void event(Timestamp t, cap::EventKind kind, int sensor, int error,
                       std::string_view text) = 0;
    virtual void metadata(Timestamp t, std::string_view toml) = 0;
    virtual void marker(Timestamp t, std::string_view label) = 0;
};

}  // namespace caphub::firmware
