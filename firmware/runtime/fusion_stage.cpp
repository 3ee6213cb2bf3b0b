#include "firmware/runtime/fusion_stage.h"

#include <algorithm>
#include <cmath>

namespace caphub::firmware {

const char* toString(MagMode m) {
    switch (m) {
        case MagMode::Calibrated:
            return "calibrated";
        case MagMode::Raw:
            return "uncorrected";
        case MagMode::Estimating:
            return "gyroscope-only heading (estimating hard iron)";
        case MagMode::Online:
            return "online hard iron";
    }
    return "?";
}

namespace {

// The sensors with a magnetometer that the calibrations do not correct: the first readings
// FieldVote waits for.
std::size_t rawSensors(const board::Board& board, const FusionStage::Calibrations& calibrations) {
    std::size_t n = 0;
    for (std::size_t i = 0; i < board.sensors.size(); ++i) {
        const auto* chip = board.sensors[i].chip;
        const bool hasMag = chip != nullptr && !chip->magOdrsHz.empty();
        const bool corrected =
            i < calibrations.size() && calibrations[i] && calibrations[i]->hasMag;
        n += hasMag && !corrected ? 1 : 0;
    }
    return n;
}

}  // namespace

FusionStage::FusionStage(const board::Board& board, RecordSink* records, Calibrations calibrations)
    : latest_(board.sensors.size()),
      valid_(board.sensors.size(), false),
      resetPending_(board.sensors.size(), false),
      resets_(board.sensors.size(), 0),
      calibrations_(std::move(calibrations)),
      headingSteps_(board.sensors.size()),
      firstFields_(board.sensors.size(), rawSensors(board, calibrations_)),
      records_(records) {
    calibrations_.resize(board.sensors.size());
    onlineMag_.resize(board.sensors.size());
    for (std::size_t i = 0; i < board.sensors.size(); ++i) {
        const auto& s = board.sensors[i];
        fusion::FilterParams p;
        p.gyrRateHz = s.achievedOdrHz;
        p.accRateHz = s.achievedOdrHz;
        p.magRateHz = s.magOdrHz > 0 ? s.magOdrHz : s.achievedOdrHz;
        filters_.push_back(std::make_unique<Filter>(p));
        if (!calibrations_[i] || !calibrations_[i]->hasMag) {
            OnlineMag m(fusion::OnlineHardIron(p.magRateHz));
            m.solveEvery = static_cast<std::uint32_t>(std::max(1.0, std::round(p.magRateHz)));
            m.alignEvery = static_cast<std::uint32_t>(std::max(1.0, std::round(2.0 * p.magRateHz)));
            onlineMag_[i] = m;
        }
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
        magUpdate(static_cast<std::size_t>(s.sensor), f, c.magUt, in.t);
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
            if (onlineMag_[i]) {
                // A heading error averaged against the old orientation says nothing of the new.
                onlineMag_[i]->alignCount = 0;
                onlineMag_[i]->sumSin = 0;
                onlineMag_[i]->sumCos = 0;
            }
            resetPending_[i] = true;
            ++resets_[i];
            return;
        }
        case RuntimeEvent::Kind::SensorOnline:
            return;
    }
}

