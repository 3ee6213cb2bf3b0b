#include "firmware/runtime/body_stage.h"

#include <bit>
#include <cmath>
#include <numbers>
#include <vector>

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

std::vector<body::TrackedSensor> trackedSensors(const board::Board& board) {
    std::vector<body::TrackedSensor> out;
    out.reserve(board.sensors.size());
    for (const auto& s : board.sensors) {
        out.push_back({s.segment, s.mounting, s.positionM});
    }
    return out;
}

body::BodyTrackerOptions trackerOptions(const BodyStage::Options& o) {
    body::BodyTrackerOptions t;
    t.rateHz = o.rateHz;
    t.solveUncalibrated = !o.calibrate;
    t.calibrationAverage = o.average;
    t.aidFilters = o.aidFilters;
    t.footInertial = o.footInertial;
    t.footInertialOptions = o.footInertialOptions;
    t.kneeHeading = o.kneeHeading;
    t.jointHeading = o.jointHeading;
    t.knownHeadingErrorRad = o.knownHeadingErrorRad;
    t.footStretches = o.footStretches;
    return t;
}

}  // namespace

BodyStage::BodyStage(const board::Board& board, FusionStage& fusion, RecordSink* records,
                     Clock& clock, const Options& options)
    : fusion_(fusion),
      records_(records),
      clock_(clock),
      options_(options),
      tracker_(options.dimensions ? body::Skeleton(*options.dimensions) : skeletonFor(board),
               trackedSensors(board), trackerOptions(options)),
      headingSteps_(board.sensors.size(), 0) {
    for (const auto& sc : board.sensors) {
        sensorNames_.push_back(sc.name);
    }
}

void BodyStage::onSample(const SensorSample& s) {
    const Timestamp t = s.sample.t;
    if (!started_) {
        started_ = true;
        if (options_.calibrate) {
            tracker_.startCalibration(*options_.calibrate, t + options_.settle);
        }
    }
    if (s.sensor >= 0 && static_cast<std::size_t>(s.sensor) < headingSteps_.size()) {
        // The sensor's filter turned its heading (gyroscope-only, or an unchecked raw one) to
        // magnetic north: what the tracker holds of it, and a calibration that took it, turn
        // with it.
        const FusionStage::HeadingStep& step = fusion_.headingStep(s.sensor);
        auto& seen = headingSteps_[static_cast<std::size_t>(s.sensor)];
        if (step.count != seen) {
            seen = step.count;
            const body::TrackerEvents events = tracker_.realignHeading(s.sensor, step.angleRad);
            if (events.reexpressed) {
                recordReexpression(t, s.sensor, step.angleRad);
            }
        }
    }
    const FusionStage::Latest* now = fusion_.latest(s.sensor);
    if (now != nullptr) {
        // A sample is the sensor back: its filter has started again from this one.
        if (!tracker_.sensorOnline(s.sensor)) {
            tracker_.setSensorOnline(s.sensor, true);
        }
        body::SensorUpdate u;
        u.sensor = s.sensor;
        u.t = t;
        u.qEnuSensor = now->orientation;
        u.specificForceMps2 = now->specificForceMps2;
        u.rateRadS = now->rateRadS;
        u.headingFree = fusion_.headingFree(s.sensor);
        u.headingUnchecked = fusion_.magMode(s.sensor) == MagMode::Raw;
        const body::TrackerEvents events = tracker_.update(u);
        if (events.calibrated || events.calibrationFailed || events.headingReset ||
            events.headingResetFailed) {
            record(t, events);
        }
        if (events.kneeHeading) {
            recordKneeHeading(t, events.kneeHeadingRad);
        }
    }
    // Poses on a fixed grid of the output rate, solved at the watermark: a grid point gets its
    // pose once every live sensor, whatever bus it is on, has reported past it (a sensor whose
    // bus stalls is declared late and left out), so that no bus's orientations are carried on
    // past their samples while another's are measured. The watermark can pass several grid
    // points at once.
    const std::optional<Timestamp> through = tracker_.watermark(t);
    while (const std::optional<Timestamp> g = through ? tracker_.due(*through) : std::nullopt) {
        const body::TrackedPose& p = tracker_.solveAt(*g);
        if (p.aidEnuMps2) {
            fusion_.setBodyAcceleration(*p.aidEnuMps2);
        }
        if (records_ != nullptr || feed_ != nullptr) {
            // A segment not measured (its sensor, or the one it follows, out) keeps the rotation
            // of the last pose that measured it, and is flagged: held visibly, never frozen or
            // snapped to a default without a word.
            const std::uint32_t notMeasured = ~p.valid & kAllJoints;
            for (std::size_t j = 0; j < joints_.size(); ++j) {
                if ((notMeasured >> j & 1u) == 0 || !jointSeen_[j]) {
                    joints_[j] = p.pose->qLocal[j].cast<float>();
                    jointSeen_[j] = jointSeen_[j] || (notMeasured >> j & 1u) == 0;
                }
            }
            const Eigen::Vector3f root = p.pose->positionM[0].cast<float>();
            if (records_ != nullptr) {
                records_->pose(p.t, root, joints_, notMeasured);
            }
            if (feed_ != nullptr) {
                publish(p, t, notMeasured);
            }
        }
        latency_.add(clock_.now() - t);
    }
}

