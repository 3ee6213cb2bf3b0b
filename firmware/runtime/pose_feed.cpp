#include "firmware/runtime/pose_feed.h"

#include <algorithm>

namespace caphub::firmware {

void PoseFeed::publish(const PoseFrame& pose) {
    latest_.publish(pose);
    const std::shared_ptr<const Queues> queues = queues_.load(std::memory_order_acquire);
    for (const auto& q : *queues) {
        q->push(pose);
    }
    published_.store(pose.serial, std::memory_order_release);
    // A futex wake only when a consumer waits: never a wait here.
    changes_.fetch_add(1, std::memory_order_acq_rel);
    changes_.notify_all();
}

void PoseFeed::wake() {
    changes_.fetch_add(1, std::memory_order_acq_rel);
    changes_.notify_all();
}

std::uint64_t PoseFeed::latest(PoseFrame& out) const {
    if (published_.load(std::memory_order_acquire) == 0) {
        return 0;
    }
    latest_.read(out);
    return out.serial;
}

std::shared_ptr<PoseQueue> PoseFeed::subscribe() {
    auto queue = std::make_shared<PoseQueue>();
    const std::lock_guard lock(subscribeMutex_);
    auto next = std::make_shared<Queues>(*queues_.load(std::memory_order_acquire));
    next->push_back(queue);
    queues_.store(std::move(next), std::memory_order_release);
    return queue;
}

void PoseFeed::unsubscribe(const std::shared_ptr<PoseQueue>& queue) {
    const std::lock_guard lock(subscribeMutex_);
    auto next = std::make_shared<Queues>(*queues_.load(std::memory_order_acquire));
    next->erase(std::remove(next->begin(), next->end(), queue), next->end());
    queues_.store(std::move(next), std::memory_order_release);
}

}  // namespace caphub::firmware
