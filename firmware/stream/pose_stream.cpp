#include "firmware/stream/pose_stream.h"

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>

#include <fmt/format.h>
#include <netdb.h>
#include <sys/socket.h>
#include <unistd.h>

#include "board/stream_spec.h"
#include "hal/core/log.h"

namespace caphub::firmware {

namespace {

// The rate limit lets a frame go when the credit is at least this: a pose arriving a little
// early (the pose grid's jitter against the stream's) is not held back a whole period.
constexpr double kSendCredit = 0.9;
// How often the caphub stream repeats the skeleton's description (a receiver that joins late).
constexpr Duration kSkeletonInterval = std::chrono::seconds(1);
// How long a destination that cannot be resolved waits before trying again.
constexpr auto kResolveRetry = std::chrono::seconds(2);

}  // namespace

PoseStream::PoseStream(board::StreamConfig config, PoseFeed& feed, const Clock& clock,
                       std::function<void()> threadSetup)
    : config_(std::move(config)),
      feed_(feed),
      clock_(clock),
      threadSetup_(std::move(threadSetup)),
      encoder_(makeEncoder(config_.kind)) {}

PoseStream::~PoseStream() {
    stop();
    if (fd_ >= 0) {
        ::close(fd_);
    }
}

void PoseStream::start(Timestamp captureStart) {
    if (thread_.joinable()) {
        return;
    }
    captureStart_ = captureStart;
    stop_.store(false);
    thread_ = std::thread([this] { run(); });
}

void PoseStream::stop() {
    {
        const std::lock_guard lock(sleepMutex_);
        stop_.store(true);
    }
    sleepWake_.notify_all();
    feed_.wake();
    if (thread_.joinable()) {
        thread_.join();
    }
}

std::string PoseStream::lastError() const {
    const std::lock_guard lock(errorMutex_);
    return lastError_;
}

void PoseStream::fail(int err, const char* what) {
    errors_.fetch_add(1, std::memory_order_relaxed);
    const std::lock_guard lock(errorMutex_);
    lastError_ = fmt::format("{}: {}", what, std::strerror(err));
}

bool PoseStream::resolve() {
    addrinfo hints{};
    hints.ai_family = AF_UNSPEC;
    hints.ai_socktype = SOCK_DGRAM;
    hints.ai_flags = AI_NUMERICSERV;
    addrinfo* found = nullptr;
    const std::string port = std::to_string(config_.port);
    const int r = ::getaddrinfo(config_.host.c_str(), port.c_str(), &hints, &found);
    if (r != 0 || found == nullptr) {
        errors_.fetch_add(1, std::memory_order_relaxed);
        const std::lock_guard lock(errorMutex_);
        lastError_ = fmt::format("cannot resolve '{}': {}", config_.host, ::gai_strerror(r));
        return false;
    }
    const int fd = ::socket(found->ai_family, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
    if (fd < 0) {
        const int err = errno;
        ::freeaddrinfo(found);
        fail(err, "socket");
        return false;
    }
    // Connected, so that the kernel reports an ICMP port unreachable from the destination
    // on the next send (ECONNREFUSED), which is counted: an unconnected socket never hears it.
    const int c = ::connect(fd, found->ai_addr, found->ai_addrlen);
    const int err = errno;
    ::freeaddrinfo(found);
    if (c != 0) {
        ::close(fd);
        fail(err, "connect");
        return false;
    }
    fd_ = fd;
    return true;
}

void PoseStream::run() {
    if (threadSetup_) {
        threadSetup_();
    }
    using Steady = std::chrono::steady_clock;
    const auto period = std::chrono::duration<double>(1.0 / config_.rateHz);
    double credit = 1;
    auto creditAt = Steady::now();
    std::uint64_t lastSerial = 0;
    PoseFrame pose;
    while (true) {
        // Read the count first: a pose or a stop after it ends the wait at once.
        const std::uint32_t seen = feed_.changes();
        if (stop_.load(std::memory_order_acquire)) {
            break;
        }
        if (fd_ < 0 && !resolve()) {
            std::unique_lock lock(sleepMutex_);
            sleepWake_.wait_for(lock, kResolveRetry, [this] { return stop_.load(); });
            continue;
        }
        if (feed_.published() <= lastSerial) {
            feed_.waitForChange(seen);
            continue;
        }
        // The rate: a credit that grows at rateHz up to 2, one per frame sent.
        const auto now = Steady::now();
        credit = std::min(2.0, credit + (now - creditAt) / period);
        creditAt = now;
        if (credit < kSendCredit) {
            // Not due yet: this pose is skipped, the next one may go. Holding it until due would
            // send it late (and older than the next) when the poses come faster than the rate.
            lastSerial = feed_.published();
            continue;
        }
        lastSerial = feed_.latest(pose);
        if (lastSerial == 0) {
            continue;
        }
        credit -= 1;
        sendPose(pose);
    }
}

void PoseStream::sendPose(const PoseFrame& pose) {
    EncodeContext ctx;
    ctx.captureStart = captureStart_;
    ctx.now = clock_.now();
    ctx.withSkeleton = !skeletonSent_ || ctx.now - lastSkeleton_ >= kSkeletonInterval;
    if (ctx.withSkeleton) {
        skeletonSent_ = true;
        lastSkeleton_ = ctx.now;
    }
    buffer_.clear();
    encoder_->encode(pose, ctx, buffer_);
    bool ok = true;
    for (const Datagram& d : buffer_) {
        const ssize_t n = ::send(fd_, d.data(), d.size(), MSG_DONTWAIT | MSG_NOSIGNAL);
        if (n < 0) {
            // ECONNREFUSED: the port was unreachable for an earlier datagram (ICMP); EAGAIN: the
            // socket's buffer is full; the frame is lost to this destination only.
            fail(errno, "send");
            ok = false;
            break;
        }
        datagrams_.fetch_add(1, std::memory_order_relaxed);
    }
    if (!ok) {
        return;
    }
    sent_.fetch_add(1, std::memory_order_relaxed);
    const Duration latency = clock_.now() - pose.newestSampleT;
    const std::int64_t ns = std::max<std::int64_t>(0, latency.count());
    const auto bin = static_cast<std::size_t>(
        std::min<std::int64_t>(ns / kBinNs, static_cast<std::int64_t>(latencyBins_.size()) - 1));
    ++latencyBins_[bin];
    ++latencyCount_;
    latencyMax_ = std::max(latencyMax_, Duration{ns});
}

Duration PoseStream::latencyPercentile(double p) const {
    if (latencyCount_ == 0) {
        return Duration{0};
    }
    const auto target = static_cast<std::uint64_t>(
        std::ceil(std::clamp(p, 0.0, 1.0) * static_cast<double>(latencyCount_)));
    std::uint64_t seen = 0;
    for (std::size_t i = 0; i < latencyBins_.size(); ++i) {
        seen += latencyBins_[i];
        if (seen >= std::max<std::uint64_t>(target, 1)) {
            // The bin's upper edge (at most the largest seen).
            return std::min(Duration{static_cast<std::int64_t>(i + 1) * kBinNs}, latencyMax_);
        }
    }
    return latencyMax_;
}

}  // namespace caphub::firmware
