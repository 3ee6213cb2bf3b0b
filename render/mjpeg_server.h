// The preview as an MJPEG stream over HTTP (multipart/x-mixed-replace): any browser or
// `ffplay http://hub:8080/stream` shows it. Bound to 127.0.0.1 unless configured otherwise.
#pragma once

#include <cstdint>
#include <memory>
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
