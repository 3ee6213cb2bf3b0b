#include "fusion/body/foot_inertial.h"

#include <algorithm>
#include <cmath>

namespace caphub::body {

void FootInertial::useStretchLog(FootStretchLog* log, FootStretchUse use) {
    log_ = log;
    use_ = use;
    stretch_ = 0;
    errorRate_.setZero();
    correctedSpanS_ = 0;
    logMatched_ = true;
}

void FootInertial::beginStretch() {
    if (log_ == nullptr || use_ != FootStretchUse::Correct || !logMatched_ ||
        stretch_ >= log_->stretches.size()) {
        return;
    }
    const FootStretchLog::Stretch& s = log_->stretches[stretch_];
    // An error the dead reckoning could have made: at most what an orientation a few degrees
    // off makes of gravity, over the stretch. More is the foot still moving at the instant
    // called still (a zero-velocity update is only as good as its stillness), not an error.
    const bool plausible =
        s.endVelocityMps.norm() <= options_.maxErrorAccelerationMps2 * s.durationS;
    if (s.durationS > 0 && s.durationS <= options_.maxCorrectedSpanS && plausible) {
        errorRate_ = s.endVelocityMps / s.durationS;
        correctedSpanS_ = s.durationS;
    }
}

void FootInertial::endStretch(const Vec3d& endVelocityMps, double durationS) {
    if (use_ == FootStretchUse::Record) {
        log_->stretches.push_back({endVelocityMps, durationS});
    } else if (logMatched_) {
        const bool known = stretch_ < log_->stretches.size();
        const double logged = known ? log_->stretches[stretch_].durationS : 0;
        if (!known || (logged < 0) != (durationS < 0) ||
            (durationS >= 0 && std::abs(logged - durationS) > 1e-9)) {
            logMatched_ = false;  // not the recorded samples: no correction from here on
        }
    }
    ++stretch_;
    errorRate_.setZero();
    correctedSpanS_ = 0;
}

void FootInertial::reset() {
    if (moving_ && log_ != nullptr) {
        endStretch(Vec3d::Zero(), -1);
    }
    moving_ = false;
    reported_.setZero();
    velocity_.setZero();
    lastAcceleration_.setZero();
    rateEnu_.setZero();
    sinceStillS_ = 0;
    quietForS_ = -1;
    still_ = false;
    started_ = false;
}

void FootInertial::add(const Quatd& qEnuSensor, const Vec3d& forceMps2, const Vec3d& rateRadS,
                       double dtS) {
    const Vec3d acceleration = qEnuSensor * forceMps2 - Vec3d(0, 0, options_.gravityMps2);
    rateEnu_ = qEnuSensor * rateRadS;
    const bool quiet = rateRadS.norm() < options_.stillRateRadS &&
                       std::abs(forceMps2.norm() - options_.gravityMps2) < options_.stillForceMps2;
    if (!quiet) {
        quietForS_ = -1;
    } else {
        quietForS_ = quietForS_ < 0 ? 0 : quietForS_ + dtS;
    }
    // The quiet run's time is measured between its samples: a run of n samples spans n - 1
    // intervals. Half an interval's slack keeps two samples at 100 Hz still for 0.01 s.
    still_ = quiet && quietForS_ + 0.5 * dtS >= options_.stillForS;
    if (still_) {
        if (moving_ && log_ != nullptr) {
            // What this sample would have integrated to: the error the update takes away.
            endStretch(velocity_ + 0.5 * (acceleration + lastAcceleration_) * dtS,
                       sinceStillS_ + dtS);
        }
        moving_ = false;
        velocity_.setZero();
        sinceStillS_ = 0;
        started_ = true;
    } else if (started_ && dtS > 0) {
        if (!moving_) {
            moving_ = true;
            beginStretch();
        }
        velocity_ += 0.5 * (acceleration + lastAcceleration_) * dtS;  // trapezoid
        sinceStillS_ += dtS;
    }
    lastAcceleration_ = acceleration;
    reported_ = velocity_ - errorRate_ * std::min(sinceStillS_, correctedSpanS_);
}

void FootInertial::turn(const Quatd& turn) {
    velocity_ = turn * velocity_;
    reported_ = turn * reported_;
    lastAcceleration_ = turn * lastAcceleration_;
    rateEnu_ = turn * rateEnu_;
    errorRate_ = turn * errorRate_;
}

void FootStateHistory::turn(const Quatd& turn) {
    for (FootSample& s : states_) {
        s.velocityEnuMps = turn * s.velocityEnuMps;
        s.rateEnuRadS = turn * s.rateEnuRadS;
    }
}

void FootStateHistory::push(const FootSample& s) {
    states_[head_] = s;
    head_ = (head_ + 1) % kSize;
    count_ = std::min(count_ + 1, kSize);
}

std::optional<FootSample> FootStateHistory::at(Timestamp t) const {
    if (count_ == 0) {
        return std::nullopt;
    }
    if (t >= newest(0).t) {
        return newest(0);
    }
    for (std::size_t k = 1; k < count_; ++k) {
        const FootSample& before = newest(k);
        if (before.t <= t) {
            const FootSample& after = newest(k - 1);
            FootSample s = before;
            // A zero-velocity update at `after` is a step, kept on its side: not interpolated.
            if (before.known && after.known && !after.still) {
                const double along = toSeconds(t - before.t) / toSeconds(after.t - before.t);
                s.velocityEnuMps += (after.velocityEnuMps - before.velocityEnuMps) * along;
                s.rateEnuRadS += (after.rateEnuRadS - before.rateEnuRadS) * along;
            }
            s.t = t;
            return s;
        }
    }
    return newest(count_ - 1);
}

}  // namespace caphub::body
