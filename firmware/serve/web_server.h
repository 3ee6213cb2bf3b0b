// `caphub serve`'s HTTP side: the JSON API on a running Hub, its live state and poses as
// Server-Sent Events, the MJPEG preview, downloads of takes and their exports made on demand,
// and the web page (docs/serve.md). It runs on cpp-httplib's threads and never holds up the
// capture: commands go through the Hub (which carries them out between two batches of samples),
// the state is read by one thread of its own a few times a second and served from there to every
// client, and poses come from the pose feed's latest-value slot.
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>

#include "board/board.h"
#include "firmware/runtime/hub.h"
#include "hal/core/error.h"
#include "render/mjpeg_server.h"

namespace caphub::firmware::serve {

class SensorCalibrationSession;

struct WebOptions {
    std::string host = "127.0.0.1";  // anything else needs a password (docs/serve.md)
    int port = 8080;                 // 0: any free port (see WebServer::port())
    std::filesystem::path recordings;
    std::filesystem::path stateDir;  // the password's hash
    std::filesystem::path webRoot;   // index.html, app.js, style.css
    std::filesystem::path threeRoot = "/usr/share/javascript/three";  // Debian's libjs-three
    std::string version;
    std::string sensorCalibration;  // the calibration file applied (empty: none), for the state
    // The guided sensor calibration (null: not offered). Not owned.
    SensorCalibrationSession* calibrationSession = nullptr;
    // Bounds: HTTP worker threads; of them at most maxStreams held by streams (events, poses,
    // MJPEG) at once, so that requests are always served; request bodies; socket timeouts. One
    // request per connection (no keep-alive: an idle connection would hold a thread).
    int threads = 24;
    int maxStreams = 12;
    // Of the workers, at most maxDownloads held by downloads (a take, an export): a client that
    // reads a download slowly holds its worker for as long as it keeps reading, and without a
    // bound such clients could hold them all.
    int maxDownloads = 6;
    std::size_t maxBodyBytes = 16 * 1024;
    int timeoutS = 5;
    // A request (line, headers and body) must arrive within this of its connection's accept: a
    // client sending it a byte at a time would otherwise hold a worker for as long as it likes.
    double requestTimeoutS = 10;
    double stateHz = 4;                              // how often the state is read from the Hub
    double poseHz = 30;                              // poses per second on /api/poses
    std::shared_ptr<render::JpegFrameSlot> preview;  // null: no preview
};

class WebServer {
public:
    // Errors: EPERM for a non-loopback host with no password set, EINVAL for bad options,
    // EADDRINUSE when the address cannot be bound.
    static Result<std::unique_ptr<WebServer>> start(Hub& hub, const board::Board& board,
                                                    WebOptions options);
    ~WebServer();
    WebServer(const WebServer&) = delete;
    WebServer& operator=(const WebServer&) = delete;

    int port() const;
    // Stops serving: open streams end within a second.
    void stop();

    struct State;

private:
    WebServer();
    std::unique_ptr<State> s_;
};

// Where the page's files are: $CAPHUB_WEB_DIR, the data folder's web/ (installed), or
// firmware/web in the source tree; empty when none holds index.html.
std::filesystem::path defaultWebRoot();

}  // namespace caphub::firmware::serve
