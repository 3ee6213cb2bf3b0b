// The poses of a running capture, for the consumers outside the pipeline thread (the live
// streams, the control plane's live view, anything else that wants the body as it moves). The
// body stage publishes each pose it solves; the feed never waits for a consumer:
// - a latest-value slot (a seqlock) that a consumer reads at its own rate (a stream at 60 Hz, a
//   web page at 30): it sees the newest pose, and skips the rest;
// - bounded queues for a consumer that wants every pose (for example a recorder of a live
//   stream): a full queue drops the pose and counts it, it never blocks the pipeline.
// Subscribing and unsubscribing are safe from any thread at any time.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <vector>

#include <Eigen/Geometry>

#include "firmware/runtime/spsc_ring.h"
#include "fusion/body/skeleton.h"
#include "hal/core/time.h"

namespace caphub::firmware {

// One solved pose, in the skeleton's world frame (docs/frames.md: Y up, right-handed, the
// subject facing +Z in the reference pose, +X their left), metres.
struct PoseFrame {
    std::uint64_t serial = 0;  // 1, 2, ... in the order solved (0: none yet)
    Timestamp t{};             // the grid time it was solved for, on the capture clock
    // The newest sample it includes (its data-ready time), and when it was published, both on
    // the capture clock: a consumer's latency is its send time minus newestSampleT.
    Timestamp newestSampleT{};
    Timestamp publishedT{};
    Eigen::Vector3f rootM = Eigen::Vector3f::Zero();  // the pelvis joint centre
    // Per segment (body::Segment order): the joint rotation (segment -> parent; the pelvis:
    // -> world) as recorded, the segment's orientation in the world, its joint centre.
    std::array<Eigen::Quaternionf, body::kSegmentCount> local;
    std::array<Eigen::Quaternionf, body::kSegmentCount> world;
    std::array<Eigen::Vector3f, body::kSegmentCount> positionM;
    // Segments not measured in this pose (bit = segment index): they hold the rotation of the
    // latest pose that measured them.
    std::uint32_t notMeasured = 0;
    bool bodyCalibrated = false;  // false: nominal mountings

    PoseFrame() {
        local.fill(Eigen::Quaternionf::Identity());
        world.fill(Eigen::Quaternionf::Identity());
        positionM.fill(Eigen::Vector3f::Zero());
    }
};

// Every pose, in order, for one consumer: a bounded single-producer single-consumer queue.
class PoseQueue {
public:
    // Consumer side: the oldest pose not yet taken.
    bool pop(PoseFrame& out) { return ring_.pop(out); }
    // Poses dropped because the queue was full.
    std::uint64_t dropped() const { return dropped_.load(std::memory_order_relaxed); }

    // Producer side (the feed).
    void push(const PoseFrame& p) {
        if (!ring_.push(p)) {
            dropped_.fetch_add(1, std::memory_order_relaxed);
        }
    }

private:
    SpscRing<PoseFrame, 256> ring_;  // 4 s at 60 Hz
    std::atomic<std::uint64_t> dropped_{0};
};

class PoseFeed {
public:
    // Pipeline thread: never blocks on a consumer.
    void publish(const PoseFrame& pose);

    // Any thread: the newest pose into out; its serial (0: none published yet, out untouched).
    std::uint64_t latest(PoseFrame& out) const;
    std::uint64_t published() const { return published_.load(std::memory_order_acquire); }

    // Waiting for the next pose without polling (a stream that sends each pose as it comes): a
    // count that changes with every pose published and every wake(). A consumer reads it, then
    // checks what it waits for (a newer pose, its own stop), then waits for the count to move
    // on from what it read: nothing published or woken in between is missed.
    std::uint32_t changes() const { return changes_.load(std::memory_order_acquire); }
    void waitForChange(std::uint32_t seen) const { changes_.wait(seen, std::memory_order_acquire); }
    // Any thread: wakes every consumer waiting (one that is asked to stop).
    void wake();

    // A queue that gets every pose published from now on, until unsubscribed.
    std::shared_ptr<PoseQueue> subscribe();
    void unsubscribe(const std::shared_ptr<PoseQueue>& queue);

private:
    using Queues = std::vector<std::shared_ptr<PoseQueue>>;

    LatestValue<PoseFrame> latest_;
    std::atomic<std::uint64_t> published_{0};
    std::atomic<std::uint32_t> changes_{0};
    // Copy on write: the pipeline takes the current list without a lock that a subscriber could
    // hold for long (an atomic shared_ptr), subscribers replace it under their own mutex.
    std::atomic<std::shared_ptr<const Queues>> queues_{std::make_shared<const Queues>()};
    std::mutex subscribeMutex_;
};

}  // namespace caphub::firmware
