// libFuzzer target: the .cap reader on arbitrary bytes must never crash, never loop forever,
// and never hand out a record that fails its own decoding rules.
#include <cstdint>
#include <cstdlib>
#include <span>
#include <string>
#include <vector>

#include "firmware/recording/reader.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    using namespace caphub::firmware;
    auto reader = RecordingReader::fromMemory(std::span(data, size));
    if (!reader.ok()) {
        return 0;
    }
    RecordView v;
    std::size_t records = 0;
    std::uint64_t lastOffset = 0;
    while ((*reader)->next(v) == 1) {
        // Records come in file order and lie inside the input.
        if ((records > 0 && v.offset <= lastOffset) || v.offset + v.payload.size() > size) {
            std::abort();
        }
        lastOffset = v.offset;
        ++records;
        int sensor = 0;
        caphub::hal::ImuSample sample;
        Eigen::Quaternionf q;
        Eigen::Vector3f root;
        std::vector<Eigen::Quaternionf> joints;
        cap::EventKind kind{};
        int error = 0;
        std::string text;
        (void)decodeRawSample(v, sensor, sample);
        (void)decodeOrientation(v, sensor, q);
        (void)decodePose(v, root, joints);
        (void)decodeEvent(v, kind, sensor, error, text);
    }
    return 0;
}
