// A foot sensor's velocity by dead reckoning from the foot's latest still instant: its
// accelerometer, turned into the world by its filter and less gravity, integrated, and set to
// zero whenever the foot is still (a zero-velocity update). Over the short spans it is used for
// (a planted foot rolling off after its still mid-stance) it measures what the foot contacts
// cannot: the planted foot slipping (docs/skeleton.md, "The planted foot's slip").
#pragma once

#include <array>
#include <cstddef>
#include <optional>
#include <vector>

#include "fusion/body/skeleton.h"
#include "hal/core/time.h"

namespace caphub::body {

struct FootInertialOptions {
    // Still: the rate below stillRateRadS and the specific force within stillForceMps2 of
    // gravity, on consecutive samples spanning at least stillForS (at 100 Hz: two samples).
    double stillRateRadS = 0.7;
    double stillForceMps2 = 0.7;
    double stillForS = 0.01;
    // The velocity is trusted for this long after the latest still instant (s): a stance's roll
    // off the floor, not a swing (the accelerometer's errors grow with the square of the time).
    double maxSpanS = 0.6;
    // Whether the foot moves or stands (faster than a swing, slower than a planted foot) is
    // told from the velocity for this long after the latest still instant (s): a swing down a
    // stair or a long stride is longer than maxSpanS, and to tell a swing from a foot at rest
    // the velocity need only be right to a few tenths of a metre a second.
    double maxKnownSpanS = 1.5;
    double gravityMps2 = 9.81;
    // Offline: a stretch's recorded error is taken off along it when the stretch is at most
    // this long (s). Its error grows with the square of the time as the orientation's error
    // grows; over a stride the linear part (the accelerometer's bias, the tilt's error at the
    // start) dominates, over seconds not.
    double maxCorrectedSpanS = 2.0;
    // ... and when its error is one the integration could have made: at most this acceleration
    // over the stretch (m/s^2). 0.5: gravity read 3 deg off (9.81 sin 3 deg = 0.51), beyond the
    // filters' tilt on a limb in motion; a larger end velocity over a short stretch is the foot
    // still moving (turning on its sole: 0.7 rad/s at 0.1 m is 0.07 m/s) at the instant the
    // update called still.
    double maxErrorAccelerationMps2 = 0.5;
};

// What each of a foot's stretches between still instants ended with: the velocity the
// zero-velocity update at its end took away (the integration's error, as the foot was still),
// and the stretch's length. Offline (`caphub reprocess --smooth`) one pass over a take records
// them and the next pass, fed the same samples and orientations, takes each stretch's error off
// along it (docs/reprocess.md, "The feet between their still instants").
struct FootStretchLog {
    struct Stretch {
        Vec3d endVelocityMps = Vec3d::Zero();
        double durationS = -1;  // < 0: cut short by a reset (no still instant ended it)
    };
    std::vector<Stretch> stretches;
};

enum class FootStretchUse { Record, Correct };

class FootInertial {
public:
    explicit FootInertial(const FootInertialOptions& options = {}) : options_(options) {}

    // One sample: the sensor's orientation (sensor -> ENU), its specific force (m/s^2) and rate
    // (rad/s) in the sensor frame, dtS after the foot's previous sample.
    void add(const Quatd& qEnuSensor, const Vec3d& forceMps2, const Vec3d& rateRadS, double dtS);
    // Forget the motion (a sensor lost, a new capture): invalid until the foot is still again.
    void reset();
    // The sensor's orientations turned by `turn` (ENU, on the left) from now on: what was
    // integrated in the old frame is carried into the new one.
    void turn(const Quatd& turn);
    // Offline: record each stretch's end into `log`, or take the errors it recorded off the
    // velocity, the error of a stretch growing linearly from its start (a constant acceleration
    // error: a bias, a tilt) to its end. A stretch whose length differs from the recorded one
    // (not the same samples) stops the corrections. `log` outlives the dead reckoning.
    void useStretchLog(FootStretchLog* log, FootStretchUse use);
    // Correct: whether the stretches met so far matched the log.
    bool stretchLogMatched() const { return logMatched_; }

    // Integrated from a still instant no longer than maxSpanS ago.
    bool valid() const { return started_ && sinceStillS_ <= options_.maxSpanS; }
    // Integrated from a still instant no longer than maxKnownSpanS ago.
    bool known() const { return started_ && sinceStillS_ <= options_.maxKnownSpanS; }
    bool still() const { return still_; }
    // The sensor's velocity (m/s) and rate (rad/s) in ENU at the latest sample: with them, the
    // velocity of any point of the rigid foot.
    const Vec3d& velocityEnuMps() const { return reported_; }
    const Vec3d& rateEnuRadS() const { return rateEnu_; }

private:
    void beginStretch();
    void endStretch(const Vec3d& endVelocityMps, double durationS);

    FootInertialOptions options_;
    Vec3d velocity_ = Vec3d::Zero();
    Vec3d reported_ = Vec3d::Zero();  // velocity_ less the stretch's error so far (Correct)
    Vec3d lastAcceleration_ = Vec3d::Zero();
    Vec3d rateEnu_ = Vec3d::Zero();
    double sinceStillS_ = 0;
    double quietForS_ = -1;  // how long the samples have been quiet; < 0: the latest was not
    bool still_ = false;
    bool started_ = false;  // a still instant since the reset
    bool moving_ = false;   // a sample in motion since the latest still instant

    FootStretchLog* log_ = nullptr;
    FootStretchUse use_ = FootStretchUse::Record;
    std::size_t stretch_ = 0;          // the stretch the foot is in (or the next one)
    Vec3d errorRate_ = Vec3d::Zero();  // the stretch's recorded error per second
    double correctedSpanS_ = 0;        // its recorded length (0: no correction)
    bool logMatched_ = true;
};

// A foot's dead reckoning as it stood after one of its samples.
struct FootSample {
    Timestamp t{};
    bool valid = false;
    bool known = false;
    bool still = false;
    Vec3d velocityEnuMps = Vec3d::Zero();
    Vec3d rateEnuRadS = Vec3d::Zero();
};

// The states after a foot's latest samples (a ring of 8), to take the foot at a time just
// before its newest sample: a pose's grid time, which the watermark solves up to a sample
// interval later.
class FootStateHistory {
public:
    static constexpr std::size_t kSize = 8;
    void push(const FootSample& s);
    void clear() { count_ = 0; }
    // Every held state's vectors turned (ENU, on the left), as FootInertial::turn.
    void turn(const Quatd& turn);
    // The state at t: the velocity and rate interpolated between the samples around it (the
    // still flag and validity of the one at or before t; not interpolated towards a still one,
    // whose zero velocity is a step), the oldest held when t is before them all, the newest
    // when after. Empty when there is none.
    std::optional<FootSample> at(Timestamp t) const;

private:
    const FootSample& newest(std::size_t k) const {  // 0: the newest
        return states_[(head_ + kSize - 1 - k) % kSize];
    }
    std::array<FootSample, kSize> states_;
    std::size_t head_ = 0;  // where the next goes
    std::size_t count_ = 0;
};

}  // namespace caphub::body
