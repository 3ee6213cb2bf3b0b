#include "firmware/runtime/pipeline.h"

namespace caphub::firmware {

bool Pipeline::post(std::function<void(Timestamp)> fn) {
    std::lock_guard lock(postedMutex_);
    if (finished_) {
        return false;
    }
    posted_.push_back(std::move(fn));
    postedPending_.store(true, std::memory_order_release);
    return true;
}

int Pipeline::runPosted(Timestamp now) {
    if (!postedPending_.load(std::memory_order_acquire)) {
        return 0;
    }
    std::vector<std::function<void(Timestamp)>> work;
    {
        std::lock_guard lock(postedMutex_);
        work.swap(posted_);
        postedPending_.store(false, std::memory_order_relaxed);
    }
    for (auto& fn : work) {
        fn(now);
    }
    return static_cast<int>(work.size());
}

void Pipeline::finish(Timestamp now) {
    {
        std::lock_guard lock(postedMutex_);
        finished_ = true;  // from here on post() refuses; what was queued runs now
    }
    postedPending_.store(true, std::memory_order_relaxed);
    (void)runPosted(now);
    for (auto* stage : stages_) {
        stage->finish(now);
    }
}

}  // namespace caphub::firmware
