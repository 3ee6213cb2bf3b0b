#include "tests/firmware/export_fixture.h"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include <toml++/toml.h>

#include "board/sim/joint_map.h"
#include "board/sim/motion.h"
#include "firmware/recording/writer.h"
#include "fusion/body/skeleton.h"

namespace caphub::firmware::testing {

namespace bs = board::sim;

namespace {

const bs::Motion& walk() {
    static const bs::Motion m = [] {
        auto clip =
            bs::loadBvh(std::filesystem::path(CAPHUB_TEST_DATA_DIR) / "bvh" / "cmu_12_01_walk.bvh");
        if (!clip) {
            throw std::runtime_error(clip.error().message);
        }
        auto motion = bs::Motion::fromClip(*clip, *bs::detectJointMap(*clip));
        if (!motion) {
            throw std::runtime_error(motion.error().message);
        }
        return std::move(motion).value();
    }();
    return m;
}

}  // namespace

std::string walkMetadata(double heightM) {
    std::ifstream in(std::filesystem::path(CAPHUB_SOURCE_DIR) / "board" / "sim-suit.toml");
    std::stringstream text;
    text << in.rdbuf();
    std::string board = text.str();
    const std::string key = "height_m = 1.75";
    const auto at = board.find(key);
    if (at == std::string::npos) {
        throw std::runtime_error("board/sim-suit.toml has no 'height_m = 1.75' any more");
    }
    board.replace(at, key.size(), "height_m = " + std::to_string(heightM));
    toml::table meta{{"recording", toml::table{{"software", "export tests"}}},
                     {"board", toml::table{{"name", "sim-suit"}, {"text", board}}}};
    std::stringstream out;
    out << meta;
    return out.str();
}

std::vector<RecordedPose> writeWalkRecording(const std::string& path,
                                             const WalkRecordingOptions& options) {
    std::filesystem::remove(path);
    auto writer = RecordingWriter::create(path, walkMetadata(options.heightM));
    if (!writer) {
        throw std::runtime_error(writer.error().message);
    }
    std::vector<RecordedPose> poses;
    const auto n = static_cast<int>(std::llround(options.seconds * options.rateHz));
    bs::SuitState state;
    const auto calibrationNs =
        options.startNs + static_cast<std::int64_t>(std::llround(options.calibrationAtS * 1e9));
    bool calibrationWritten = options.bodyCalibrationText.empty();
    for (int k = 0; k < n; ++k) {
        const auto tNs = static_cast<std::int64_t>(std::llround(k * 1e9 / options.rateHz));
        if (!calibrationWritten && options.startNs + tNs >= calibrationNs) {
            toml::table record{
                {"body_calibration", toml::table{{"text", options.bodyCalibrationText}}}};
            std::stringstream text;
            text << record;
            if ((*writer)->writeMetadata(timestampFromNs(calibrationNs), text.str()) != 0) {
                throw std::runtime_error("writeMetadata failed");
            }
            calibrationWritten = true;
        }
        walk().evaluateAll(tNs, state);
        RecordedPose p;
        p.tNs = options.startNs + tNs;
        p.rootM = state[0].positionM.cast<float>();
        for (int s = 0; s < board::kSegmentCount; ++s) {
            const auto i = static_cast<std::size_t>(s);
            p.qWorld[i] = state[i].qWorldSegment;
            const int parent = body::parentOf(s);
            const Eigen::Quaterniond local =
                parent < 0 ? state[i].qWorldSegment
                           : state[static_cast<std::size_t>(parent)].qWorldSegment.conjugate() *
                                 state[i].qWorldSegment;
            p.qLocal[i] = local.normalized().cast<float>();
        }
        if (options.withPoses) {
            const std::uint32_t held = tNs >= std::llround(options.heldFromS * 1e9) &&
                                               tNs <= std::llround(options.heldToS * 1e9)
                                           ? options.heldSegments
                                           : 0;
            if ((*writer)->writePose(timestampFromNs(p.tNs), p.rootM, p.qLocal, held) != 0) {
                throw std::runtime_error("writePose failed");
            }
        } else {
            hal::ImuSample sample;
            sample.t = timestampFromNs(p.tNs);
            if ((*writer)->writeRawSample(0, sample) != 0) {
                throw std::runtime_error("writeRawSample failed");
            }
        }
        poses.push_back(p);
    }
    if (options.extraPoseAtS && options.withPoses && !poses.empty()) {
        const RecordedPose& last = poses.back();
        const std::int64_t tNs =
            options.startNs + static_cast<std::int64_t>(std::llround(*options.extraPoseAtS * 1e9));
        auto joints = last.qLocal;
        if (options.extraPoseZero) {
            for (auto& q : joints) {
                q.coeffs().setZero();
            }
        }
        if ((*writer)->writePose(timestampFromNs(tNs), last.rootM, joints, 0) != 0) {
            throw std::runtime_error("writePose failed");
        }
    }
    if ((*writer)->close() != 0) {
        throw std::runtime_error("close failed");
    }
    return poses;
}

}  // namespace caphub::firmware::testing
