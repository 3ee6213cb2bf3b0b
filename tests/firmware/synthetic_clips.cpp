#include "tests/firmware/synthetic_clips.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <fstream>
#include <functional>
#include <map>
#include <numbers>
#include <sstream>
#include <vector>

#include <Eigen/Geometry>
#include <fmt/format.h>

#include "board/sim/joint_map.h"

namespace caphub::testing {

namespace {

using Eigen::AngleAxisd;
using Eigen::Matrix3d;
using Eigen::Vector2d;
using Eigen::Vector3d;

constexpr double kUnitM = board::sim::kCmuUnitM;
constexpr double kRadToDeg = 180.0 / std::numbers::pi;
constexpr double kFrameS = 1.0 / 120;

Matrix3d rx(double a) {
    return Matrix3d(AngleAxisd(a, Vector3d::UnitX()));
}
Matrix3d rz(double a) {
    return Matrix3d(AngleAxisd(a, Vector3d::UnitZ()));
}

double ease(double x) {
    return 0.5 * (1 - std::cos(std::numbers::pi * std::clamp(x, 0.0, 1.0)));
}

// Where the hips and both ankles are at one instant, in metres from where they stand at frame 0:
// forward (the clip's +z, where the knees bend to) and up.
struct LegFrame {
    Vector2d root = Vector2d::Zero();
    std::array<Vector2d, 2> ankle{Vector2d::Zero(), Vector2d::Zero()};  // left, right
    std::array<double, 2> heelUpRad{};  // each foot's pitch, heel up, from flat
};

// cmu_12_01's hierarchy, its T-pose and its legs.
class CmuRig {
public:
    explicit CmuRig(const std::filesystem::path& walkClip) {
        std::ifstream in(walkClip);
        std::string line;
        std::string joint;
        int channels = 0;
        while (std::getline(in, line) && line.find("MOTION") == std::string::npos) {
            header_ += line + "\n";
            std::istringstream words(line);
            std::string word;
            words >> word;
            if (word == "ROOT" || word == "JOINT") {
                words >> joint;
            } else if (word == "CHANNELS") {
                int n = 0;
                words >> n;
                channelOf_[joint] = channels;
                channels += n;
            }
        }
        std::getline(in, line);  // Frames:
        std::getline(in, line);  // Frame Time:
        std::getline(in, tposeLine_);
        std::istringstream values(tposeLine_);
        double v = 0;
        while (values >> v) {
            tpose_.push_back(v);
        }
        // Per leg: the straightening Z rotation of frame 0 and the straightened thigh and shin.
        const std::array<Vector3d, 2> thigh{Vector3d(2.03633, -5.59477, 0),
                                            Vector3d(-2.09328, -5.75123, 0)};
        const std::array<Vector3d, 2> shin{Vector3d(2.74354, -7.53782, 0),
                                           Vector3d(-2.65375, -7.29113, 0)};
        for (std::size_t k = 0; k < 2; ++k) {
            Leg& leg = legs_[k];
            leg.straight = tpose_[static_cast<std::size_t>(channelOf_.at(leg.up))] / kRadToDeg;
            leg.thighM = -(rz(leg.straight) * thigh[k]).y() * kUnitM;
            leg.shinM = -(rz(leg.straight) * shin[k]).y() * kUnitM;
        }
        // Each ankle stands where the shorter straight leg puts it.
        standM_ = std::min(legs_[0].thighM + legs_[0].shinM, legs_[1].thighM + legs_[1].shinM);
    }

    // The hips' height above the ankles when standing (m).
    double standM() const { return standM_; }
    // The longer leg's reach, hip to ankle (m).
    double legM() const {
        return std::max(legs_[0].thighM + legs_[0].shinM, legs_[1].thighM + legs_[1].shinM);
    }

    // The clip: frame 0 the T-pose, then `seconds` of `at(t)` at 120 Hz.
    std::string write(double seconds, const std::function<LegFrame(double)>& at) const {
        const int frames = static_cast<int>(seconds / kFrameS);
        std::string out = header_ + "MOTION\n" + fmt::format("Frames: {}\n", frames + 1) +
                          "Frame Time: .0083333\n" + tposeLine_ + "\n";
        for (int i = 0; i < frames; ++i) {
            const LegFrame p = at(i * kFrameS);
            std::vector<double> f = tpose_;
            f[1] += p.root.y() / kUnitM;
            f[2] += p.root.x() / kUnitM;
            for (std::size_t k = 0; k < 2; ++k) {
                pose(f, legs_[k], p.ankle[k] - p.root, p.heelUpRad[k]);
            }
            for (std::size_t k = 0; k < f.size(); ++k) {
                out += fmt::format("{}{:.5f}", k == 0 ? "" : " ", f[k]);
            }
            out += "\n";
        }
        return out;
    }

private:
    struct Leg {
        std::string up, knee, foot;
        double straight = 0;  // rad
        double thighM = 0, shinM = 0;
    };

