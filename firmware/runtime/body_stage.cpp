#include "firmware/runtime/body_stage.h"

#include <algorithm>
#include <bit>
#include <cmath>

#include <fmt/format.h>

#include "firmware/runtime/recorder_stage.h"
#include "hal/core/log.h"

namespace caphub::firmware {

namespace {

body::Skeleton skeletonFor(const board::Board& board) {
    auto d = body::dimensionsFromSubject(board.subject);
    // The loader has checked the subject; the defaults stand in should it ever not be.
    return body::Skeleton(d ? *d : *body::dimensionsFromSubject(board::SubjectConfig{}));
}

body::SegmentMask maskOf(const board::Board& board) {
    body::SegmentMask m = 0;
    for (const auto& s : board.sensors) {
        m |= body::bit(s.segment);
    }
    return m;
}

}  // namespace

BodyStage::BodyStage(const board::Board& board, FusionStage& fusion, RecordSink* records,
                     Clock& clock, const Options& options)
    : board_(board),
      fusion_(fusion),
      records_(records),
      clock_(clock),
      options_(options),
      period_(periodFromHz(options.rateHz)),
      solver_(options.dimensions ? body::Skeleton(*options.dimensions) : skeletonFor(board),
              maskOf(board)),
      mask_(maskOf(board)),
      sensorOfSegment_(body::kSegmentCount, -1),
      held_(board.sensors.size()),
      sum_(board.sensors.size(), Eigen::Vector4d::Zero()),
      count_(board.sensors.size(), 0) {
    nominal_.fill(Quatd::Identity());
    for (std::size_t i = 0; i < board.sensors.size(); ++i) {
        const auto seg = static_cast<std::size_t>(board.sensors[i].segment);
        sensorOfSegment_[seg] = static_cast<int>(i);
        nominal_[seg] = board.sensors[i].mounting;
    }
    auto sensorOf = [this](body::Segment s) {
        return sensorOfSegment_[static_cast<std::size_t>(body::idx(s))];
    };
    pelvisSensor_ = sensorOf(body::Segment::Pelvis);
    footSensor_ = {sensorOf(body::Segment::LHindfoot), sensorOf(body::Segment::RHindfoot)};
    footInertial_ = {body::FootInertial(options_.footInertialOptions),
                     body::FootInertial(options_.footInertialOptions)};
    if (!options_.calibrate) {
        // No calibration pose: the nominal mountings, the subject facing north.
        calibration_.mask = mask_;
        calibration_.mounting = nominal_;
        solver_.setCalibration(calibration_);
        calibrated_ = true;
    }
}

void BodyStage::onSample(const SensorSample& s) {
    const Timestamp t = s.sample.t;
    if (!first_) {
        first_ = t;
        nextFrame_ = t;
    }
    const FusionStage::Latest* now = fusion_.latest(s.sensor);
    if (now != nullptr) {
        auto& h = held_[static_cast<std::size_t>(s.sensor)];
        if (h.count > 0 && t > h.latestT) {
            h.previous = h.latest;
            h.previousT = h.latestT;
            h.count = 2;
        } else if (h.count == 0) {
            h.count = 1;
        }
        h.latest = now->orientation;
        h.latestT = t;
        h.rateRadS = now->rateRadS;
    }
    if (!calibrated_ && options_.calibrate && calibrationError_.empty()) {
        const Timestamp from = *first_ + options_.settle;
        if (t >= from + options_.average) {
            calibrate(t);
        } else if (t >= from) {
            const auto i = static_cast<std::size_t>(s.sensor);
            if (now != nullptr) {
                const Eigen::Quaternionf& q = now->orientation;
                Eigen::Vector4d v(q.w(), q.x(), q.y(), q.z());
                // q and -q are one rotation: add each on the side of the running sum.
                if (v.dot(sum_[i]) < 0) {
                    v = -v;
                }
                sum_[i] += v;
                ++count_[i];
            }
        }
        return;
    }
    if (!calibrated_) {
        return;
    }
    if (options_.footInertial && now != nullptr) {
        const auto& h = held_[static_cast<std::size_t>(s.sensor)];
        for (std::size_t k = 0; k < 2; ++k) {
            if (s.sensor == footSensor_[k] && h.count == 2) {
                footInertial_[k].add(
                    now->orientation.cast<double>(), now->specificForceMps2.cast<double>(),
                    now->rateRadS.cast<double>(), toSeconds(h.latestT - h.previousT));
            }
        }
    }
    if (s.sensor == pelvisSensor_ && now != nullptr) {
        pelvisForceSumEnu_ +=
            now->orientation.cast<double>() * now->specificForceMps2.cast<double>();
        ++pelvisForceCount_;
    }
    // Poses on a fixed grid of the output rate: every grid point the newest sample has passed
    // gets its pose (samples of several buses arrive interleaved, so the newest time can jump by
    // more than a period). After a long gap (every sensor silent) the grid restarts at t.
    if (t - nextFrame_ > period_ * 10) {
        nextFrame_ = t;
    }
    while (t >= nextFrame_) {
        solveFrame(nextFrame_, t);
        nextFrame_ += period_;
    }
}

void BodyStage::onEvent(const RuntimeEvent& e) {
    // A sensor out (lost, silent, resetting): its filter restarts, its held orientations are
    // stale.
    if (e.kind != RuntimeEvent::Kind::SensorOnline && e.sensor >= 0 &&
        static_cast<std::size_t>(e.sensor) < held_.size()) {
        held_[static_cast<std::size_t>(e.sensor)].count = 0;
        for (std::size_t k = 0; k < 2; ++k) {
            if (footSensor_[k] == e.sensor) {
                footInertial_[k].reset();
            }
        }
    }
}

void BodyStage::calibrate(Timestamp t) {
    body::SensorFrame frame;
    for (std::size_t i = 0; i < board_.sensors.size(); ++i) {
        if (count_[i] == 0) {
            continue;  // no orientation: the segment stays uncalibrated
        }
        const Eigen::Vector4d m = sum_[i].normalized();
        const auto seg = static_cast<std::size_t>(board_.sensors[i].segment);
        frame.qEnuSensor[seg] = Quatd(m[0], m[1], m[2], m[3]);
        frame.mask |= body::bit(board_.sensors[i].segment);
    }
    body::CalibrationOptions copt;
    copt.nominalMounting = nominal_;
    auto cal = body::calibrateOnePose(*options_.calibrate, frame, copt, toNs(t));
    if (!cal) {
        calibrationError_ = cal.error().message;
        log::logger(log::Category::Body).error("body calibration failed: {}", calibrationError_);
        return;
    }
    calibration_ = *cal;
    solver_.setCalibration(calibration_);
    solver_.resetRoot();
    rootVelocityValid_ = false;
    calibrated_ = true;
    nextFrame_ = t;
    if (records_ != nullptr) {
        const std::string text = body::toText(calibration_);
        records_->event(
            t, cap::EventKind::Calibrated, -1, 0,
            fmt::format("body calibration: {} pose, {} segments",
                        body::toString(calibration_.method), std::popcount(calibration_.mask)));
        records_->metadata(t, "[body_calibration]\ntext = " + tomlString(text) + "\n");
    }
}

void BodyStage::solveFrame(Timestamp t, Timestamp newestSample) {
    body::SensorFrame frame;
    for (int seg = 0; seg < body::kSegmentCount; ++seg) {
        const int i = sensorOfSegment_[static_cast<std::size_t>(seg)];
        Eigen::Quaternionf q;
        if (i >= 0 && fusion_.latest(i) != nullptr && orientationAt(i, t, q)) {
            frame.qEnuSensor[static_cast<std::size_t>(seg)] = q.cast<double>();
            frame.mask |= body::SegmentMask{1} << seg;
        }
    }
    const double dtS = poses_ == 0 ? toSeconds(period_) : toSeconds(t - lastFrame_);
    lastFrame_ = t;
    // The pelvis accelerometer over the frame, in the skeleton world frame: it tells a flight
    // phase (a jump, a running stride) from stance, and the velocity at take-off.
    std::optional<Vec3d> rootSpecificForce;
    if (pelvisForceCount_ > 0) {
        rootSpecificForce =
            calibration_.qEnuWorld().conjugate() * (pelvisForceSumEnu_ / pelvisForceCount_);
        pelvisForceSumEnu_.setZero();
        pelvisForceCount_ = 0;
    }
    // The feet's dead reckoning, in the skeleton world frame.
    body::FootSensorMotion feet;
    const Quatd qWorldEnu = calibration_.qEnuWorld().conjugate();
    for (std::size_t k = 0; k < 2; ++k) {
        const int i = footSensor_[k];
        if (options_.footInertial && i >= 0 && fusion_.latest(i) != nullptr &&
            footInertial_[k].valid()) {
            feet.valid[k] = true;
            feet.still[k] = footInertial_[k].still();
            feet.velocityMps[k] = qWorldEnu * footInertial_[k].velocityEnuMps();
            feet.rateRadS[k] = qWorldEnu * footInertial_[k].rateEnuRadS();
            feet.onFootM[k] = board_.sensors[static_cast<std::size_t>(i)].positionM;
        }
    }
    const body::Pose& pose = solver_.solve(frame, dtS, rootSpecificForce, &feet);
    ++poses_;
    if (options_.aidFilters) {
        feedBackAcceleration(dtS);
    }
    if (records_ != nullptr) {
        for (std::size_t j = 0; j < joints_.size(); ++j) {
            joints_[j] = pose.qLocal[j].cast<float>();
        }
        // Segments whose sensor gave nothing for this pose (out: lost, silent, resetting) are
        // held by the solver, and flagged as such in the record.
        records_->pose(t, pose.positionM[0].cast<float>(), joints_,
                       static_cast<std::uint32_t>(mask_ & ~frame.mask));
    }
    latency_.add(clock_.now() - newestSample);
}

bool BodyStage::orientationAt(int sensor, Timestamp t, Eigen::Quaternionf& q) const {
    const auto& h = held_[static_cast<std::size_t>(sensor)];
    if (h.count == 0) {
        return false;
    }
    if (h.count == 1) {
        q = h.latest;  // no interval yet to interpolate or carry on over
        return true;
    }
    const double span = toSeconds(h.latestT - h.previousT);  // > 0: samples are kept in order
    if (t <= h.latestT) {
        const double along = std::max(0.0, toSeconds(t - h.previousT) / span);
        q = h.previous.slerp(static_cast<float>(along), h.latest).normalized();
        return true;
    }
    // Past the latest (the sample for t has not arrived yet): on at the gyroscope's rate, as the
    // filter's next prediction would, for at most one interval; a sensor silent for longer is
    // held where it was.
    const double ahead = std::min(toSeconds(t - h.latestT), span);
    const float angle = h.rateRadS.norm() * static_cast<float>(ahead);
    q = angle > 0
            ? (h.latest * Eigen::Quaternionf(Eigen::AngleAxisf(angle, h.rateRadS.normalized())))
                  .normalized()
            : h.latest;
    return true;
}

void BodyStage::feedBackAcceleration(double dtS) {
    // The filters low-pass gravity over seconds, so a sustained horizontal acceleration (starting
    // to walk, stopping) would tilt every one of them alike; the root's velocity from the foot
    // contacts says what it is. Low-passed over 0.5 s (within each step the root's speed swings
    // and the contact changes step it; only the slow part tilts the filters), then
    // differentiated; vertical motion averages out over a gait cycle and is left to the filters.
    constexpr double kTauS = 0.5;
    constexpr double kMaxMps2 = 4.0;  // beyond what walking or running sustains: a tracking slip
    const Vec3d& v = solver_.rootTracker().rootVelocityMps();
    const Vec3d horizontal(v.x(), 0, v.z());
    if (!rootVelocityValid_ || dtS <= 0) {
        rootVelocityLp_ = horizontal;
        rootVelocityValid_ = true;
        return;
    }
    const Vec3d before = rootVelocityLp_;
    rootVelocityLp_ += (horizontal - before) * (1.0 - std::exp(-dtS / kTauS));
    Vec3d a = (rootVelocityLp_ - before) / dtS;
    if (a.norm() > kMaxMps2) {
        a *= kMaxMps2 / a.norm();
    }
    fusion_.setBodyAcceleration(calibration_.qEnuWorld() * a);
}

}  // namespace caphub::firmware
