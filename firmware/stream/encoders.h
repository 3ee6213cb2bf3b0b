// The datagrams of one pose in each protocol (docs/streams.md): OSC bundles built and serialised
// with liblo. Pure functions of the pose: the stream sends what they return.
#pragma once

#include <cstdint>
#include <memory>
#include <string_view>
#include <vector>

#include "board/board.h"
#include "firmware/runtime/pose_feed.h"
#include "hal/core/time.h"

namespace caphub::firmware {

using Datagram = std::vector<std::uint8_t>;

struct EncodeContext {
    Timestamp captureStart{};   // the capture's start, on the capture clock
    Timestamp now{};            // when the datagrams are built (caphub: recorded in the frame)
    bool withSkeleton = false;  // caphub: add the skeleton's description (once a second)
};

class StreamEncoder {
public:
    virtual ~StreamEncoder() = default;
    // Appends the datagrams that carry `pose` to out (one or more OSC bundles).
    virtual void encode(const PoseFrame& pose, const EncodeContext& ctx,
                        std::vector<Datagram>& out) = 0;
};

std::unique_ptr<StreamEncoder> makeEncoder(board::StreamKind kind);

// VMC: the Unity HumanBodyBones name of each caphub segment (docs/streams.md).
std::string_view vmcBoneName(int segment);
// VRChat: the trackers' segments, 1 to 8 (hip, chest, left/right foot, left/right knee,
// left/right elbow), and the head's.
inline constexpr int kVrChatTrackers = 8;
int vrChatTrackerSegment(int tracker);  // tracker 1..8
int vrChatHeadSegment();

// The largest bundle the encoders build (VMC splits its bones over several): it fits an
// Ethernet frame with the IP and UDP headers, so no datagram is fragmented.
inline constexpr std::size_t kMaxDatagram = 1400;

}  // namespace caphub::firmware