    void setRotation(std::vector<double>& f, const std::string& j, const Matrix3d& r) const {
        const Vector3d zyx = r.eulerAngles(2, 1, 0);  // r = Rz Ry Rx, the channels' order
        for (int k = 0; k < 3; ++k) {
            f[static_cast<std::size_t>(channelOf_.at(j) + k)] = zyx[k] * kRadToDeg;
        }
    }

    // The leg with its ankle `fromHips` away from where it stands under the hips (forward, up):
    // the knee's flexion from the law of cosines, the hip's so that the ankle is there, the foot
    // as when standing with its heel raised by heelUpRad.
    void pose(std::vector<double>& f, const Leg& leg, const Vector2d& fromHips,
              double heelUpRad) const {
        const double forward = fromHips.x();
        const double down = standM_ - fromHips.y();
        const double reach = std::min(std::hypot(forward, down), leg.thighM + leg.shinM);
        const double c = (reach * reach - leg.thighM * leg.thighM - leg.shinM * leg.shinM) /
                         (2 * leg.thighM * leg.shinM);
        const double knee = std::acos(std::clamp(c, -1.0, 1.0));
        const double hip =
            -std::atan2(leg.shinM * std::sin(knee), leg.thighM + leg.shinM * std::cos(knee)) -
            std::atan2(forward, down);
        const Matrix3d straight = rz(leg.straight);
        const Matrix3d upWorld = rx(hip) * straight;
        const Matrix3d kneeWorld = rx(hip + knee) * straight;
        setRotation(f, leg.up, upWorld);
        setRotation(f, leg.knee, upWorld.transpose() * kneeWorld);
        setRotation(f, leg.foot, kneeWorld.transpose() * rx(heelUpRad) * straight);
    }

