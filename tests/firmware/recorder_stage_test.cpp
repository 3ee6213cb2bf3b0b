// The recorder stage: what a capture's recording holds, and how it ends.
#include "firmware/runtime/recorder_stage.h"

#include <filesystem>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <unistd.h>

#include "firmware/recording/reader.h"

namespace caphub::firmware {
namespace {

namespace fs = std::filesystem;

std::string tempPath(const std::string& name) {
    const fs::path dir = fs::path(::testing::TempDir()) / "caphub-recorder-stage-test";
    fs::create_directories(dir);
    const fs::path p = dir / (name + "-" + std::to_string(::getpid()) + ".cap");
    fs::remove(p);
    return p.string();
}

struct EventSeen {
    cap::EventKind kind{};
    int sensor = 0;
    int error = 0;
    std::string text;
    Timestamp t{};
};

TEST(RecorderStage, ARecordingThatRanToItsEndEndsWithARecordingStoppedEvent) {
    const std::string path = tempPath("end");
    {
        auto w = RecordingWriter::create(path, "");
        ASSERT_TRUE(w.ok()) << w.error().message;
        RecorderStage stage(std::move(*w));
        for (int i = 0; i < 10; ++i) {
            SensorSample s;
            s.sensor = i % 2;
            s.sample.t = timestampFromNs(1'000'000'000 + i * 5'000'000LL);
            stage.onSample(s);
        }
        RuntimeEvent lost;
        lost.kind = RuntimeEvent::Kind::SensorLost;
        lost.sensor = 1;
        lost.t = timestampFromNs(1'050'000'000);
        lost.error = -ENXIO;
        stage.onEvent(lost);
        stage.finish(timestampFromNs(1'060'000'000));
        EXPECT_EQ(stage.error(), 0);
        EXPECT_EQ(stage.writer().stats().records, 12u);  // 10 samples, 2 events
    }
    auto r = RecordingReader::open(path);
    ASSERT_TRUE(r.ok()) << r.error().message;
    RecordView v;
    int records = 0;
    std::vector<EventSeen> events;
    while ((*r)->next(v) == 1) {
        ++records;
        EventSeen e;
        if (decodeEvent(v, e.kind, e.sensor, e.error, e.text)) {
            e.t = v.t;
            events.push_back(e);
        }
    }
    EXPECT_EQ(records, 12);
    ASSERT_EQ(events.size(), 2u);
    EXPECT_EQ(events[0].kind, cap::EventKind::SensorLost);
    EXPECT_EQ(events[1].kind, cap::EventKind::RecordingStopped);
    EXPECT_EQ(events[1].sensor, -1);
    EXPECT_EQ(events[1].error, 0);
    EXPECT_EQ(events[1].text, "end of capture");
    EXPECT_EQ(events[1].t, timestampFromNs(1'060'000'000));
}

}  // namespace
}  // namespace caphub::firmware
