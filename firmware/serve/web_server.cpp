// WebServer: starting and stopping the HTTP server; the routes are in web_*_routes.cpp
// (web_state.h).
#include "firmware/serve/web_server.h"

#include <cmath>

#include <fmt/format.h>
#include <sys/socket.h>

#include "firmware/cli/data_dir.h"
#include "firmware/serve/web_state.h"

namespace caphub::firmware::serve {

namespace fs = std::filesystem;

WebServer::WebServer() = default;

WebServer::~WebServer() {
    stop();
}

void WebServer::stop() {
    if (!s_) {
        return;
    }
    {
        std::lock_guard lock(s_->mutex);
        if (s_->stopping) {
            return;
        }
        s_->stopping = true;
    }
    s_->cv.notify_all();
    if (s_->options.preview) {
        s_->options.preview->close();
    }
    s_->server.stop();
    if (s_->listener.joinable()) {
        s_->listener.join();
    }
    if (s_->stateReader.joinable()) {
        s_->stateReader.join();
    }
}

int WebServer::port() const {
    return s_->port;
}

Result<std::unique_ptr<WebServer>> WebServer::start(Hub& hub, const board::Board& board,
                                                    WebOptions options) {
    if (options.port < 0 || options.port > 65535) {
        return Error{EINVAL, fmt::format("port {}: expected 0 to 65535", options.port)};
    }
    if (options.threads < 4 || options.maxStreams < 1 || options.maxDownloads < 1 ||
        options.maxStreams + options.maxDownloads > options.threads - 2) {
        return Error{EINVAL,
                     fmt::format("expected at least 4 threads, one stream and one download, and "
                                 "at most threads - 2 streams and downloads together ({} + {} of "
                                 "{} threads)",
                                 options.maxStreams, options.maxDownloads, options.threads)};
    }
    if (!(options.requestTimeoutS >= 0.001 && options.requestTimeoutS <= 3600)) {
        return Error{EINVAL, "expected a request timeout of 0.001 to 3600 s"};
    }
    const bool password = hasPassword(options.stateDir);
    if (!isLoopbackHost(options.host) && !password) {
        return Error{EPERM, fmt::format("listening on {} (not this machine only) needs a password: "
                                        "set one with `caphub serve --set-password --state-dir "
                                        "{}` first",
                                        options.host, options.stateDir.string())};
    }
    std::unique_ptr<WebServer> w(new WebServer);
    w->s_ = std::make_unique<State>(hub, board, std::move(options));
    State* s = w->s_.get();
    s->passwordRequired = password;
    {
        // Exports left by a server that was killed mid-download.
        std::error_code ec;
        fs::remove_all(s->options.stateDir / "exports", ec);
    }
    const int threads = s->options.threads;
    s->server.new_task_queue = [threads] {
        return new httplib::ThreadPool(static_cast<std::size_t>(threads));
    };
    s->server.set_read_timeout(s->options.timeoutS, 0);
    s->server.set_write_timeout(s->options.timeoutS, 0);
    s->server.setRequestTimeout(std::chrono::milliseconds(
        static_cast<long long>(std::llround(s->options.requestTimeoutS * 1000))));
    // One request per connection: an idle keep-alive connection holds a worker thread until it
    // times out, and 24 such clients would leave none for anyone else.
    s->server.set_keep_alive_max_count(1);
    s->server.set_payload_max_length(s->options.maxBodyBytes);
    // A POST with neither a length nor chunks has no body (RFC 9112 6.3), but the HTTP library
    // waits for one until its read timeout (5 s), then answers 400: say what is missing at once.
    s->server.set_pre_routing_handler([](const httplib::Request& req, httplib::Response& res) {
        const bool body = req.method == "POST" || req.method == "PUT" || req.method == "PATCH";
        if (body && !req.has_header("Content-Length") && !req.has_header("Transfer-Encoding")) {
            fail(res, 411, "a request body needs its Content-Length (0 for none)");
            return httplib::Server::HandlerResponse::Handled;
        }
        // One range a request: 500 overlapping ranges of a 4.5 KB header made the library send a
        // take 500 times over (and its multipart answers state a total length of 0). A suffix of
        // no bytes (bytes=-0) is unsatisfiable, which the library answered 206 with nothing.
        if (req.ranges.size() > 1 ||
            (req.ranges.size() == 1 && req.ranges[0].first < 0 && req.ranges[0].second == 0)) {
            fail(res, 416, "one range of bytes at a time, of at least one byte");
            // The library applies a request's ranges to any answer, this one too (101 ranges of
            // the error made an 18 KB reply). The request is the library's own non-const object,
            // handed over as const: clearing its ranges is allowed.
            const_cast<httplib::Request&>(req).ranges.clear();
            return httplib::Server::HandlerResponse::Handled;
        }
        return httplib::Server::HandlerResponse::Unhandled;
    });
    // Errors the HTTP layer answers itself (an unknown route, a body too large, a request it
    // cannot read) carry {"error": ...} like every other: they came with an empty body.
    s->server.set_error_handler([](const httplib::Request& req, httplib::Response& res) {
        if (!res.body.empty()) {
            return;
        }
        const std::string what =
            res.status == 404   ? fmt::format("no such route: {} {}", req.method, req.path)
            : res.status == 413 ? std::string("the request body is over its limit")
            : res.status == 400 ? std::string("the request could not be read")
                                : fmt::format("HTTP {}", res.status);
        fail(res, res.status, what);
    });
    s->server.set_exception_handler(
        [](const httplib::Request&, httplib::Response& res, std::exception_ptr ep) {
            std::string what = "unknown";
            try {
                std::rethrow_exception(ep);
            } catch (const std::exception& e) {
                what = e.what();
            } catch (...) {
            }
            fail(res, 500, "internal error: " + what);
        });
    // SO_REUSEADDR only: httplib's default adds SO_REUSEPORT, which would let a second server
    // share a taken port silently instead of reporting it.
    s->server.set_socket_options([s](socket_t sock) {
        int yes = 1;
        setsockopt(sock, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof yes);
        s->listenSocket = sock;
    });
    s->sessionRoutes();
    s->liveRoutes();
    s->commandRoutes();
    s->takeRoutes();
    s->sensorCalibrationRoutes();
    if (s->options.port == 0) {
        s->port = s->server.bind_to_any_port(s->options.host);
    } else {
        s->port = s->server.bind_to_port(s->options.host, s->options.port) ? s->options.port : -1;
    }
    if (s->port <= 0) {
        return Error{EADDRINUSE, fmt::format("cannot listen on {}:{} (port taken or address not "
                                             "local)",
                                             s->options.host, s->options.port)};
    }
    // Debian's libcpp-httplib listens with a backlog of 5: 50 clients connecting at once would
    // have their SYNs dropped and retried a second later. listen() again only raises it.
    if (s->listenSocket >= 0) {
        (void)::listen(s->listenSocket, 128);
    }
    // The first state document is built before any request can come: an early client (the
    // page loading as the hub starts) never gets an empty one.
    s->stateJson =
        s->buildState(s->hub.state()).dump(-1, ' ', false, Json::error_handler_t::replace);
    s->stateReader = std::thread([s] { s->readStateLoop(); });
    s->listener = std::thread([s] { s->server.listen_after_bind(); });
    for (int i = 0; i < 2000 && !s->server.is_running(); ++i) {
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    return w;
}

fs::path defaultWebRoot() {
    std::vector<fs::path> candidates;
    if (const char* env = std::getenv("CAPHUB_WEB_DIR"); env != nullptr && *env != '\0') {
        candidates.emplace_back(env);
    }
    for (const auto& d : dataDirCandidates()) {
        candidates.push_back(d / "web");
        candidates.push_back(d / "firmware" / "web");
    }
    for (const auto& c : candidates) {
        std::error_code ec;
        if (fs::is_regular_file(c / "index.html", ec)) {
            return c;
        }
    }
    return {};
}

}  // namespace caphub::firmware::serve