    std::string header_;
    std::string tposeLine_;
    std::vector<double> tpose_;
    std::map<std::string, int> channelOf_;  // joint -> its first channel
    std::array<Leg, 2> legs_{Leg{"LeftUpLeg", "LeftLeg", "LeftFoot", 0, 0, 0},
                             Leg{"RightUpLeg", "RightLeg", "RightFoot", 0, 0, 0}};
    double standM_ = 0;
};

}  // namespace

std::string jumpClip(const std::filesystem::path& walkClip) {
    const CmuRig rig(walkClip);
    // The root's height below standing (m) and the legs' reach below straight (m), by phase.
    // The legs stretch on for kSettleS after take-off, slowing to a stop, and stretch the same
    // way to meet the floor, so that the feet leave and meet it with the velocity the body
    // gives them (the simulation's smoothing would otherwise lift them before take-off).
    const double lowM = -0.25;
    const double takeoffM = -0.05;
    constexpr double kSettleS = 0.05;
    const double pushS = 2 * (takeoffM - lowM) / kJumpTakeoffMps;
    const double pushMps2 = kJumpTakeoffMps / pushS;
    const double flightS = 2 * kJumpTakeoffMps / kGravityMps2;
    const std::array<double, 6> phaseS{1.0, 0.7, pushS, flightS, pushS, 0.8};  // then 1 s
    std::array<double, 7> start{};
    for (std::size_t k = 0; k < phaseS.size(); ++k) {
        start[k + 1] = start[k] + phaseS[k];
    }
    auto between = [](double from, double to, double x) { return from + (to - from) * ease(x); };
    auto stretch = [&](double fromFloorS) {
        const double s = std::min(fromFloorS, kSettleS);
        return takeoffM + kJumpTakeoffMps * (s - s * s / (2 * kSettleS));
    };
    // The root's offset, and the legs' reach below straight: the ankles at the root's offset
    // less it (on the floor, 0).
    auto below = [&](double t) -> std::pair<double, double> {
        if (t < start[1] || t >= start[6]) {
            return {0, 0};
        }
        double r = 0;
        if (t < start[2]) {
            r = between(0, lowM, (t - start[1]) / phaseS[1]);
        } else if (t < start[3]) {
            r = lowM + 0.5 * pushMps2 * (t - start[2]) * (t - start[2]);
        } else if (t < start[4]) {
            const double f = t - start[3];
            return {takeoffM + kJumpTakeoffMps * f - 0.5 * kGravityMps2 * f * f,
                    stretch(std::min(f, start[4] - t))};
        } else if (t < start[5]) {
            r = lowM + 0.5 * pushMps2 * (start[5] - t) * (start[5] - t);
        } else {
            r = between(lowM, 0, (t - start[5]) / phaseS[5]);
        }
        return {r, r};
    };
    return rig.write(start[6] + 1.0, [&](double t) {
        const auto [rootM, legM] = below(t);
        LegFrame p;
        p.root = Vector2d(0, rootM);
        p.ankle = {Vector2d(0, rootM - legM), Vector2d(0, rootM - legM)};
        return p;
    });
}

std::string stairsClip(const std::filesystem::path& walkClip, double riseM) {
    const CmuRig rig(walkClip);
    constexpr double kStandS = 1.0;
    constexpr double kSwingS = 0.6;  // the right foot onto the next tread
    constexpr double kRaiseS = 0.9;  // the body over it; the left foot follows in its second half
    const Vector2d tread(kStairGoingM, riseM);
    // A foot's swing from a to b: forward eased, up over an arc that clears the higher tread by
    // 0.08 m; it meets the tread with no speed.
    auto swing = [](const Vector2d& a, const Vector2d& b, double x) {
        const double e = ease(x);
        const double top = std::max(a.y(), b.y()) + 0.08;
        const double up =
            x < 0.5 ? a.y() + (top - a.y()) * ease(2 * x) : top + (b.y() - top) * ease(2 * x - 1);
        return Vector2d(a.x() + (b.x() - a.x()) * e, up);
    };
    // The foot's ball from its ankle when flat (cmu_12_01's toe joint, straightened): forward,
    // up (m). The ankle of a foot standing at `ankle` with its heel raised by a, the ball kept.
    const Vector2d ballFromAnkle(0.112, -0.014);
    auto onBall = [&](const Vector2d& ankle, double a) {
        const Vector2d back = -ballFromAnkle;  // the ankle from the ball
        return Vector2d(ankle + ballFromAnkle +
                        Vector2d(back.x() * std::cos(a) + back.y() * std::sin(a),
                                 -back.x() * std::sin(a) + back.y() * std::cos(a)));
    };
    // The least heel raise (up to 70 deg) that keeps the ankle within the leg's reach of the
    // hips, the root at `root`.
    const double reachM = 0.995 * rig.legM();
    auto heelUp = [&](const Vector2d& root, const Vector2d& ankle) {
        const Vector2d hips = root + Vector2d(0, rig.standM());
        double lo = 0;
        double hi = 70 * std::numbers::pi / 180;
        if ((hips - onBall(ankle, 0)).norm() <= reachM) {
            return 0.0;
        }
        for (int i = 0; i < 40; ++i) {
            const double mid = 0.5 * (lo + hi);
            ((hips - onBall(ankle, mid)).norm() > reachM ? lo : hi) = mid;
        }
        return hi;
    };
    const double stepS = kSwingS + kRaiseS;
    const double totalS = 2 * kStandS + kStairSteps * stepS;
    return rig.write(totalS, [&](double t) {
        LegFrame p;
        const int k =
            std::clamp(static_cast<int>(std::floor((t - kStandS) / stepS)), 0, kStairSteps);
        const Vector2d from = (t < kStandS ? 0 : k) * tread;  // both feet on tread k
        p.root = from;
        p.ankle = {from, from};
        if (t < kStandS || k >= kStairSteps) {
            return p;
        }
        const double u = t - kStandS - k * stepS;
        const Vector2d to = from + tread;
        // Going down, the left knee bends while the right foot swings, the hips moving half a
        // tread ahead and down to 0.02 m below where they will stand, so that the right leg
        // reaches the lower tread as the swing ends.
        const Vector2d dip =
            riseM < 0 ? Vector2d(from + Vector2d(0.5 * kStairGoingM, riseM - 0.02)) : from;
        if (u < kSwingS) {
            p.root = from + (dip - from) * ease(u / kSwingS);
            p.ankle[1] = swing(from, to, u / kSwingS);
            return p;
        }
        const double x = (u - kSwingS) / kRaiseS;
        p.root = dip + (to - dip) * ease(x);
        p.ankle[1] = to;
        // The left heel rises as far as the hips need (the foot turning about its ball, which
        // stays on the tread) until the toe leaves at x = 0.5; it then swings up beside the right
        // one, the foot flattening.
        const double raised = heelUp(dip + (to - dip) * ease(std::min(x, 0.5)), from);
        if (x <= 0.5) {
            p.ankle[0] = onBall(from, raised);
            p.heelUpRad[0] = raised;
        } else {
            const double y = (x - 0.5) / 0.5;
            p.ankle[0] = swing(onBall(from, raised), to, y);
            p.heelUpRad[0] = raised * (1 - ease(y));
        }
        return p;
    });
}

}  // namespace caphub::testing
