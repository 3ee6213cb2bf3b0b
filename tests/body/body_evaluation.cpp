#include "tests/body/body_evaluation.h"

#include <cmath>

#include <fmt/format.h>

#include "board/loader.h"
#include "board/sim/bvh.h"
#include "board/sim/joint_map.h"
#include "board/sim/motion.h"
#include "fusion/body/body_solver.h"

namespace caphub::body::evaluation {

namespace bs = board::sim;

Result<ClipScore> scoreClip(const std::filesystem::path& bvh, const std::filesystem::path& suit,
                            double rateHz, double speed) {
    auto clip = bs::loadBvh(bvh);
    if (!clip) {
        return clip.error();
    }
    const bs::JointMap* map = bs::detectJointMap(*clip);
    if (map == nullptr) {
        return Error{EINVAL, fmt::format("{}: no built-in joint map fits", bvh.string())};
    }
    auto motion = bs::Motion::fromClip(*clip, *map);
    if (!motion) {
        return motion.error();
    }
    auto board = board::loadBoardFile(suit);
    if (!board.ok()) {
        return Error{EINVAL, fmt::format("{}: {}", suit.string(),
                                         board.errors.empty() ? "invalid" : board.errors[0].str())};
    }
    SegmentMask mask = 0;
    std::array<Quatd, kSegmentCount> mounting;
    mounting.fill(Quatd::Identity());
    for (const auto& s : board.board->sensors) {
        mask |= bit(s.segment);
        mounting[static_cast<std::size_t>(idx(s.segment))] = s.mounting;
    }

    // The subject's measured skeleton: each bone vector in its parent's frame, averaged over the
    // clip (segments made of several BVH joints are not perfectly rigid).
    board::SubjectConfig subject;
    Dimensions d = *dimensionsFromSubject(subject);
    const int n = motion->frameCount();
    for (int i = 1; i < kSegmentCount; ++i) {
        const auto s = static_cast<Segment>(i);
        const auto p = static_cast<Segment>(parentOf(i));
        Vec3d sum = Vec3d::Zero();
        for (int f = 0; f < n; ++f) {
            sum += motion->keyOrientation(p, f).conjugate() *
                   (motion->keyPositionM(s, f) - motion->keyPositionM(p, f));
        }
        d.offsetM[static_cast<std::size_t>(i)] = sum / n;
    }
    for (int foot = 0; foot < 2; ++foot) {
        const Vec3d ball = d.offsetM[static_cast<std::size_t>(
            idx(foot == 0 ? Segment::LMiddistal : Segment::RMiddistal))];
        const Vec3d horiz(ball.x(), 0, ball.z());
        auto& fp = foot == 0 ? d.leftFootPointM : d.rightFootPointM;
        fp[0] = Vec3d(0, ball.y(), 0) - 0.3 * horiz;  // heel: behind the ankle
        fp[1] = ball;
        fp[2] = ball + 0.4 * horiz;  // toe tip
    }
    const Skeleton skeleton(d);

    const Quatd qEnuWorld = enuFromSkeletonWorld();
    SensorFrame tpose;
    tpose.mask = mask;
    for (int i = 0; i < kSegmentCount; ++i) {
        tpose.qEnuSensor[static_cast<std::size_t>(i)] =
            qEnuWorld * mounting[static_cast<std::size_t>(i)];
    }
    CalibrationOptions copt;
    copt.nominalMounting = mounting;
    auto cal = calibrateOnePose(ReferencePoseKind::T, tpose, copt);
    if (!cal) {
        return cal.error();
    }
    BodySolver solver(skeleton, mask);
    solver.setCalibration(*cal);

    bs::SuitState truth;
    ClipScore score;
    score.clip = bvh.filename().string();
    score.rateHz = rateHz;
    score.speed = speed;
    const double dt = 1.0 / rateHz;
    const auto durationNs = motion->durationNs();
    Vec3d lastTrueRoot = Vec3d::Zero();
    int frames = 0;
    for (std::int64_t k = 0;; ++k) {
        const auto tNs =
            static_cast<std::int64_t>(std::llround(static_cast<double>(k) * dt * speed * 1e9));
        if (tNs > durationNs) {
            break;
        }
        motion->evaluateAll(tNs, truth);
        SensorFrame f;
        f.mask = mask;
        for (int i = 0; i < kSegmentCount; ++i) {
            const auto u = static_cast<std::size_t>(i);
            f.qEnuSensor[u] = qEnuWorld * truth[u].qWorldSegment * mounting[u];
        }
        const Vec3d trueRoot = truth[0].positionM;
        if (k == 0) {
            solver.resetRoot(trueRoot.x(), trueRoot.z());
        } else {
            score.walkedM +=
                std::hypot(trueRoot.x() - lastTrueRoot.x(), trueRoot.z() - lastTrueRoot.z());
        }
        lastTrueRoot = trueRoot;
        const Pose& pose = solver.solve(f, dt);
        for (int i = 0; i < kSegmentCount; ++i) {
            const auto u = static_cast<std::size_t>(i);
            const Quatd trueLocal =
                i == 0 ? truth[0].qWorldSegment
                       : truth[static_cast<std::size_t>(parentOf(i))].qWorldSegment.conjugate() *
                             truth[u].qWorldSegment;
            score.angleDeg[u] += angleBetween(trueLocal, pose.qLocal[u]) * 180 / M_PI;
            score.positionM[u] +=
                ((pose.positionM[u] - pose.positionM[0]) - (truth[u].positionM - trueRoot)).norm();
        }
        const double drift =
            std::hypot(pose.positionM[0].x() - trueRoot.x(), pose.positionM[0].z() - trueRoot.z());
        score.finalDriftM = drift;
        score.maxDriftM = std::max(score.maxDriftM, drift);
        ++frames;
    }
    score.frames = frames;
    for (int i = 0; i < kSegmentCount; ++i) {
        const auto u = static_cast<std::size_t>(i);
        score.angleDeg[u] /= frames;
        score.positionM[u] /= frames;
        score.meanAngleDeg += score.angleDeg[u] / kSegmentCount;
        if (i > 0) {
            score.meanPositionM += score.positionM[u] / (kSegmentCount - 1);
        }
    }
    score.stanceChanges = solver.rootTracker().stanceChanges();
    return score;
}

std::string formatTable(const ClipScore& s) {
    std::string out = fmt::format("clip {}: {} frames at {} Hz{}\n\n", s.clip, s.frames, s.rateHz,
                                  s.speed != 1.0 ? fmt::format(", played {}x", s.speed) : "");
    out += "| joint | segment | angle error (deg) | position error (cm) |\n|---|---|---|---|\n";
    for (int i = 0; i < kSegmentCount; ++i) {
        const auto u = static_cast<std::size_t>(i);
        out += fmt::format("| {} | {} | {:.3f} | {:.3f} |\n", joints()[u].name,
                           board::segmentName(static_cast<Segment>(i)), s.angleDeg[u],
                           s.positionM[u] * 100);
    }
    out +=
        fmt::format("| **mean** | | {:.3f} | {:.3f} |\n\n", s.meanAngleDeg, s.meanPositionM * 100);
    out += fmt::format(
        "root: true horizontal path {:.3f} m, final drift {:.3f} m ({:.2f} %), max drift {:.3f} m, "
        "{} stance changes\n",
        s.walkedM, s.finalDriftM, s.walkedM > 0 ? 100 * s.finalDriftM / s.walkedM : 0.0,
        s.maxDriftM, s.stanceChanges);
    return out;
}

}  // namespace caphub::body::evaluation
