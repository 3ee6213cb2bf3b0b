#include "render/mjpeg_server.h"

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <mutex>
#include <thread>

#include <fmt/format.h>
#include <httplib.h>
#include <turbojpeg.h>

namespace caphub::render {

namespace {
constexpr const char* kBoundary = "caphubframe";
}

JpegEncoder::JpegEncoder() : handle_(tjInitCompress()) {}

JpegEncoder::~JpegEncoder() {
    if (handle_) {
        tjDestroy(static_cast<tjhandle>(handle_));
    }
}

Result<void> JpegEncoder::encode(const Image& image, int quality, std::vector<std::uint8_t>& out) {
    if (!handle_) {
        return Error{ENOMEM, "libturbojpeg: no compressor"};
    }
    unsigned char* buf = nullptr;
    unsigned long size = 0;
    if (tjCompress2(static_cast<tjhandle>(handle_), image.rgb.data(), image.width, 0, image.height,
                    TJPF_RGB, &buf, &size, TJSAMP_420, quality, TJFLAG_FASTDCT) != 0) {
        const std::string why = tjGetErrorStr2(static_cast<tjhandle>(handle_));
        tjFree(buf);
        return Error{
            EIO, fmt::format("JPEG encoding of a {}x{} frame: {}", image.width, image.height, why)};
    }
    out.assign(buf, buf + size);
    tjFree(buf);
    return {};
}

Result<void> JpegFrameSlot::publish(const Image& image) {
    auto jpeg = std::make_shared<std::vector<std::uint8_t>>();
    if (auto ok = encoder_.encode(image, quality_, *jpeg); !ok) {
        return ok;
    }
    {
        std::lock_guard lock(mutex_);
        jpeg_ = std::move(jpeg);
        ++sequence_;
    }
    cv_.notify_all();
    return {};
}

std::shared_ptr<const std::vector<std::uint8_t>> JpegFrameSlot::latest(
    std::uint64_t* sequence) const {
    std::lock_guard lock(mutex_);
    if (sequence != nullptr) {
        *sequence = sequence_;
    }
    return jpeg_;
}

bool JpegFrameSlot::waitNewer(std::uint64_t sequence, int timeoutMs) const {
    std::unique_lock lock(mutex_);
    return cv_.wait_for(lock, std::chrono::milliseconds(timeoutMs), [&] {
        return closed_ || sequence_ != sequence;
    }) && !closed_;
}

void JpegFrameSlot::close() {
    {
        std::lock_guard lock(mutex_);
        closed_ = true;
    }
    cv_.notify_all();
}

struct MjpegServer::State {
    httplib::Server server;
    std::thread thread;
    int port = 0;
    int quality = 80;
    JpegEncoder encoder;
    std::mutex mutex;
    std::condition_variable cv;
    std::shared_ptr<const std::vector<std::uint8_t>> jpeg;  // the latest frame
    std::uint64_t sequence = 0;
    bool stopping = false;
    int maxStreams = 4;
    std::atomic<int> streams{0};
};

MjpegServer::MjpegServer() : s_(std::make_unique<State>()) {}

MjpegServer::~MjpegServer() {
    {
        std::lock_guard lock(s_->mutex);
        s_->stopping = true;
    }
    s_->cv.notify_all();
    s_->server.stop();
    if (s_->thread.joinable()) {
        s_->thread.join();
    }
}

Result<std::unique_ptr<MjpegServer>> MjpegServer::start(const MjpegOptions& options) {
    if (options.quality < 1 || options.quality > 100) {
        return Error{EINVAL, fmt::format("MJPEG quality {}: expected 1 to 100", options.quality)};
    }
    if (options.port < 0 || options.port > 65535) {
        return Error{EINVAL, fmt::format("MJPEG port {}: expected 0 to 65535", options.port)};
    }
    if (options.maxStreams < 1 || options.maxStreams > 64) {
        return Error{EINVAL, fmt::format("MJPEG viewers {}: expected 1 to 64", options.maxStreams)};
    }
    std::unique_ptr<MjpegServer> m(new MjpegServer);
    State* s = m->s_.get();
    s->quality = options.quality;
    s->maxStreams = options.maxStreams;
    // httplib's default pool (8 threads) was taken by eight viewers or eight idle sockets, and
    // every further request waited forever: threads for the viewers and for the requests, and
    // short timeouts for connections that send or take nothing.
    const auto threads = static_cast<std::size_t>(options.maxStreams + kRequestThreads);
    s->server.new_task_queue = [threads] { return new httplib::ThreadPool(threads); };
    s->server.set_read_timeout(kIdleTimeoutS, 0);
    s->server.set_write_timeout(kIdleTimeoutS, 0);
    s->server.set_keep_alive_timeout(kIdleTimeoutS);
    s->server.set_keep_alive_max_count(20);
    s->server.set_payload_max_length(64 * 1024);  // nothing here takes a body

    s->server.Get("/", [](const httplib::Request&, httplib::Response& res) {
        res.set_content(
            "<!doctype html><title>caphub preview</title>"
            "<img src=\"/stream\" alt=\"caphub preview\">",
            "text/html");
    });
    s->server.Get("/frame.jpg", [s](const httplib::Request&, httplib::Response& res) {
        std::shared_ptr<const std::vector<std::uint8_t>> jpeg;
        {
            std::lock_guard lock(s->mutex);
            jpeg = s->jpeg;
        }
        if (!jpeg) {
            res.status = 503;
            res.set_content("no frame yet\n", "text/plain");
            return;
        }
        res.set_content(reinterpret_cast<const char*>(jpeg->data()), jpeg->size(), "image/jpeg");
    });
    s->server.Get("/stream", [s](const httplib::Request&, httplib::Response& res) {
        if (s->streams.fetch_add(1) >= s->maxStreams) {
            s->streams.fetch_sub(1);
            res.status = 503;
            res.set_header("Retry-After", "5");
            res.set_content(fmt::format("{} viewers already watch the preview; try /frame.jpg\n",
                                        s->maxStreams),
                            "text/plain");
            return;
        }
        auto last = std::make_shared<std::uint64_t>(0);
        res.set_chunked_content_provider(
            fmt::format("multipart/x-mixed-replace; boundary={}", kBoundary),
            [s, last](std::size_t, httplib::DataSink& sink) {
                std::shared_ptr<const std::vector<std::uint8_t>> jpeg;
                {
                    std::unique_lock lock(s->mutex);
                    // Wake at least every second so that a stop or a dead client is noticed.
                    s->cv.wait_for(lock, std::chrono::seconds(1),
                                   [&] { return s->stopping || s->sequence != *last; });
                    if (s->stopping) {
                        return false;
                    }
                    if (s->sequence == *last || !s->jpeg) {
                        return sink.is_writable();
                    }
                    *last = s->sequence;
                    jpeg = s->jpeg;
                }
                const std::string head =
                    fmt::format("--{}\r\nContent-Type: image/jpeg\r\nContent-Length: {}\r\n\r\n",
                                kBoundary, jpeg->size());
                return sink.write(head.data(), head.size()) &&
                       sink.write(reinterpret_cast<const char*>(jpeg->data()), jpeg->size()) &&
                       sink.write("\r\n", 2);
            },
            [s](bool) { s->streams.fetch_sub(1); });
    });

    // SO_REUSEADDR only: httplib's default adds SO_REUSEPORT, which would let a second server
    // share a taken port silently instead of reporting it.
    s->server.set_socket_options([](socket_t sock) {
        int yes = 1;
        setsockopt(sock, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof yes);
    });
    if (options.port == 0) {
        s->port = s->server.bind_to_any_port(options.host);
    } else {
        s->port = s->server.bind_to_port(options.host, options.port) ? options.port : -1;
    }
    if (s->port <= 0) {
        return Error{EADDRINUSE, fmt::format("MJPEG server: cannot bind {}:{} (port taken or "
                                             "address not local)",
                                             options.host, options.port)};
    }
    s->thread = std::thread([s] { s->server.listen_after_bind(); });
    // stop() is a no-op until the listener runs: wait for it, so that a server destroyed at
    // once still shuts down.
    for (int i = 0; i < 2000 && !s->server.is_running(); ++i) {
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    return m;
}

int MjpegServer::port() const {
    return s_->port;
}

int MjpegServer::streamsWatching() const {
    return s_->streams.load();
}

std::uint64_t MjpegServer::framesPublished() const {
    std::lock_guard lock(s_->mutex);
    return s_->sequence;
}

Result<void> MjpegServer::publish(const Image& image) {
    auto jpeg = std::make_shared<std::vector<std::uint8_t>>();
    if (auto ok = s_->encoder.encode(image, s_->quality, *jpeg); !ok) {
        return ok;
    }
    {
        std::lock_guard lock(s_->mutex);
        s_->jpeg = std::move(jpeg);
        ++s_->sequence;
    }
    s_->cv.notify_all();
    return {};
}

}  // namespace caphub::render
