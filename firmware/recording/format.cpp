#include "firmware/recording/format.h"

namespace caphub::firmware::cap {

bool isKnownType(std::uint8_t type) {
    return type >= 1 && type <= 6;
}

std::string_view typeName(RecordType type) {
    switch (type) {
        case RecordType::RawSample:
            return "raw sample";
        case RecordType::Orientation:
            return "orientation";
        case RecordType::Pose:
            return "pose";
        case RecordType::Event:
            return "event";
        case RecordType::Metadata:
            return "metadata";
        case RecordType::Marker:
            return "marker";
    }
    return "unknown";
}

std::string_view eventName(EventKind kind) {
    switch (kind) {
        case EventKind::SensorOnline:
            return "sensor online";
        case EventKind::SensorLost:
            return "sensor lost";
        case EventKind::SensorReset:
            return "sensor reset";
        case EventKind::LineSilent:
            return "data-ready line silent";
        case EventKind::Calibrated:
            return "calibrated";
        case EventKind::RecordingStopped:
            return "recording stopped";
        case EventKind::TakeStarted:
            return "take started";
        case EventKind::TakeStopped:
            return "take stopped";
        case EventKind::HeadingReset:
            return "heading reset";
        case EventKind::Command:
            return "command";
    }
    return "unknown";
}

}  // namespace caphub::firmware::cap