void BodyStage::publish(const body::TrackedPose& p, Timestamp newest, std::uint32_t notMeasured) {
    frame_.serial += 1;
    frame_.t = p.t;
    frame_.newestSampleT = newest;
    frame_.rootM = p.pose->positionM[0].cast<float>();
    frame_.notMeasured = notMeasured;
    // A calibration done, not the nominal mountings solved on (which the tracker counts as
    // calibrated: it poses on them): what the streams' flags say (docs/streams.md).
    frame_.bodyCalibrated = tracker_.calibrations() > 0;
    // The world orientations from the joints as recorded (held ones included), so that the
    // two agree; the joint centres are the solver's.
    for (std::size_t j = 0; j < joints_.size(); ++j) {
        frame_.local[j] = joints_[j];
        const int parent = body::parentOf(static_cast<int>(j));
        frame_.world[j] =
            parent < 0 ? joints_[j]
                       : (frame_.world[static_cast<std::size_t>(parent)] * joints_[j]).normalized();
        frame_.positionM[j] = p.pose->positionM[j].cast<float>();
    }
    frame_.publishedT = clock_.now();
    feed_->publish(frame_);
}

void BodyStage::onEvent(const RuntimeEvent& e) {
    switch (e.kind) {
        case RuntimeEvent::Kind::SensorLost:
        case RuntimeEvent::Kind::LineSilent:
            tracker_.setSensorOnline(e.sensor, false);
            break;
        case RuntimeEvent::Kind::SensorReset:
            tracker_.resetSensor(e.sensor);
            break;
        case RuntimeEvent::Kind::SensorOnline:
            tracker_.setSensorOnline(e.sensor, true);
            break;
    }
}

void BodyStage::recordReexpression(Timestamp t, int sensor, double angleRad) {
    const body::BodyCalibration& cal = tracker_.calibration();
    const std::string what = fmt::format(
        "body calibration re-expressed: {}'s heading was not yet magnetic at the calibration (the "
        "gyroscope's or an unchecked one), now is (turned {:.1f} deg); capture heading {:.1f} deg",
        sensorNames_[static_cast<std::size_t>(sensor)], angleRad * 180 / std::numbers::pi,
        cal.headingRad * 180 / std::numbers::pi);
    log::logger(log::Category::Body).debug("{}", what);
    if (records_ == nullptr) {
        return;
    }
    records_->event(t, cap::EventKind::Calibrated, sensor, 0, what);
    records_->metadata(t, "[body_calibration]\ntext = " + tomlString(body::toText(cal)) + "\n");
}

void BodyStage::recordKneeHeading(Timestamp t, double angleRad) {
    const body::BodyCalibration& cal = tracker_.calibration();
    const std::string what = fmt::format(
        "body calibration: capture heading from the knees' axes, turned {:.2f} deg; capture "
        "heading {:.1f} deg",
        angleRad * 180 / std::numbers::pi, cal.headingRad * 180 / std::numbers::pi);
    log::logger(log::Category::Body).info("{}", what);
    if (records_ == nullptr) {
        return;
    }
    records_->event(t, cap::EventKind::Calibrated, -1, 0, what);
    records_->metadata(t, "[body_calibration]\ntext = " + tomlString(body::toText(cal)) + "\n");
}

void BodyStage::record(Timestamp t, const body::TrackerEvents& events) {
    if (events.calibrationFailed) {
        log::logger(log::Category::Body).error("body calibration failed: {}", events.message);
        return;
    }
    if (events.headingResetFailed) {
        log::logger(log::Category::Body).error("{}", events.message);
        return;
    }
    if (records_ == nullptr) {
        return;
    }
    const body::BodyCalibration& cal = tracker_.calibration();
    std::string what = events.calibrated
                           ? fmt::format("body calibration: {} pose, {} segments",
                                         body::toString(cal.method), std::popcount(cal.mask))
                           : fmt::format("heading reset: heading {:.1f} deg",
                                         cal.headingRad * 180 / std::numbers::pi);
    if (events.calibrated && (cal.freeHeading & cal.mask) != 0) {
        // Free (gyroscope-only) headings: docs/body-calibration.md, "Free headings".
        what += fmt::format(" ({} with a free heading, {} of them with the nominal heading)",
                            std::popcount(cal.freeHeading & cal.mask),
                            std::popcount(cal.nominalHeading & cal.freeHeading & cal.mask));
    }
    records_->event(t,
                    events.calibrated ? cap::EventKind::Calibrated : cap::EventKind::HeadingReset,
                    -1, 0, what);
    records_->metadata(t, "[body_calibration]\ntext = " + tomlString(body::toText(cal)) + "\n");
}

}  // namespace caphub::firmware
