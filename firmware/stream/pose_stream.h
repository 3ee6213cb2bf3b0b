// A live stream of the body's poses to one destination (VMC, VRChat OSC, caphub's own;
// docs/streams.md): its own thread, woken by each pose the Hub's PoseFeed publishes, sends the
// newest at most at its rate, as UDP datagrams that never block. A destination that is down or
// refuses costs a failed send, counted; never the capture.
#pragma once

#include <atomic>
#include <condition_variable>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "board/board.h"
#include "firmware/runtime/pose_feed.h"
#include "firmware/stream/encoders.h"
#include "hal/core/clock.h"

namespace caphub::firmware {

class PoseStream {
public:
    // `threadSetup` runs first on the stream's thread (its name and scheduling); may be empty.
    PoseStream(board::StreamConfig config, PoseFeed& feed, const Clock& clock,
               std::function<void()> threadSetup = {});
    ~PoseStream();
    PoseStream(const PoseStream&) = delete;
    PoseStream& operator=(const PoseStream&) = delete;

    // Starts the thread; captureStart is the capture's start on its clock (VMC's time is from it).
    void start(Timestamp captureStart);
    // Stops and joins the thread (at once: it never waits for the network).
    void stop();

    const board::StreamConfig& config() const { return config_; }
    // Frames sent (every datagram of a pose went out), sends that failed (a frame with any
    // datagram refused counts once), and the last failure (empty: none).
    std::uint64_t sent() const { return sent_.load(std::memory_order_relaxed); }
    std::uint64_t errors() const { return errors_.load(std::memory_order_relaxed); }
    std::uint64_t datagrams() const { return datagrams_.load(std::memory_order_relaxed); }
    std::string lastError() const;
    // The latency from the newest sample in a pose (its data-ready time) to the pose's last
    // datagram handed to the kernel, on the capture clock; over the frames sent. After stop().
    Duration latencyPercentile(double p) const;
    Duration latencyMax() const { return latencyMax_; }

private:
    void run();
    bool resolve();
    void sendPose(const PoseFrame& pose);
    void fail(int err, const char* what);

    board::StreamConfig config_;
    PoseFeed& feed_;
    const Clock& clock_;
    std::function<void()> threadSetup_;
    std::unique_ptr<StreamEncoder> encoder_;
    Timestamp captureStart_{};
    std::thread thread_;
    std::atomic<bool> stop_{false};
    std::mutex sleepMutex_;
    std::condition_variable sleepWake_;

    int fd_ = -1;
    std::vector<Datagram> buffer_;
    Timestamp lastSkeleton_{};
    bool skeletonSent_ = false;

    std::atomic<std::uint64_t> sent_{0};
    std::atomic<std::uint64_t> errors_{0};
    std::atomic<std::uint64_t> datagrams_{0};
    mutable std::mutex errorMutex_;
    std::string lastError_;
    // Latency histogram: 10 us bins up to 100 ms, the last bin everything above.
    static constexpr std::int64_t kBinNs = 10'000;
    std::vector<std::uint32_t> latencyBins_ = std::vector<std::uint32_t>(10'001, 0);
    std::uint64_t latencyCount_ = 0;
    Duration latencyMax_{0};
};

}  // namespace caphub::firmware
