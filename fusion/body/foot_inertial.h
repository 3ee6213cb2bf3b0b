// A foot sensor's velocity by dead reckoning from the foot's latest still instant: its
// accelerometer, turned into the world by its filter and less gravity, integrated, and set to
// zero whenever the foot is still (a zero-velocity update). Over the short spans it is used for
// (a planted foot rolling off after its still mid-stance) it measures what the foot contacts
// cannot: the planted foot slipping (docs/skeleton.md, "The planted foot's slip").
#pragma once

#include <array>
#include <cstddef>
#include <optional>

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
};

class FootInertial {
public:
    explicit FootInertial(const FootInertialOptions& options = {}) : options_(options) {}

    // One sample: the sensor's orientation (sensor -> ENU), its specific force (m/s^2) and rate
    // (rad/s) in the sensor frame, dtS after the foot's previous sample.
    void add(const Quatd& qEnuSensor, const Vec3d& forceMps2, const Vec3d& rateRadS, double dtS);
    // Forget the motion (a sensor lost, a new capture): invalid until the foot is still again.
    void reset();

    // Integrated from a still instant no longer than maxSpanS ago.
    bool valid() const { return started_ && sinceStillS_ <= options_.maxSpanS; }
    // Integrated from a still instant no longer than maxKnownSpanS ago.
    bool known() const { return started_ && sinceStillS_ <= options_.maxKnownSpanS; }
    bool still() const { return still_; }
    // The sensor's velocity (m/s) and rate (rad/s) in ENU at the latest sample: with them, the
    // velocity of any point of the rigid foot.
    const Vec3d& velocityEnuMps() const { return velocity_; }
    const Vec3d& rateEnuRadS() const { return rateEnu_; }

private:
    FootInertialOptions options_;
    Vec3d velocity_ = Vec3d::Zero();
    Vec3d lastAcceleration_ = Vec3d::Zero();
    Vec3d rateEnu_ = Vec3d::Zero();
    double sinceStillS_ = 0;
    double quietForS_ = -1;  // how long the samples have been quiet; < 0: the latest was not
    bool still_ = false;
    bool started_ = false;  // a still instant since the reset
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
