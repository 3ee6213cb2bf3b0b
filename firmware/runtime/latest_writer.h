// A thread that writes the latest of what a producer publishes: the pipeline thread only hands a
// copy over (the status snapshot, the magnetometer estimates) and never waits for a disk; a
// publication that comes while the last one is being written replaces the one pending.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <functional>
#include <mutex>
#include <thread>
#include <utility>

#include "firmware/runtime/thread_policy.h"

namespace caphub::firmware {

template <typename T>
class LatestWriter {
public:
    // write: called on the writer thread with each value it takes. threadName: the thread's name
    // (at most 15 characters); it runs at the default policy, not the realtime one a pipeline
    // thread may have.
    LatestWriter(const char* threadName, std::function<void(const T&)> write)
        : write_(std::move(write)), thread_([this, threadName] {
              (void)applyToThisThread(ThreadPolicy{}, threadName);
              loop();
          }) {}
    ~LatestWriter() {
        {
            std::lock_guard lock(mutex_);
            stopping_ = true;
        }
        wake_.notify_all();
        if (thread_.joinable()) {
            thread_.join();
        }
    }
    LatestWriter(const LatestWriter&) = delete;
    LatestWriter& operator=(const LatestWriter&) = delete;

    // Hands `value` to the writer (any thread).
    void publish(T value) {
        {
            std::lock_guard lock(mutex_);
            latest_ = std::move(value);
            ++published_;
        }
        wake_.notify_one();
    }
    // Waits until everything published so far is written.
    void flush() {
        std::unique_lock lock(mutex_);
        const std::uint64_t target = published_;
        done_.wait(lock, [&] { return written_ >= target || stopping_; });
    }
    // The last value published (any thread).
    T latest() const {
        std::lock_guard lock(mutex_);
        return latest_;
    }
    // Values published so far (any thread); a value published while another is being written
    // replaces the one pending, so fewer may be written.
    std::uint64_t published() const {
        std::lock_guard lock(mutex_);
        return published_;
    }
    // Values written so far (any thread).
    std::uint64_t written() const {
        std::lock_guard lock(mutex_);
        return written_;
    }

private:
    void loop() {
        std::uint64_t seen = 0;
        std::unique_lock lock(mutex_);
        for (;;) {
            wake_.wait(lock, [&] { return stopping_ || published_ != seen; });
            if (published_ == seen) {
                return;  // stopping, and everything published is written
            }
            seen = published_;
            const T value = latest_;
            lock.unlock();
            write_(value);
            lock.lock();
            written_ = seen;
            done_.notify_all();
        }
    }

    std::function<void(const T&)> write_;
    mutable std::mutex mutex_;
    std::condition_variable wake_;
    std::condition_variable done_;
    T latest_{};
    std::uint64_t published_ = 0;
    std::uint64_t written_ = 0;
    bool stopping_ = false;
    std::thread thread_;  // last: it starts once everything above is set
};

}  // namespace caphub::firmware
