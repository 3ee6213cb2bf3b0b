#include "fusion/body/pose_score.h"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

namespace caphub::body {

namespace {

bool segmentMeasured(std::uint32_t measured, int segment) {
    return ((measured >> segment) & 1U) != 0;
}

}  // namespace

bool independentJointMeasured(std::uint32_t measured, std::size_t j) {
    const IndependentJoint& ij = independentJoints()[j];
    return segmentMeasured(measured, ij.distal) &&
           (ij.proximal < 0 || segmentMeasured(measured, ij.proximal));
}

void PoseScorer::add(const Pose& solved, const BodyTruth& truth) {
    const Vec3d& trueRoot = truth.positionM[0];
    if (!lastTrueRootM_) {
        firstTrueRootM_ = trueRoot;
        heightOffsetM_ = trueRoot.y() - solved.positionM[0].y();
        if (origin_ == RootOrigin::AtFirstFrame) {
            rootOffsetM_ = trueRoot - solved.positionM[0];
            rootOffsetM_.y() = 0;
        }
    } else {
        sum_.walkedM +=
            std::hypot(trueRoot.x() - lastTrueRootM_->x(), trueRoot.z() - lastTrueRootM_->z());
    }
    lastTrueRootM_ = trueRoot;
    sum_.excursionM = std::max(sum_.excursionM, std::hypot(trueRoot.x() - firstTrueRootM_.x(),
                                                           trueRoot.z() - firstTrueRootM_.z()));
    for (int i = 0; i < kSegmentCount; ++i) {
        const auto u = static_cast<std::size_t>(i);
        const Quatd trueLocal =
            i == 0 ? truth.qWorldSegment[0]
                   : truth.qWorldSegment[static_cast<std::size_t>(parentOf(i))].conjugate() *
                         truth.qWorldSegment[u];
        sum_.angleDeg[u] += angleBetween(trueLocal, solved.qLocal[u]) * 180 / M_PI;
        sum_.positionM[u] +=
            ((solved.positionM[u] - solved.positionM[0]) - (truth.positionM[u] - trueRoot)).norm();
    }
    for (std::size_t j = 0; j < independentJoints().size(); ++j) {
        const IndependentJoint& ij = independentJoints()[j];
        const auto d = static_cast<std::size_t>(ij.distal);
        Quatd trueRot = truth.qWorldSegment[d];
        Quatd solvedRot = solved.qWorld[d];
        if (ij.proximal >= 0) {
            const auto p = static_cast<std::size_t>(ij.proximal);
            trueRot = truth.qWorldSegment[p].conjugate() * trueRot;
            solvedRot = solved.qWorld[p].conjugate() * solvedRot;
        }
        sum_.independentAngleDeg[j] += angleBetween(trueRot, solvedRot) * 180 / M_PI;
    }
    const Vec3d root = solved.positionM[0] + rootOffsetM_;
    const double drift = std::hypot(root.x() - trueRoot.x(), root.z() - trueRoot.z());
    sum_.finalDriftM = drift;
    sum_.maxDriftM = std::max(sum_.maxDriftM, drift);
    const double height = std::abs(solved.positionM[0].y() + heightOffsetM_ - trueRoot.y());
    sum_.meanHeightErrorM += height;
    sum_.maxHeightErrorM = std::max(sum_.maxHeightErrorM, height);
    ++sum_.frames;
}

std::optional<PoseScore> PoseScorer::score() const {
    PoseScore s = sum_;
    if (s.frames == 0) {
        return std::nullopt;
    }
    s.meanAngleDeg = 0;
    s.meanPositionM = 0;
    s.meanHeightErrorM /= s.frames;
    s.measuredJoints = 0;
    int positions = 0;
    for (int i = 0; i < kSegmentCount; ++i) {
        const auto u = static_cast<std::size_t>(i);
        s.angleDeg[u] /= s.frames;
        s.positionM[u] /= s.frames;
        if (!segmentMeasured(s.measured, i)) {
            continue;
        }
        s.meanAngleDeg += s.angleDeg[u];
        ++s.measuredJoints;
        if (i > 0) {
            s.meanPositionM += s.positionM[u];
            ++positions;
        }
    }
    s.meanAngleDeg /= std::max(1, s.measuredJoints);
    s.meanPositionM /= std::max(1, positions);
    s.independentMeanAngleDeg = 0;
    s.independentMeanPositionM = 0;
    s.measuredIndependentJoints = 0;
    positions = 0;
    for (std::size_t j = 0; j < independentJoints().size(); ++j) {
        s.independentAngleDeg[j] /= s.frames;
        // A joint's centre is a segment origin: its error is that segment's row.
        s.independentPositionM[j] =
            s.positionM[static_cast<std::size_t>(independentJoints()[j].centre)];
        if (!independentJointMeasured(s.measured, j)) {
            continue;
        }
        s.independentMeanAngleDeg += s.independentAngleDeg[j];
        ++s.measuredIndependentJoints;
        if (independentJoints()[j].proximal >= 0) {
            s.independentMeanPositionM += s.independentPositionM[j];
            ++positions;
        }
    }
    s.independentMeanAngleDeg /= std::max(1, s.measuredIndependentJoints);
    s.independentMeanPositionM /= std::max(1, positions);
    return s;
}

namespace {
// Toes measured closer to the ankle than this: the clip has none.
constexpr double kNoToesM = 0.01;
}  // namespace

Dimensions measuredDimensions(const std::vector<BodyTruth>& frames) {
    const Dimensions model = *dimensionsFromSubject(board::SubjectConfig{});
    Dimensions d = model;
    if (frames.empty()) {
        return d;
    }
    const auto n = static_cast<double>(frames.size());
    for (int i = 1; i < kSegmentCount; ++i) {
        const auto s = static_cast<std::size_t>(i);
        const auto p = static_cast<std::size_t>(parentOf(i));
        Vec3d sum = Vec3d::Zero();
        for (const BodyTruth& f : frames) {
            sum += f.qWorldSegment[p].conjugate() * (f.positionM[s] - f.positionM[p]);
        }
        d.offsetM[s] = sum / n;
    }
    for (int foot = 0; foot < 2; ++foot) {
        const auto toes =
            static_cast<std::size_t>(idx(foot == 0 ? Segment::LMiddistal : Segment::RMiddistal));
        auto& fp = foot == 0 ? d.leftFootPointM : d.rightFootPointM;
        if (d.offsetM[toes].norm() < kNoToesM) {
            // A clip with no toes (the Daz release: the foot ends at the ankle's end site) says
            // nothing of the foot's shape; the subject still has one: the default subject's
            // foot, scaled with the measured leg. Left at the ankle, all three contact points
            // would be one point and the foot could not roll from heel to toe.
            const Segment thigh = foot == 0 ? Segment::LThigh : Segment::RThigh;
            const Segment calf = foot == 0 ? Segment::LCalf : Segment::RCalf;
            const auto leg = [&](const Dimensions& dims) {  // hip to ankle
                return segmentLengthM(dims, thigh) + segmentLengthM(dims, calf);
            };
            const double k = leg(d) / leg(model);
            d.offsetM[toes] = model.offsetM[toes] * k;
            const auto& modelFoot = foot == 0 ? model.leftFootPointM : model.rightFootPointM;
            for (std::size_t i = 0; i < fp.size(); ++i) {
                fp[i] = modelFoot[i] * k;
            }
            continue;
        }
        const Vec3d ball = d.offsetM[toes];
        const Vec3d horiz(ball.x(), 0, ball.z());
        fp[0] = Vec3d(0, ball.y(), 0) - 0.3 * horiz;  // heel: behind the ankle
        fp[1] = ball;
        fp[2] = ball + 0.4 * horiz;  // toe tip
    }
    setCentresOfMass(d);
    return d;
}

namespace {

// A row whose segment the suit does not measure: its error is the held pose's against the truth.
constexpr const char* kHeld = " (not measured)";

// The mean's label says over how many joints it is when the suit does not measure them all.
std::string measuredNote(int joints, int of) {
    return joints == of ? std::string() : fmt::format(" of the {} measured", joints);
}

}  // namespace

std::string formatScoreTable(const PoseScore& s) {
    std::string out =
        "| joint | segment | angle error (deg) | position error (cm) |\n|---|---|---|---|\n";
    for (int i = 0; i < kSegmentCount; ++i) {
        const auto u = static_cast<std::size_t>(i);
        out += fmt::format("| {}{} | {} | {:.3f} | {:.3f} |\n", joints()[u].name,
                           segmentMeasured(s.measured, i) ? "" : kHeld,
                           board::segmentName(static_cast<Segment>(i)), s.angleDeg[u],
                           s.positionM[u] * 100);
    }
    out += fmt::format("| **mean**{} | | {:.3f} | {:.3f} |\n\n",
                       measuredNote(s.measuredJoints, kSegmentCount), s.meanAngleDeg,
                       s.meanPositionM * 100);
    out +=
        "the paper's 17 joints (lumbar and cervical as whole rotations, no toes):\n\n"
        "| joint | from - to | angle error (deg) | position error (cm) |\n|---|---|---|---|\n";
    for (std::size_t j = 0; j < independentJoints().size(); ++j) {
        const IndependentJoint& ij = independentJoints()[j];
        out += fmt::format(
            "| {}{} | {} - {} | {:.3f} | {:.3f} |\n", ij.name,
            independentJointMeasured(s.measured, j) ? "" : kHeld,
            ij.proximal < 0 ? "world" : board::segmentName(static_cast<Segment>(ij.proximal)),
            board::segmentName(static_cast<Segment>(ij.distal)), s.independentAngleDeg[j],
            s.independentPositionM[j] * 100);
    }
    out += fmt::format("| **mean**{} | | {:.3f} | {:.3f} |\n\n",
                       measuredNote(s.measuredIndependentJoints, kIndependentJointCount),
                       s.independentMeanAngleDeg, s.independentMeanPositionM * 100);
    // A path of a few millimetres (jumping on the spot) makes no meaningful percentage.
    const std::string percent =
        s.walkedM >= 0.05 ? fmt::format(" ({:.2f} %)", 100 * s.finalDriftM / s.walkedM) : "";
    const std::string stances =
        s.stanceChanges >= 0 ? fmt::format(", {} stance changes", s.stanceChanges) : "";
    out += fmt::format(
        "root: true horizontal path {:.3f} m, final drift {:.3f} m{}, max drift {:.3f} m{}; "
        "height error mean {:.3f} m, max {:.3f} m\n",
        s.walkedM, s.finalDriftM, percent, s.maxDriftM, stances, s.meanHeightErrorM,
        s.maxHeightErrorM);
    if (!rootTranslationMeasured(s.measured)) {
        out +=
            "root translation: not measured (the suit has no sensor on both feet: the root stays "
            "where the held legs put it)\n";
    }
    return out;
}

}  // namespace caphub::body
