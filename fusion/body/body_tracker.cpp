#include "fusion/body/body_tracker.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <utility>

#include <fmt/format.h>

namespace caphub::body {

namespace {

SegmentMask maskOf(const std::vector<TrackedSensor>& sensors) {
    SegmentMask m = 0;
    for (const auto& s : sensors) {
        m |= bit(s.segment);
    }
    return m;
}

}  // namespace

std::string_view toString(CalibrationStatus::State s) {
    switch (s) {
        case CalibrationStatus::State::NotStarted:
            return "not started";
        case CalibrationStatus::State::Averaging:
            return "averaging";
        case CalibrationStatus::State::Done:
            return "done";
        case CalibrationStatus::State::Failed:
            return "failed";
    }
    return "?";
}

std::string_view toString(HeadingResetStatus::State s) {
    switch (s) {
        case HeadingResetStatus::State::NotAsked:
            return "not asked";
        case HeadingResetStatus::State::Pending:
            return "pending";
        case HeadingResetStatus::State::Done:
            return "done";
        case HeadingResetStatus::State::Failed:
            return "failed";
    }
    return "?";
}

BodyTracker::BodyTracker(const Skeleton& skeleton, std::vector<TrackedSensor> sensors,
                         const BodyTrackerOptions& options)
    : sensors_(std::move(sensors)),
      options_(options),
      period_(periodFromHz(options.rateHz)),
      solver_(skeleton, maskOf(sensors_), options.solver),
      held_(sensors_.size()),
      online_(sensors_.size(), true),
      headingTurn_(sensors_.size(), 0.0) {
    sensorOfSegment_.fill(-1);
    nominal_.fill(Quatd::Identity());
    for (std::size_t i = 0; i < sensors_.size(); ++i) {
        const auto seg = static_cast<std::size_t>(idx(sensors_[i].segment));
        sensorOfSegment_[seg] = static_cast<int>(i);
        nominal_[seg] = sensors_[i].nominalMounting;
    }
    auto sensorOf = [this](Segment s) {
        return sensorOfSegment_[static_cast<std::size_t>(idx(s))];
    };
    pelvisSensor_ = sensorOf(Segment::Pelvis);
    footSensor_ = {sensorOf(Segment::LHindfoot), sensorOf(Segment::RHindfoot)};
    thighSensor_ = {sensorOf(Segment::LThigh), sensorOf(Segment::RThigh)};
    shankSensor_ = {sensorOf(Segment::LCalf), sensorOf(Segment::RCalf)};
    kneeHeading_ = KneeHeading(options_.kneeHeadingOptions);
    jointTurn_.assign(sensors_.size(), 0.0);
    turnScratch_.assign(sensors_.size(), 0.0);
    jointInputs_.resize(sensors_.size());
    buildJointLinks(skeleton.dimensions());
    footInertial_ = {FootInertial(options_.footInertialOptions),
                     FootInertial(options_.footInertialOptions)};
    if (options_.footStretches) {
        for (std::size_t k = 0; k < 2; ++k) {
            footInertial_[k].useStretchLog(&options_.footStretches->feet[k],
                                           options_.footStretches->use);
        }
    }
    out_.pose = &solver_.pose();
    if (options_.solveUncalibrated) {
        // No calibration pose: the nominal mountings, the subject facing north.
        calibration_.mask = maskOf(sensors_);
        calibration_.mounting = nominal_;
        solver_.setCalibration(calibration_);
        calibrated_ = true;
    }
}

TrackerEvents BodyTracker::update(const SensorUpdate& u) {
    TrackerEvents events;
    if (u.sensor < 0 || static_cast<std::size_t>(u.sensor) >= sensors_.size() ||
        !online_[static_cast<std::size_t>(u.sensor)]) {
        return events;
    }
    gridWaits_ = false;
    const Timestamp t = u.t;
    if (!firstUpdate_) {
        firstUpdate_ = t;
    }
    auto& h = held_[static_cast<std::size_t>(u.sensor)];
    // A free heading's turn from the calibration (the averaging below takes the orientation as
    // it came: a calibration finds the turn anew).
    auto turned = [&u](double turn) {
        return turn == 0 ? u.qEnuSensor
                         : (Eigen::Quaternionf(Eigen::AngleAxisf(static_cast<float>(turn),
                                                                 Eigen::Vector3f::UnitZ())) *
                            u.qEnuSensor)
                               .normalized();
    };
    const double turn = headingTurn_[static_cast<std::size_t>(u.sensor)];
    Eigen::Quaternionf q = turned(turn);
    if (h.count > 0 && t > h.latestT) {
        h.previous = h.latest;
        h.previousT = h.latestT;
        h.count = 2;
    } else if (h.count == 0) {
        h.count = 1;
    }
    h.latest = q;
    h.latestT = t;
    h.rateRadS = u.rateRadS;
    if (!gridStarted_ && calibrated_) {
        gridStarted_ = true;
        nextGrid_ = t;
    }
    if (!calibrated_) {
        // Its moment has come with nothing to turn: it fails now, rather than wait and turn a
        // calibration made after it was asked for.
        headingResetIfDue(t, events);
    }

    if (request_) {
        const Request& r = *request_;
        Timestamp end = r.windows[0].from + options_.calibrationAverage;
        for (int w = 1; w < r.windowCount; ++w) {
            end = std::max(
                end, r.windows[static_cast<std::size_t>(w)].from + options_.calibrationAverage);
        }
        const bool wasCalibrated = calibrated_;
        if (t >= end) {
            completeCalibration(t, events);
            if (!wasCalibrated) {
                // The update that completes it is not used further: the poses (and the root's
                // inputs) start from the next one.
                return events;
            }
        } else {
            average(u);
        }
        if (!wasCalibrated) {
            return events;
        }
        if (headingTurn_[static_cast<std::size_t>(u.sensor)] != turn) {
            q = turned(headingTurn_[static_cast<std::size_t>(u.sensor)]);  // a new calibration's
        }
    }
    if (!calibrated_) {
        return events;
    }
    if (options_.footInertial && h.count == 2) {
        for (std::size_t k = 0; k < 2; ++k) {
            if (u.sensor == footSensor_[k]) {
                FootInertial& f = footInertial_[k];
                f.add(q.cast<double>(), u.specificForceMps2.cast<double>(),
                      u.rateRadS.cast<double>(), toSeconds(h.latestT - h.previousT));
                footHistory_[k].push(FootSample{t, f.valid(), f.known(), f.still(),
                                                f.velocityEnuMps(), f.rateEnuRadS()});
            }
        }
    }
    if (options_.kneeHeading != KneeHeadingMode::Off && !kneeHeadingDone_ &&
        (u.sensor == shankSensor_[0] || u.sensor == shankSensor_[1])) {
        addKneeSample(static_cast<std::size_t>(u.sensor), events);
    }
    if (options_.jointHeading && h.count == 2) {
        addJointSample(static_cast<std::size_t>(u.sensor), u, q);
    }
    if (u.sensor == pelvisSensor_) {
        if (pelvisCount_ == kPelvisPending) {
            // Never more than a few samples wait (the watermark is at most a sample interval
            // behind); a ring full counts its oldest into the next pose.
            pelvisForceSumEnu_ += pelvisPending_[pelvisHead_].forceEnuMps2;
            ++pelvisForceCount_;
            pelvisHead_ = (pelvisHead_ + 1) % kPelvisPending;
            --pelvisCount_;
        }
        pelvisPending_[(pelvisHead_ + pelvisCount_) % kPelvisPending] =
            PelvisForce{t, q.cast<double>() * u.specificForceMps2.cast<double>()};
        ++pelvisCount_;
    }
    headingResetIfDue(t, events);
    return events;
}

std::optional<Timestamp> BodyTracker::due(Timestamp through) {
    if (!calibrated_ || !gridStarted_ || gridWaits_) {
        return std::nullopt;
    }
    // Samples of several buses arrive interleaved, so `through` can jump by more than a period;
    // after a long gap (every sensor silent) the grid restarts rather than catch up.
    if (through - nextGrid_ > period_ * 10) {
        nextGrid_ = through;
    }
    if (through >= nextGrid_) {
        return nextGrid_;
    }
    return std::nullopt;
}

const TrackedPose& BodyTracker::solveAt(Timestamp t) {
    const SensorFrame frame = frameAt(t);
    const double dtS = poses_ == 0 ? toSeconds(period_) : toSeconds(t - lastPose_);
    lastPose_ = t;
    // The pelvis accelerometer over the frame (its readings up to t), in the skeleton world
    // frame: it tells a flight phase (a jump, a running stride) from stance, and the velocity at
    // take-off.
    while (pelvisCount_ > 0 && pelvisPending_[pelvisHead_].t <= t) {
        pelvisForceSumEnu_ += pelvisPending_[pelvisHead_].forceEnuMps2;
        ++pelvisForceCount_;
        pelvisHead_ = (pelvisHead_ + 1) % kPelvisPending;
        --pelvisCount_;
    }
    std::optional<Vec3d> rootSpecificForce;
    if (pelvisForceCount_ > 0) {
        lastPelvisForceEnu_ = pelvisForceSumEnu_ / pelvisForceCount_;
        lastPelvisForceT_ = t;
        pelvisForceSumEnu_.setZero();
        pelvisForceCount_ = 0;
    }
    // Poses faster than the pelvis sensor: a pose between two readings takes the latest (the
    // flight is confirmed over consecutive frames, and a frame without a reading would break
    // it: at 120 poses a second from 100 Hz sensors no jump flew).
    if (lastPelvisForceT_ && toSeconds(t - *lastPelvisForceT_) <= kPelvisHoldS) {
        rootSpecificForce = calibration_.qEnuWorld().conjugate() * lastPelvisForceEnu_;
    }
    // The feet's dead reckoning at t, in the skeleton world frame.
    FootSensorMotion feet;
    const Quatd qWorldEnu = calibration_.qEnuWorld().conjugate();
    for (std::size_t k = 0; k < 2; ++k) {
        const int i = footSensor_[k];
        if (!options_.footInertial || i < 0 || held_[static_cast<std::size_t>(i)].count == 0) {
            continue;
        }
        const std::optional<FootSample> f = footHistory_[k].at(t);
        if (f && f->known) {
            feet.valid[k] = f->valid;
            feet.known[k] = true;
            feet.still[k] = f->still;
            feet.velocityMps[k] = qWorldEnu * f->velocityEnuMps;
            feet.rateRadS[k] = qWorldEnu * f->rateEnuRadS;
            feet.onFootM[k] = sensors_[static_cast<std::size_t>(i)].positionM;
        }
    }
    solver_.solve(frame, dtS, rootSpecificForce, &feet);
    ++poses_;
    while (nextGrid_ <= t) {
        nextGrid_ += period_;
    }
    // Valid: the segments of sensors that have reported within staleAfter of t.
    SegmentMask present = 0;
    for (int seg = 0; seg < kSegmentCount; ++seg) {
        const int i = sensorOfSegment_[static_cast<std::size_t>(seg)];
        if (has(frame.mask, seg) &&
            t - held_[static_cast<std::size_t>(i)].latestT <= options_.staleAfter) {
            present |= SegmentMask{1} << seg;
        }
    }
    out_.t = t;
    out_.pose = &solver_.pose();
    out_.valid = solver_.poseSolver().validSegments(present);
    if (!options_.aidFilters) {
        out_.aidEnuMps2 = std::nullopt;
    } else if (!rootTranslationMeasured(out_.valid)) {
        // The root's motion is not measured (no sensor on a foot, or one out): its velocity comes
        // from contacts of held segments, and its change is no acceleration of the body. The
        // filters are told none.
        rootVelocityValid_ = false;
        out_.aidEnuMps2 = Vec3d::Zero();
    } else {
        out_.aidEnuMps2 = aidingAcceleration(dtS);
    }
    return out_;
}

void BodyTracker::startCalibration(ReferencePoseKind pose, Timestamp from) {
    Request r;
    r.method = pose == ReferencePoseKind::T ? CalibrationMethod::TPose : CalibrationMethod::NPose;
    r.windowCount = 1;
    r.windows[0].from = from;
    r.latest = from;
    for (auto& w : r.windows) {
        w.sum.assign(sensors_.size(), Eigen::Vector4d::Zero());
        w.count.assign(sensors_.size(), 0);
        w.free.assign(sensors_.size(), false);
        w.unchecked.assign(sensors_.size(), false);
    }
    request_ = std::move(r);
    state_ = CalibrationStatus::State::Averaging;
    requested_ = request_->method;
    calibrationMessage_.clear();
}

void BodyTracker::startTwoPoseCalibration(Timestamp tPoseFrom, Timestamp nPoseFrom) {
    startCalibration(ReferencePoseKind::T, tPoseFrom);
    request_->method = CalibrationMethod::TPlusN;
    request_->windowCount = 2;
    request_->windows[1].from = nPoseFrom;
    request_->latest = std::min(tPoseFrom, nPoseFrom);
    requested_ = CalibrationMethod::TPlusN;
}

void BodyTracker::headingResetAt(Timestamp t) {
    headingResetAt_ = t;
    headingResetStatus_ = HeadingResetStatus{HeadingResetStatus::State::Pending, 0, {}};
}

void BodyTracker::forget(std::size_t sensor) {
    held_[sensor].count = 0;
    jointInputs_[sensor].count = 0;
    for (std::size_t k = 0; k < 2; ++k) {
        if (footSensor_[k] == static_cast<int>(sensor)) {
            footInertial_[k].reset();
            footHistory_[k].clear();
        }
    }
    // Its orientations before and after differ (a restarted filter finds its heading anew): the
    // calibration averages what comes after.
    if (request_) {
        for (auto& w : request_->windows) {
            w.sum[sensor].setZero();
            w.count[sensor] = 0;
            w.free[sensor] = false;
            w.unchecked[sensor] = false;
        }
    }
    // A free heading starts afresh too: the calibration's orientations of the sensor are in a
    // frame that is gone, and no later measurement of the new one can re-express them.
    // An unchecked heading taken as right keeps its measured mounting (a raw heading is found
    // anew from the same readings), but cannot be re-expressed either.
    const SegmentMask seg = bit(sensors_[sensor].segment);
    if (calibrationInput_) {
        CalibrationInput& in = *calibrationInput_;
        if (((in.free | in.uncheckedFree) & seg) != 0) {
            in.lost |= seg;
        } else if ((in.unchecked & seg) != 0) {
            in.stale |= seg;
        }
        in.free &= ~seg;
        in.unchecked &= ~seg;
        in.uncheckedFree &= ~seg;
    }
    // Its turn was for the heading that is gone, and so were its joints' sums.
    headingTurn_[sensor] = 0;
    jointTurn_[sensor] = 0;
    for (const std::size_t k : linksOf_[sensor]) {
        links_[k].heading.reset();
    }
}

void BodyTracker::turnHeld(std::size_t i, double angleRad, FootOnTurn foot) {
    const Quatd turn(Eigen::AngleAxisd(angleRad, Vec3d::UnitZ()));  // about ENU up
    const Eigen::Quaternionf turnF = turn.cast<float>();
    HeldOrientation& h = held_[i];
    h.previous = (turnF * h.previous).normalized();
    h.latest = (turnF * h.latest).normalized();
    for (auto& b : jointInputs_[i].before) {
        b.q = (turn * b.q).normalized();
    }
    if (i == static_cast<std::size_t>(pelvisSensor_)) {
        // The pelvis' forces not yet taken by a pose are in the frame that turned.
        for (std::size_t k = 0; k < pelvisCount_; ++k) {
            auto& f = pelvisPending_[(pelvisHead_ + k) % kPelvisPending].forceEnuMps2;
            f = turn * f;
        }
        pelvisForceSumEnu_ = turn * pelvisForceSumEnu_;
        lastPelvisForceEnu_ = turn * lastPelvisForceEnu_;
    }
    for (std::size_t k = 0; k < 2; ++k) {
        if (footSensor_[k] != static_cast<int>(i)) {
            continue;
        }
        if (foot == FootOnTurn::Turn) {
            footInertial_[k].turn(turn);
            footHistory_[k].turn(turn);
        } else {
            // Its dead reckoning integrated in the old frame: start it again from the next still
            // instant, as after an outage.
            footInertial_[k].reset();
            footHistory_[k].clear();
        }
    }
}

void BodyTracker::applyHeadingTurns(FootOnTurn foot) {
    for (std::size_t i = 0; i < sensors_.size(); ++i) {
        const int seg = idx(sensors_[i].segment);
        const double turn = has(calibration_.freeHeading & calibration_.mask, seg)
                                ? calibration_.headingTurnRad[static_cast<std::size_t>(seg)]
                                : 0.0;
        if (turn != headingTurn_[i]) {
            if (held_[i].count > 0) {
                turnHeld(i, std::remainder(turn - headingTurn_[i], 2 * std::numbers::pi), foot);
            }
            headingTurn_[i] = turn;
        }
    }
}

TrackerEvents BodyTracker::realignHeading(int sensor, double angleRad) {
    TrackerEvents events;
    if (sensor < 0 || static_cast<std::size_t>(sensor) >= sensors_.size() ||
        !std::isfinite(angleRad)) {
        return events;
    }
    const auto i = static_cast<std::size_t>(sensor);
    const Quatd turn(Eigen::AngleAxisd(angleRad, Vec3d::UnitZ()));  // about ENU up
    // The filter's frame turned: what is held (taken with the calibration's turn, if any) turns
    // with it; the calibration's turn is replaced below.
    turnHeld(i, angleRad);
    if (request_) {
        // A rotation on the left is linear in the quaternion's components: the turned sum is the
        // sum of the turned orientations, so the average goes on in the new frame.
        Eigen::Matrix4d left;  // (w, x, y, z) -> turn * q
        const double w = turn.w();
        const double z = turn.z();
        left << w, 0, 0, -z, 0, w, -z, 0, 0, z, w, 0, z, 0, 0, w;
        for (auto& win : request_->windows) {
            win.sum[i] = left * win.sum[i];
            win.free[i] = false;
            win.unchecked[i] = false;
        }
    }
    const SegmentMask seg = bit(sensors_[i].segment);
    if (!calibrationInput_ ||
        ((calibrationInput_->free | calibrationInput_->unchecked) & seg) == 0) {
        return events;
    }
    CalibrationInput in = *calibrationInput_;
    for (auto& f : in.frames) {
        auto& q = f.qEnuSensor[static_cast<std::size_t>(idx(sensors_[i].segment))];
        q = (turn * q).normalized();
    }
    in.free &= ~seg;
    in.unchecked &= ~seg;
    in.uncheckedFree &= ~seg;
    Result<BodyCalibration> cal = computeCalibration(in, calibration_.tNs);
    if (!cal) {
        return events;  // it was computed from these orientations once: cannot fail now
    }
    // A heading reset since the calibration turned the capture world by the difference: keep it.
    const double resetTurn = calibration_.headingRad - calibrationInput_->headingRad;
    in.headingRad = cal->headingRad;
    cal->headingRad = std::remainder(cal->headingRad + resetTurn, 2 * std::numbers::pi);
    calibrationInput_ = in;
    calibration_ = *cal;
    // This sensor's heading is measured now; the other free ones keep what their joints found
    // (the computation above gave them their nominal mountings again).
    jointTurn_[i] = 0;
    const std::vector<double> kept = jointTurn_;
    std::fill(jointTurn_.begin(), jointTurn_.end(), 0.0);
    resetJointHeadings();
    // This sensor's turn dropped, the free ones' anew (relative to the capture heading now).
    applyHeadingTurns();
    turnFreeHeadings(kept);
    solver_.setCalibration(calibration_);
    // The aiding's low-passed velocity is in the old world.
    rootVelocityValid_ = false;
    events.reexpressed = true;
    return events;
}

void BodyTracker::turnMounting(Segment segment, double angleRad) {
    const ReferencePoseKind pose = calibration_.method == CalibrationMethod::NPose
                                       ? ReferencePoseKind::N
                                       : ReferencePoseKind::T;
    const Quatd ref = referenceOrientation(pose, segment);
    const Quatd turn(Eigen::AngleAxisd(angleRad, Vec3d::UnitY()));
    auto& m = calibration_.mounting[static_cast<std::size_t>(idx(segment))];
    m = (ref.conjugate() * turn * ref * m).normalized();
}

bool BodyTracker::kneeHeadingApplies() const {
    // Only a calibration taken in one pose from magnetic headings: a free heading's mounting is
    // the nominal one about the vertical (its own strap's turn, not the capture heading's, turns
    // its knee), and T+N's arms come from gravity alone.
    const CalibrationMethod method = calibration_.method;
    return calibrationInput_ && freeAtCalibration() == 0 && calibration_.freeHeading == 0 &&
           (method == CalibrationMethod::TPose || method == CalibrationMethod::NPose);
}

void BodyTracker::turnCaptureHeading(double errorRad, TrackerEvents& events) {
    // The capture heading was off by the error: psi + error, and every mounting
    // q_segment_sensor = q_W_segment(ref)^-1 q_ENU_W^-1 q_ENU_sensor turns with it.
    for (int i = 0; i < kSegmentCount; ++i) {
        if ((calibration_.mask & bit(static_cast<Segment>(i))) == 0) {
            continue;
        }
        turnMounting(static_cast<Segment>(i), -errorRad);
    }
    calibration_.headingRad =
        std::remainder(calibration_.headingRad + errorRad, 2 * std::numbers::pi);
    solver_.setCalibration(calibration_);
    rootVelocityValid_ = false;  // the aiding's low-passed velocity is in the old world
    kneeHeadingDone_ = true;
    events.kneeHeading = true;
    events.kneeHeadingRad = errorRad;
}

std::optional<double> BodyTracker::kneeHeadingError() const {
    return kneeHeadingApplies() ? kneeHeading_.headingErrorRad() : std::nullopt;
}

void BodyTracker::addKneeSample(std::size_t sensor, TrackerEvents& events) {
    if (!kneeHeadingApplies()) {
        return;
    }
    const int knee = static_cast<int>(sensor) == shankSensor_[0] ? 0 : 1;
    const int thigh = thighSensor_[static_cast<std::size_t>(knee)];
    if (thigh < 0) {
        return;
    }
    const HeldOrientation& s = held_[sensor];
    const HeldOrientation& th = held_[static_cast<std::size_t>(thigh)];
    const Segment shankSegment = sensors_[sensor].segment;
    const auto seg = static_cast<std::size_t>(idx(shankSegment));
    if (s.count == 0 || th.count == 0 || (calibration_.mask & bit(shankSegment)) == 0) {
        return;
    }
    // The shank's rate relative to the thigh's, ENU, then in the shank's segment frame.
    const Quatd shankEnu = s.latest.cast<double>();
    const Vec3d relativeEnu = shankEnu * s.rateRadS.cast<double>() -
                              th.latest.cast<double>() * th.rateRadS.cast<double>();
    kneeHeading_.add(knee, calibration_.mounting[seg] * (shankEnu.conjugate() * relativeEnu));
    if (options_.kneeHeading != KneeHeadingMode::Live) {
        return;
    }
    const std::optional<double> error = kneeHeading_.headingErrorRad();
    if (!error) {
        return;
    }
    turnCaptureHeading(*error, events);
}

Result<BodyCalibration> BodyTracker::computeCalibration(const CalibrationInput& in,
                                                        std::int64_t tNs) const {
    CalibrationOptions copt;
    copt.nominalMounting = nominal_;
    // The capture heading from the sensors whose headings are corrected; failing any, from all
    // (a free heading is off by an angle of its own, an unchecked one by whatever its offset
    // makes it: neither is better than the other).
    copt.headingFrom = ~(in.free | in.unchecked | in.lost | in.stale);
    // A free heading's mounting: the one closest to the nominal about the vertical. A sensor
    // lost since keeps that mounting (still the best known), but no turn: its orientations are
    // in a new frame that nothing relates to the one averaged. An unchecked heading is checked
    // against its strap by the first computation (a wrong one is taken as free); the
    // re-expressions keep what it found.
    copt.freeHeading = in.free | in.lost | in.uncheckedFree;
    copt.checkHeading = in.checked ? 0 : in.unchecked;
    const auto pose =
        in.method == CalibrationMethod::TPose ? ReferencePoseKind::T : ReferencePoseKind::N;
    Result<BodyCalibration> cal = in.method == CalibrationMethod::TPlusN
                                      ? calibrateTwoPose(in.frames[0], in.frames[1], copt, tNs)
                                      : calibrateOnePose(pose, in.frames[0], copt, tNs);
    if (cal) {
        for (int i = 0; i < kSegmentCount; ++i) {
            if (has(in.lost, i)) {
                cal->headingTurnRad[static_cast<std::size_t>(i)] = 0;
            }
        }
    }
    return cal;
}

void BodyTracker::setSensorOnline(int sensor, bool online) {
    if (sensor < 0 || static_cast<std::size_t>(sensor) >= sensors_.size()) {
        return;
    }
    const auto i = static_cast<std::size_t>(sensor);
    if (online_[i] != online) {
        forget(i);
    }
    online_[i] = online;
}

void BodyTracker::resetSensor(int sensor) {
    if (sensor >= 0 && static_cast<std::size_t>(sensor) < sensors_.size()) {
        forget(static_cast<std::size_t>(sensor));
    }
}

bool BodyTracker::sensorOnline(int sensor) const {
    return sensor >= 0 && static_cast<std::size_t>(sensor) < sensors_.size() &&
           online_[static_cast<std::size_t>(sensor)];
}

std::optional<Timestamp> BodyTracker::latestUpdate(int sensor) const {
    if (!sensorOnline(sensor) || held_[static_cast<std::size_t>(sensor)].count == 0) {
        return std::nullopt;
    }
    return held_[static_cast<std::size_t>(sensor)].latestT;
}

std::optional<Timestamp> BodyTracker::watermark(Timestamp newest) const {
    constexpr Duration kMinLate = std::chrono::milliseconds(10);
    std::optional<Timestamp> least;
    for (std::size_t i = 0; i < held_.size(); ++i) {
        const HeldOrientation& h = held_[i];
        if (online_[i] && h.count == 0 && firstUpdate_ && newest - *firstUpdate_ <= kStartWait) {
            return std::nullopt;  // its first sample is still to come
        }
        if (!online_[i] || h.count == 0) {
            continue;
        }
        if (h.count == 2) {
            const Duration late = std::max((h.latestT - h.previousT) * 5 / 2, kMinLate);
            if (newest - h.latestT > late) {
                continue;
            }
        }
        if (!least || h.latestT < *least) {
            least = h.latestT;
        }
    }
    return least;
}

CalibrationStatus BodyTracker::calibrationStatus() const {
    CalibrationStatus s;
    s.state = state_;
    s.method = requested_;
    s.message = calibrationMessage_;
    if (state_ == CalibrationStatus::State::Done) {
        s.progress = 1;
    } else if (request_) {
        // The windows may overlap or not: the share of their total length passed.
        double passed = 0;
        for (int w = 0; w < request_->windowCount; ++w) {
            const Duration in =
                request_->latest - request_->windows[static_cast<std::size_t>(w)].from;
            passed += std::clamp(toSeconds(in), 0.0, toSeconds(options_.calibrationAverage));
        }
        s.progress = passed / (toSeconds(options_.calibrationAverage) * request_->windowCount);
    }
    return s;
}

void BodyTracker::average(const SensorUpdate& u) {
    Request& r = *request_;
    r.latest = std::max(r.latest, u.t);
    const auto i = static_cast<std::size_t>(u.sensor);
    for (int k = 0; k < r.windowCount; ++k) {
        Window& w = r.windows[static_cast<std::size_t>(k)];
        if (u.t < w.from || u.t >= w.from + options_.calibrationAverage) {
            continue;
        }
        const Eigen::Quaternionf& q = u.qEnuSensor;
        Eigen::Vector4d v(q.w(), q.x(), q.y(), q.z());
        // q and -q are one rotation: add each on the side of the running sum.
        if (v.dot(w.sum[i]) < 0) {
            v = -v;
        }
        w.sum[i] += v;
        ++w.count[i];
        w.free[i] = w.free[i] || u.headingFree;
        w.unchecked[i] = w.unchecked[i] || u.headingUnchecked;
    }
}

SensorFrame BodyTracker::averagedFrame(const Window& w, SegmentMask only) const {
    SensorFrame frame;
    for (std::size_t i = 0; i < sensors_.size(); ++i) {
        if (w.count[i] == 0 || (only & bit(sensors_[i].segment)) == 0) {
            continue;  // no orientation: the segment stays uncalibrated
        }
        const Eigen::Vector4d m = w.sum[i].normalized();
        const auto seg = static_cast<std::size_t>(idx(sensors_[i].segment));
        frame.qEnuSensor[seg] = Quatd(m[0], m[1], m[2], m[3]);
        frame.mask |= bit(sensors_[i].segment);
    }
    return frame;
}

void BodyTracker::completeCalibration(Timestamp t, TrackerEvents& events) {
    const Request r = std::move(*request_);
    request_.reset();
    CalibrationInput in;
    in.method = r.method;
    if (r.method == CalibrationMethod::TPlusN) {
        // Both poses need the same sensors: those averaged in both windows.
        const SegmentMask both = averagedFrame(r.windows[0], ~SegmentMask{0}).mask &
                                 averagedFrame(r.windows[1], ~SegmentMask{0}).mask;
        in.frames = {averagedFrame(r.windows[0], both), averagedFrame(r.windows[1], both)};
    } else {
        in.frames[0] = averagedFrame(r.windows[0], ~SegmentMask{0});
    }
    for (std::size_t i = 0; i < sensors_.size(); ++i) {
        for (int w = 0; w < r.windowCount; ++w) {
            if (r.windows[static_cast<std::size_t>(w)].free[i]) {
                in.free |= bit(sensors_[i].segment) & in.frames[0].mask;
            }
            if (r.windows[static_cast<std::size_t>(w)].unchecked[i]) {
                in.unchecked |= bit(sensors_[i].segment) & in.frames[0].mask;
            }
        }
    }
    Result<BodyCalibration> cal = computeCalibration(in, toNs(t));
    if (!cal) {
        state_ = CalibrationStatus::State::Failed;
        calibrationMessage_ = cal.error().message;
        events.calibrationFailed = true;
        events.message = calibrationMessage_;
        return;
    }
    const bool first = !calibrated_;
    in.uncheckedFree = cal->freeHeading & in.unchecked;
    in.checked = true;
    in.headingRad = cal->headingRad;
    calibrationInput_ = in;
    calibration_ = *cal;
    // The joints' corrections were of the calibration before.
    std::fill(jointTurn_.begin(), jointTurn_.end(), 0.0);
    resetJointHeadings();
    applyHeadingTurns();
    solver_.setCalibration(calibration_);
    solver_.resetRoot();
    kneeHeading_.reset();
    kneeHeadingDone_ = false;
    ++calibrations_;
    if (options_.knownHeadingErrorRad && calibrations_ == 1 && kneeHeadingApplies()) {
        // Offline: the error the knees showed over the whole take, from the calibration on.
        turnCaptureHeading(*options_.knownHeadingErrorRad, events);
    }
    rootVelocityValid_ = false;
    calibrated_ = true;
    state_ = CalibrationStatus::State::Done;
    calibrationMessage_.clear();
    events.calibrated = true;
    if (first) {
        // The first pose is the calibration's own moment, solved once the next update is in.
        gridStarted_ = true;
        nextGrid_ = t;
        gridWaits_ = true;
    }
}

void BodyTracker::headingResetIfDue(Timestamp t, TrackerEvents& events) {
    if (headingResetAt_ && t >= *headingResetAt_) {
        applyHeadingReset(*headingResetAt_, events);
        headingResetAt_.reset();
    }
}

void BodyTracker::applyHeadingReset(Timestamp t, TrackerEvents& events) {
    const auto fail = [&](std::string message) {
        events.headingResetFailed = true;
        events.message = message;
        headingResetStatus_ =
            HeadingResetStatus{HeadingResetStatus::State::Failed, 0, std::move(message)};
    };
    if (!calibrated_) {
        fail("heading reset: no body calibration to turn");
        return;
    }
    const SensorFrame frame = frameAt(t);
    SegmentMask present = 0;
    for (int seg = 0; seg < kSegmentCount; ++seg) {
        if (has(frame.mask, seg)) {
            present |= SegmentMask{1} << seg;
        }
    }
    if (!has(solver_.poseSolver().validSegments(present), idx(Segment::Pelvis))) {
        fail("heading reset: no orientation of the pelvis (nor the spine it follows)");
        return;
    }
    Pose pose;
    solver_.poseSolver().solve(frame, pose);
    const Vec3d forward = pose.world(Segment::Pelvis) * Vec3d::UnitZ();
    if (std::hypot(forward.x(), forward.z()) < 1e-6) {
        fail("heading reset: the pelvis' forward axis is vertical, its heading undefined");
        return;
    }
    headingReset(calibration_, pose);
    solver_.setCalibration(calibration_);
    // The aiding's low-passed velocity is in the old world.
    rootVelocityValid_ = false;
    events.headingReset = true;
    headingResetStatus_ = HeadingResetStatus{
        HeadingResetStatus::State::Done, calibration_.headingRad * 180 / std::numbers::pi, {}};
}

SensorFrame BodyTracker::frameAt(Timestamp t) const {
    SensorFrame frame;
    for (int seg = 0; seg < kSegmentCount; ++seg) {
        const int i = sensorOfSegment_[static_cast<std::size_t>(seg)];
        Eigen::Quaternionf q;
        if (i >= 0 && orientationAt(static_cast<std::size_t>(i), t, q)) {
            frame.qEnuSensor[static_cast<std::size_t>(seg)] = q.cast<double>();
            frame.mask |= SegmentMask{1} << seg;
        }
    }
    return frame;
}

bool BodyTracker::orientationAt(std::size_t sensor, Timestamp t, Eigen::Quaternionf& q) const {
    const auto& h = held_[sensor];
    if (h.count == 0 || !online_[sensor]) {
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
    // held where it was (and, past staleAfter, not valid).
    const double ahead = std::min(toSeconds(t - h.latestT), span);
    const float angle = h.rateRadS.norm() * static_cast<float>(ahead);
    q = angle > 0
            ? (h.latest * Eigen::Quaternionf(Eigen::AngleAxisf(angle, h.rateRadS.normalized())))
                  .normalized()
            : h.latest;
    return true;
}

std::optional<Vec3d> BodyTracker::aidingAcceleration(double dtS) {
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
        return std::nullopt;
    }
    const Vec3d before = rootVelocityLp_;
    rootVelocityLp_ += (horizontal - before) * (1.0 - std::exp(-dtS / kTauS));
    Vec3d a = (rootVelocityLp_ - before) / dtS;
    if (a.norm() > kMaxMps2) {
        a *= kMaxMps2 / a.norm();
    }
    return calibration_.qEnuWorld() * a;
}

}  // namespace caphub::body