void FusionStage::magUpdate(std::size_t sensor, Filter& f, const Eigen::Vector3d& magUt,
                            Timestamp t) {
    const auto feed = [&f](const Eigen::Vector3d& m) {
        f.updateMag(
            {static_cast<float>(m.x()), static_cast<float>(m.y()), static_cast<float>(m.z())});
    };
    auto& slot = onlineMag_[sensor];
    if (!slot) {
        feed(magUt);  // calibrated
        return;
    }
    OnlineMag& o = *slot;
    if (!magUt.allFinite()) {
        feed(magUt);  // the filter rejects and counts it
        return;
    }
    if (!o.decided) {
        decideMode(sensor, o, f, magUt, t);
    }
    o.estimator.add(magUt);
    if (f.state().inclinationInit && o.estimator.learnsAlignment()) {
        // The sensor's up in its own frame, from the filter's tilt (its heading plays no part):
        // what the magnetometer's axes are aligned to (OnlineHardIron::addAlignment).
        const auto q = f.quat();
        const Eigen::Quaterniond qe(q.w, q.x, q.y, q.z);
        o.estimator.addAlignment(magUt, qe.normalized().conjugate() * Eigen::Vector3d::UnitZ());
    }
    if (++o.sinceSolve >= o.solveEvery) {
        o.sinceSolve = 0;
        o.estimate = o.estimator.refresh();
        // Raw stays raw while the estimate agrees that the offset is small; an estimate that
        // turns good switches to it, one that turns bad (the field no longer fits: a
        // disturbance, a new magnet) falls back to the gyroscope.
        const bool smallOffset = o.estimate.offsetUt.norm() < 0.1 * o.estimate.fieldNormUt;
        if (o.estimate.good && !(o.mode == MagMode::Raw && smallOffset)) {
            if (o.mode == MagMode::Estimating || o.mode == MagMode::Raw) {
                // From a gyroscope-only heading to a magnetic one: the heading error is measured
                // first (alignHeading), then corrected in one step. So from a raw one whose offset
                // turned out large: its heading was as unknown as a free one (the body's
                // calibration took it so, docs/body-calibration.md), and a step, unlike a blend,
                // says by how much it was off.
                if (!o.aligning) {
                    o.aligning = true;
                    o.sumSin = 0;
                    o.sumCos = 0;
                    o.alignCount = 0;
                }
            } else {
                o.mode = MagMode::Online;
            }
        } else if (o.mode == MagMode::Online && o.estimate.valid && !o.estimate.good) {
            o.mode = MagMode::Estimating;
        } else if ((o.mode == MagMode::Estimating || o.mode == MagMode::Raw) && !o.estimate.good) {
            o.aligning = false;
        }
    }
    if ((o.mode == MagMode::Estimating || o.mode == MagMode::Raw) && o.aligning) {
        alignHeading(sensor, o, f, magUt, t);
    }
    switch (o.mode) {
        case MagMode::Raw:
            if (!o.aligning) {
                feed(magUt);  // (while its error is measured, the heading is the gyroscope's)
            }
            return;
        case MagMode::Online:
            feed(o.estimate.corrected(magUt));
            return;
        case MagMode::Estimating:
        case MagMode::Calibrated:
            return;
    }
}

void FusionStage::decideMode(std::size_t sensor, OnlineMag& o, const Filter& f,
                             const Eigen::Vector3d& magUt, Timestamp t) {
    // A saved estimate that is good already: magnetic from the start.
    o.estimate = o.estimator.refresh();
    if (o.estimate.good) {
        o.mode = MagMode::Online;
        o.decided = true;
        return;
    }
    // Otherwise the heading is the gyroscope's (mode Estimating) until the suit's first readings
    // have voted: a raw reading that agrees with the others' field is taken as it is (Raw),
    // anything else is a chip offset or hard iron, and stays gyroscope-only until the estimate is
    // good (fusion::FieldVote).
    const double tS = toSeconds(t.time_since_epoch());
    if (f.state().inclinationInit) {
        const auto q = f.quat();
        const Eigen::Vector3d up = Eigen::Quaterniond(q.w, q.x, q.y, q.z).normalized().conjugate() *
                                   Eigen::Vector3d::UnitZ();
        const double n = magUt.norm();
        if (n > 0) {
            firstFields_.add(sensor, n, std::acos(std::clamp(magUt.dot(up) / n, -1.0, 1.0)), tS);
        }
    }
    firstFields_.close(tS);
    if (const std::optional<bool> trusted = firstFields_.trusted(sensor)) {
        o.mode = *trusted ? MagMode::Raw : MagMode::Estimating;
        o.decided = true;
    }
}

void FusionStage::alignHeading(std::size_t sensor, OnlineMag& o, Filter& f,
                               const Eigen::Vector3d& magUt, Timestamp t) {
    if (!f.state().inclinationInit) {
        return;
    }
    const Eigen::Vector3d m = o.estimate.corrected(magUt);
    const double b = o.estimate.fieldNormUt;
    const auto restart = [&o] {
        o.sumSin = 0;
        o.sumCos = 0;
        o.alignCount = 0;
    };
    if (std::abs(m.norm() - b) > 0.1 * b) {
        restart();  // disturbed (or the estimate is not yet right for this direction)
        return;
    }
    // The field in the earth frame through the filter's gyroscope-only orientation: its
    // horizontal part points where the filter thinks north is; the angle that turns it onto
    // +y (north) about up is the heading error, the filter's own rule (updateMag).
    const auto q = f.quat();
    const Eigen::Vector3d mE = Eigen::Quaterniond(q.w, q.x, q.y, q.z).normalized() * m;
    const double h = std::hypot(mE.x(), mE.y());
    if (h < 0.2 * m.norm()) {
        return;  // the field near vertical here: no heading in it
    }
    o.sumSin += mE.x() / h;
    o.sumCos += mE.y() / h;
    if (++o.alignCount < o.alignEvery) {
        return;
    }
    // The mean resultant length: 1 when every reading gave the same error. Below 0.97 (a circular
    // spread of about 14 deg) the errors disagree - a disturbance, an estimate not yet right for
    // every direction - and the average starts again.
    const double r = std::hypot(o.sumSin, o.sumCos) / static_cast<double>(o.alignCount);
    if (r < 0.97) {
        restart();
        return;
    }
    const double angle = std::atan2(o.sumSin, o.sumCos);
    auto st = f.state();
    const fusion::Quat<float> turn{static_cast<float>(std::cos(angle / 2)), 0.0F, 0.0F,
                                   static_cast<float>(std::sin(angle / 2))};
    st.qCorr = fusion::renormalized(fusion::quatMul(turn, st.qCorr));
    // Magnetic from here on at the normal heading gain: the step was the alignment.
    st.headingInit = true;
    f.setState(st);
    o.mode = MagMode::Online;
    o.aligning = false;
    if (!override_) {
        HeadingStep& step = headingSteps_[sensor];
        ++step.count;
        step.angleRad = angle;
        step.t = t;
    }
}

