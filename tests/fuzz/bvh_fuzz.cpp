// libFuzzer target for the BVH reader, and through it the joint binding, the motion fit and the
// IMU model: no input may crash, and every rejected input must say on which line.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string_view>

#include "board/sim/bvh.h"
#include "board/sim/imu_model.h"
#include "board/sim/joint_map.h"
#include "board/sim/motion.h"

namespace {

using namespace caphub;
using namespace caphub::board::sim;

// Bounds the work per input so the fuzzer explores inputs instead of fitting long clips.
constexpr std::size_t kMaxJoints = 64;
constexpr long long kMaxFrameJoints = 20000;

void drive(const BvhClip& clip, std::size_t variant) {
    if (clip.joints.empty() || clip.frameCount < 1 ||
        static_cast<long long>(clip.frameCount) * static_cast<long long>(clip.joints.size()) >
            kMaxFrameJoints ||
        clip.joints.size() > kMaxJoints) {
        return;
    }
    // What evaluate reports of the clip's truth: any clip, any frame time.
    for (const ImplausibleTurns& t : implausibleTurns(clip)) {
        if (t.frames < 1 || t.frames >= clip.frameCount || !(t.maxTurnRad >= 0)) {
            std::abort();
        }
    }
    // The first joints of the file onto the first segments: chains, names and the pelvis all
    // come from the input, so binding errors are exercised as well as successes.
    JointMap map;
    map.name = "fuzz";
    map.unitM = 0.01;
    for (std::size_t i = 0; i < clip.joints.size() && i < board::kSegmentCount; ++i) {
        map.joints[i].push_back(clip.joints[i].name);
    }
    MotionOptions options;
    const ReferencePose::Kind kinds[] = {ReferencePose::Kind::Frame, ReferencePose::Kind::Rest,
                                         ReferencePose::Kind::TPose};
    options.reference = ReferencePose{kinds[variant % 3], 0};
    options.interpolate = (variant / 3) % 2 == 0;
    options.smoothingHz = (variant / 6) % 2 == 0 ? 10 : 0;
    const auto motion = Motion::fromClip(clip, map, options);
    if (!motion) {
        return;
    }
    SuitState truth;
    const std::int64_t end = motion->durationNs();
    for (std::int64_t t : {std::int64_t{-1}, std::int64_t{0}, end / 3, end, end + 1}) {
        motion->evaluateAll(t, truth);
    }
    const auto spec = errorSpec("icm20948", ErrorProfile::Harsh);
    if (spec) {
        VirtualImu imu(*motion, environmentFor(ErrorProfile::Harsh, Vec3d(0, 1, 0)),
                       {board::Segment::Pelvis, Quatd::Identity(), Vec3d(0.1, 0, 0)}, *spec, 1, 200,
                       100);
        (void)imu.read(end / 2);
        (void)imu.read(end);
    }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const std::string_view text(reinterpret_cast<const char*>(data), size);
    const auto clip = parseBvh(text, "fuzz");
    if (!clip) {
        // A rejection must point at a line.
        if (clip.error().message.find("fuzz: line ") != 0) {
            std::abort();
        }
        return 0;
    }
    drive(*clip, size);
    return 0;
}
