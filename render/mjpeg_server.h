// The preview as an MJPEG stream over HTTP (multipart/x-mixed-replace): any browser or
// `ffplay http://hub:8080/stream` shows it. Bound to 127.0.0.1 unless configured otherwise.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "hal/core/error.h"
#include "render/image.h"

namespace caphub::render {

// JPEG compression with libturbojpeg (4:2:0, fast DCT).
class JpegEncoder {
public:
    JpegEncoder();
    ~JpegEncoder();
    JpegEncoder(const JpegEncoder&) = delete;
    JpegEncoder& operator=(const JpegEncoder&) = delete;
    Result<void> encode(const Image& image, int quality, std::vector<std::uint8_t>& out);

private:
    void* handle_ = nullptr;
};

// The latest preview frame as a JPEG, for a server that is not this one (`caphub serve`'s): the
// renderer publishes, any number of HTTP threads read the newest or wait for the next. Encoding
// happens once per frame on the publishing thread; readers share the bytes.
class JpegFrameSlot {
public:
    explicit JpegFrameSlot(int quality = 80) : quality_(quality) {}
    Result<void> publish(const Image& image);
    // The newest frame (null: none yet) and its sequence number (1, 2, ...).
    std::shared_ptr<const std::vector<std::uint8_t>> latest(std::uint64_t* sequence) const;
    // Waits up to `timeoutMs` for a frame newer than `sequence`; false on timeout or close().
    bool waitNewer(std::uint64_t sequence, int timeoutMs) const;
    // Wakes every waiter for good (the server is stopping).
    void close();

private:
    int quality_;
    JpegEncoder encoder_;  // the publishing thread's
    mutable std::mutex mutex_;
    mutable std::condition_variable cv_;
    std::shared_ptr<const std::vector<std::uint8_t>> jpeg_;
    std::uint64_t sequence_ = 0;
    bool closed_ = false;
};

struct MjpegOptions {
    std::string host = "127.0.0.1";  // "0.0.0.0" to serve other machines
    int port = 8080;                 // 0: any free port (see MjpegServer::port())
    int quality = 80;                // JPEG quality 1-100
    // Viewers of /stream at once; one more is answered 503 at once. Each holds a server thread
    // for as long as it watches, so the pool has these plus kRequestThreads for everything else
    // (a page, /frame.jpg), and an idle or slow connection is dropped after a few seconds: a
    // full house of viewers and any number of idle sockets never stop a request being served.
    int maxStreams = 4;
};

// Serves GET /stream (the MJPEG stream), GET /frame.jpg (the latest frame) and GET / (a page
// showing the stream). Frames published while no client listens cost one JPEG encoding.
class MjpegServer {
public:
    static constexpr int kRequestThreads = 8;
    static constexpr int kIdleTimeoutS = 2;  // reading a request, keep-alive, writing
    static Result<std::unique_ptr<MjpegServer>> start(const MjpegOptions& options);
    ~MjpegServer();
    MjpegServer(const MjpegServer&) = delete;
    MjpegServer& operator=(const MjpegServer&) = delete;

    int port() const;
    Result<void> publish(const Image& image);
    std::uint64_t framesPublished() const;
    int streamsWatching() const;

private:
    MjpegServer();
    struct State;
    std::unique_ptr<State> s_;
};

}  // namespace caphub::render