bool FusionStage::headingFree(int sensor) const {
    return !override_ && magMode(sensor) == MagMode::Estimating;
}

const FusionStage::HeadingStep& FusionStage::headingStep(int sensor) const {
    static const HeadingStep kNone{};
    if (sensor < 0 || static_cast<std::size_t>(sensor) >= headingSteps_.size()) {
        return kNone;
    }
    return headingSteps_[static_cast<std::size_t>(sensor)];
}

const FusionStage::OnlineMag* FusionStage::onlineMagOf(int sensor) const {
    if (sensor < 0 || static_cast<std::size_t>(sensor) >= onlineMag_.size() ||
        !onlineMag_[static_cast<std::size_t>(sensor)]) {
        return nullptr;
    }
    return &*onlineMag_[static_cast<std::size_t>(sensor)];
}

std::uint32_t FusionStage::alignReadings(int sensor) const {
    const OnlineMag* o = onlineMagOf(sensor);
    return o != nullptr ? o->alignEvery : 0;
}

const char* key(MagMode m) {
    switch (m) {
        case MagMode::Calibrated:
            return "calibrated";
        case MagMode::Raw:
            return "uncorrected";
        case MagMode::Estimating:
            return "gyro-only";
        case MagMode::Online:
            return "online-hard-iron";
    }
    return "?";
}

MagMode FusionStage::magMode(int sensor) const {
    const OnlineMag* o = onlineMagOf(sensor);
    return o != nullptr ? o->mode : MagMode::Calibrated;
}

fusion::HardIronEstimate FusionStage::magEstimate(int sensor) const {
    const OnlineMag* o = onlineMagOf(sensor);
    return o != nullptr ? o->estimator.estimate() : fusion::HardIronEstimate{};
}

std::optional<FusionStage::MagLearning> FusionStage::magLearning(int sensor) const {
    const OnlineMag* found = onlineMagOf(sensor);
    if (found == nullptr || found->mode != MagMode::Estimating) {
        return std::nullopt;
    }
    const OnlineMag& o = *found;
    const fusion::OnlineHardIronParams& p = o.estimator.params();
    const fusion::HardIronEstimate e = o.estimator.estimate();  // now, not the latest solve's
    MagLearning m;
    m.readingsS = o.estimator.readingsS();
    m.neededS = p.minWeightS;
    m.spread = e.spread;
    m.neededSpread = p.minSpread;
    m.residualPct = e.residualPct;
    m.maxResidualPct = p.maxResidualPct;
    m.fieldUt = e.fieldNormUt;
    m.solved = e.valid;
    m.measuring = o.aligning;
    if (o.aligning) {
        m.waitingFor = "the heading measured";
    } else if (m.readingsS < m.neededS) {
        m.waitingFor = "readings";
    } else if (!e.valid || e.spread < p.minSpread) {  // one direction alone: no solution at all
        m.waitingFor = "turns";
    } else {
        m.waitingFor = "a steadier field";  // residual or field size out of bounds
    }
    return m;
}

std::optional<fusion::OnlineHardIronState> FusionStage::magEstimatorState(int sensor) const {
    const OnlineMag* o = onlineMagOf(sensor);
    return o != nullptr ? std::optional(o->estimator.state()) : std::nullopt;
}

bool FusionStage::setMagEstimatorState(int sensor, const fusion::OnlineHardIronState& state) {
    OnlineMag* o = onlineMagOf(sensor);
    if (o == nullptr) {
        return false;
    }
    o->decided = false;
    return o->estimator.setState(state);
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
