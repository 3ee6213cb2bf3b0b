#include "tests/body/body_evaluation.h"

#include <cmath>
#include <vector>

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

    // The subject's measured skeleton, from the clip's key frames.
    const int n = motion->frameCount();
    std::vector<BodyTruth> keys(static_cast<std::size_t>(n));
    for (int f = 0; f < n; ++f) {
        for (int i = 0; i < kSegmentCount; ++i) {
            const auto s = static_cast<Segment>(i);
            keys[static_cast<std::size_t>(f)].qWorldSegment[static_cast<std::size_t>(i)] =
                motion->keyOrientation(s, f);
            keys[static_cast<std::size_t>(f)].positionM[static_cast<std::size_t>(i)] =
                motion->keyPositionM(s, f);
        }
    }
    const Skeleton skeleton(measuredDimensions(keys));

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
    PoseScorer scorer;
    const double dt = 1.0 / rateHz;
    const auto durationNs = motion->durationNs();
    for (std::int64_t k = 0;; ++k) {
        const auto tNs =
            static_cast<std::int64_t>(std::llround(static_cast<double>(k) * dt * speed * 1e9));
        if (tNs > durationNs) {
            break;
        }
        motion->evaluateAll(tNs, truth);
        SensorFrame f;
        f.mask = mask;
        BodyTruth t;
        for (int i = 0; i < kSegmentCount; ++i) {
            const auto u = static_cast<std::size_t>(i);
            f.qEnuSensor[u] = qEnuWorld * truth[u].qWorldSegment * mounting[u];
            t.qWorldSegment[u] = truth[u].qWorldSegment;
            t.positionM[u] = truth[u].positionM;
        }
        if (k == 0) {
            solver.resetRoot(t.positionM[0].x(), t.positionM[0].z());
        }
        scorer.add(solver.solve(f, dt), t);
    }
    const auto scored = scorer.score();
    if (!scored) {
        return Error{EINVAL, bvh.string() + ": the clip is too short to score a single pose"};
    }
    ClipScore score;
    static_cast<PoseScore&>(score) = *scored;
    score.clip = bvh.filename().string();
    score.rateHz = rateHz;
    score.speed = speed;
    score.stanceChanges = solver.rootTracker().stanceChanges();
    return score;
}

std::string formatTable(const ClipScore& s) {
    return fmt::format("clip {}: {} frames at {} Hz{}\n\n", s.clip, s.frames, s.rateHz,
                       s.speed != 1.0 ? fmt::format(", played {}x", s.speed) : "") +
           formatScoreTable(s);
}

}  // namespace caphub::body::evaluation
