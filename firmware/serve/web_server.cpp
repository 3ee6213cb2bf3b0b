#include "firmware/serve/web_server.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <condition_variable>
#include <fstream>
#include <map>
#include <mutex>
#include <set>
#include <sstream>
#include <thread>

#include <fmt/format.h>
#include <httplib.h>
#include <nlohmann/json.hpp>

#include "firmware/cli/data_dir.h"
#include "firmware/cli/info.h"
#include "firmware/export/export.h"
#include "firmware/serve/auth.h"
#include "firmware/serve/takes.h"
#include "fusion/body/skeleton.h"
#include "hal/core/log.h"

namespace caphub::firmware::serve {

namespace fs = std::filesystem;
using Json = nlohmann::ordered_json;
using SteadyClock = std::chrono::steady_clock;

namespace {

constexpr const char* kSessionCookie = "caphub_session";
constexpr const char* kCsrfHeader = "X-CSRF-Token";
constexpr const char* kBoundary = "caphubframe";
// An SSE comment: keeps a quiet stream writing, so that a client gone is noticed.
constexpr std::string_view kIdle = ": idle\n\n";

void reply(httplib::Response& res, int status, const Json& body) {
    res.status = status;
    res.set_header("Cache-Control", "no-store");
    res.set_content(body.dump(), "application/json");
}

void fail(httplib::Response& res, int status, const std::string& message) {
    reply(res, status, Json{{"error", message}});
}

// The HTTP status for an error of a Hub command or a file operation.
int statusFor(const Error& e) {
    switch (e.code) {
        case EINVAL:
            return 400;
        case EPERM:
        case EACCES:
            return 403;
        case ENOENT:
            return 404;
        case ESRCH:
        case ETIMEDOUT:
        case EBUSY:
            return 503;
        default:
            return 500;
    }
}

std::string cookieValue(const httplib::Request& req, const std::string& name) {
    const std::string header = req.get_header_value("Cookie");
    std::size_t pos = 0;
    while (pos < header.size()) {
        const std::size_t end = std::min(header.find(';', pos), header.size());
        std::string item = header.substr(pos, end - pos);
        const std::size_t first = item.find_first_not_of(' ');
        item = first == std::string::npos ? "" : item.substr(first);
        if (item.size() > name.size() && item.compare(0, name.size(), name) == 0 &&
            item[name.size()] == '=') {
            return item.substr(name.size() + 1);
        }
        pos = end + 1;
    }
    return {};
}

// The host part of a Host header ("127.0.0.1:8080", "[::1]:8080", "localhost").
std::string hostOf(const std::string& header) {
    if (header.starts_with('[')) {
        const auto close = header.find(']');
        return close == std::string::npos ? header : header.substr(1, close - 1);
    }
    return header.substr(0, header.find(':'));
}

std::string readFile(const fs::path& p, bool& ok) {
    std::ifstream in(p, std::ios::binary);
    std::stringstream s;
    s << in.rdbuf();
    ok = static_cast<bool>(in);
    return s.str();
}

// Streams a file in 64 KiB pieces; `removeAfter` deletes it when the response is done.
void streamFile(httplib::Response& res, const fs::path& path, const std::string& mime,
                const std::string& downloadName, bool removeAfter) {
    std::error_code ec;
    const auto size = fs::file_size(path, ec);
    auto in = std::make_shared<std::ifstream>(path, std::ios::binary);
    if (ec || !*in) {
        fail(res, 500, fmt::format("cannot read '{}'", downloadName));
        if (removeAfter) {
            fs::remove(path, ec);
        }
        return;
    }
    res.set_header("Content-Disposition", fmt::format("attachment; filename=\"{}\"", downloadName));
    res.set_header("Cache-Control", "no-store");
    res.set_content_provider(
        static_cast<std::size_t>(size), mime,
        [in](std::size_t offset, std::size_t length, httplib::DataSink& sink) {
            std::vector<char> buf(std::min<std::size_t>(length, 64 * 1024));
            in->seekg(static_cast<std::streamoff>(offset));
            in->read(buf.data(), static_cast<std::streamsize>(buf.size()));
            const auto n = static_cast<std::size_t>(in->gcount());
            return n > 0 && sink.write(buf.data(), n);
        },
        [path, removeAfter](bool) {
            if (removeAfter) {
                std::error_code e;
                fs::remove(path, e);
            }
        });
}

const char* mimeOf(exporter::Format f) {
    switch (f) {
        case exporter::Format::Glb:
            return "model/gltf-binary";
        case exporter::Format::Csv:
            return "text/csv";
        default:
            return "text/plain";
    }
}

const char* extensionOf(exporter::Format f) {
    switch (f) {
        case exporter::Format::Bvh:
            return ".bvh";
        case exporter::Format::Glb:
            return ".glb";
        case exporter::Format::Csv:
            return ".csv";
        case exporter::Format::Sto:
            return ".sto";
    }
    return ".out";
}

std::optional<double> numberParam(const httplib::Request& req, const char* key,
                                  std::string& error) {
    if (!req.has_param(key)) {
        return std::nullopt;
    }
    const std::string v = req.get_param_value(key);
    try {
        std::size_t used = 0;
        const double d = std::stod(v, &used);
        if (used == v.size() && std::isfinite(d) && d >= 0) {
            return d;
        }
    } catch (const std::exception&) {
    }
    error = fmt::format("{}: expected a number >= 0, got '{}'", key, v);
    return std::nullopt;
}

}  // namespace

struct WebServer::State {
    State(Hub& h, const board::Board& b, WebOptions o) : hub(h), board(b), options(std::move(o)) {}

    Hub& hub;
    const board::Board& board;
    WebOptions options;
    httplib::Server server;
    std::thread listener;
    std::thread stateReader;
    int port = 0;
    int listenSocket = -1;
    bool passwordRequired = false;
    Sessions sessions;
    std::mutex loginMutex;  // one password check at a time (each costs 64 MiB and ~0.1 s)

    // The latest state document, for every client.
    std::mutex mutex;
    std::condition_variable cv;
    std::string stateJson = "{}";
    std::uint64_t stateSequence = 0;
    bool stopping = false;

    std::atomic<int> streams{0};

    // The body calibration's countdown, for the page (wall time).
    std::mutex calibrationMutex;
    std::string calibrationKind;
    std::optional<SteadyClock::time_point> tAt;
    std::optional<SteadyClock::time_point> nAt;

    // One export at a time: they read whole takes.
    std::timed_mutex exportMutex;
    std::mutex exportStatusMutex;
    Json exportStatus;  // null: none running

    std::mutex summaryMutex;
    struct CachedSummary {
        std::uint64_t bytes = 0;
        std::int64_t modified = 0;
        RecordingSummary summary;
    };
    std::map<std::string, CachedSummary> summaries;

    bool waitStopping(std::chrono::milliseconds d) {
        std::unique_lock lock(mutex);
        return cv.wait_for(lock, d, [&] { return stopping; });
    }

    // Checks the request may go on; answers it (401, 403) when not.
    bool authorize(const httplib::Request& req, httplib::Response& res, bool changesState) {
        if (!passwordRequired && !isLoopbackHost(hostOf(req.get_header_value("Host")))) {
            // No password: loopback only, also by name (a DNS-rebound page is refused).
            fail(res, 403, "this hub has no password: only http://127.0.0.1 may use it");
            return false;
        }
        const auto csrf = sessions.csrfOf(cookieValue(req, kSessionCookie));
        if (!csrf) {
            fail(res, 401, "log in first (POST /api/login)");
            return false;
        }
        if (changesState && !sameToken(req.get_header_value(kCsrfHeader), *csrf)) {
            fail(res, 403, fmt::format("missing or wrong {} header", kCsrfHeader));
            return false;
        }
        return true;
    }

    // The request's JSON object (an empty body: {}); answers 400 when it is not one.
    std::optional<Json> parseBody(const httplib::Request& req, httplib::Response& res) {
        if (req.body.empty()) {
            return Json::object();
        }
        try {
            Json j = Json::parse(req.body);
            if (j.is_object()) {
                return j;
            }
            fail(res, 400, "request body: expected a JSON object");
        } catch (const Json::parse_error& e) {
            fail(res, 400, fmt::format("request body: not JSON: {}", e.what()));
        }
        return std::nullopt;
    }

    // The take being recorded, as the commands left it (the state document may be older).
    std::mutex takeMutex;
    std::string takeFile;
    std::string currentTakeName() {
        std::lock_guard lock(takeMutex);
        return takeFile;
    }
    void setCurrentTake(std::string file) {
        std::lock_guard lock(takeMutex);
        takeFile = std::move(file);
    }

    Json buildState(const HubState& h) {
        Json doc = Json::parse(statusJson(h.status));
        doc["version"] = options.version;
        doc["sensor_calibration"] =
            options.sensorCalibration.empty() ? Json(nullptr) : Json(options.sensorCalibration);
        // Per sensor: gyroscope clipping episodes (saturation), by board sensor.
        for (auto& sensor : doc["sensors"]) {
            const std::string name = sensor["name"].get<std::string>();
            for (std::size_t i = 0; i < board.sensors.size() && i < h.gyroClipEvents.size(); ++i) {
                if (board.sensors[i].name == name) {
                    sensor["gyro_clip_events"] = h.gyroClipEvents[i];
                }
            }
        }
        if (const std::size_t n = h.poseLatency.size(); n > 0) {
            const auto ms = [](Duration d) { return toSeconds(d) * 1e3; };
            doc["pose_latency_ms"] = {{"window", n},
                                      {"p50", ms(h.poseLatency.percentile(0.5))},
                                      {"p99", ms(h.poseLatency.percentile(0.99))},
                                      {"max", ms(h.poseLatency.max())}};
        }
        Json bodyJson;
        bodyJson["calibrated"] = h.bodyCalibrated;
        bodyJson["calibration"] = h.bodyCalibration;
        bodyJson["poses"] = h.poses;
        bodyJson["request"] = {{"state", std::string(body::toString(h.calibrationStatus.state))},
                               {"method", std::string(body::toString(h.calibrationStatus.method))},
                               {"progress", h.calibrationStatus.progress},
                               {"message", h.calibrationStatus.message}};
        {
            std::lock_guard lock(calibrationMutex);
            const auto now = SteadyClock::now();
            const auto left = [&](const std::optional<SteadyClock::time_point>& at) -> Json {
                if (!at) {
                    return nullptr;
                }
                return std::max(0.0, std::chrono::duration<double>(*at - now).count());
            };
            bodyJson["countdown"] = {
                {"kind", calibrationKind}, {"t_in_s", left(tAt)}, {"n_in_s", left(nAt)}};
        }
        doc["body"] = bodyJson;
        if (h.take) {
            doc["take"] = {{"name", h.take->name},
                           {"file", h.take->path.filename().string()},
                           {"records", h.take->records},
                           {"error", h.take->error != 0 ? errnoText(h.take->error) : ""}};
        } else {
            doc["take"] = nullptr;
        }
        doc["takes_recorded"] = h.takesRecorded;
        {
            std::lock_guard lock(exportStatusMutex);
            doc["export"] = exportStatus;
        }
        return doc;
    }

    void readStateLoop() {
        const auto period = std::chrono::milliseconds(
            static_cast<int>(1000.0 / std::clamp(options.stateHz, 0.5, 50.0)));
        for (;;) {
            const HubState h = hub.state();
            std::string text = buildState(h).dump();
            {
                std::lock_guard lock(mutex);
                stateJson = std::move(text);
                ++stateSequence;
            }
            cv.notify_all();
            if (waitStopping(period)) {
                return;
            }
        }
    }

    Json skeletonJson() const {
        Json segments = Json::array();
        for (int i = 0; i < body::kSegmentCount; ++i) {
            segments.push_back(
                {{"name", std::string(board::segmentName(static_cast<board::Segment>(i)))},
                 {"parent", body::parentOf(i)}});
        }
        Json ends = Json::array();
        if (auto dims = body::dimensionsFromSubject(board.subject)) {
            for (int e = 0; e < body::kEndEffectorCount; ++e) {
                const auto effector = static_cast<body::EndEffector>(e);
                const Vec3d& v = dims->endSiteM[static_cast<std::size_t>(e)];
                ends.push_back({{"name", std::string(body::endEffectorName(effector))},
                                {"segment", body::idx(body::endEffectorSegment(effector))},
                                {"offset", {v.x(), v.y(), v.z()}}});
            }
        }
        return {{"segments", segments}, {"end_sites", ends}};
    }

    static std::string poseEvent(const PoseFrame& p) {
        std::string out;
        out.reserve(2048);
        auto it = std::back_inserter(out);
        fmt::format_to(it, "data: {{\"serial\":{},\"t\":{:.4f},\"calibrated\":{},\"p\":[", p.serial,
                       toSeconds(p.t.time_since_epoch()), p.bodyCalibrated);
        for (int i = 0; i < body::kSegmentCount; ++i) {
            const auto& v = p.positionM[static_cast<std::size_t>(i)];
            fmt::format_to(it, "{}[{:.4f},{:.4f},{:.4f}]", i == 0 ? "" : ",", v.x(), v.y(), v.z());
        }
        out += "],\"q\":[";
        for (int i = 0; i < body::kSegmentCount; ++i) {
            const auto& q = p.world[static_cast<std::size_t>(i)];
            fmt::format_to(it, "{}[{:.5f},{:.5f},{:.5f},{:.5f}]", i == 0 ? "" : ",", q.w(), q.x(),
                           q.y(), q.z());
        }
        fmt::format_to(it, "],\"not_measured\":{}}}\n\n", p.notMeasured);
        return out;
    }

    // Reserves one of the stream slots; false (and 503) when all are taken.
    bool takeStream(httplib::Response& res) {
        if (streams.fetch_add(1) >= options.maxStreams) {
            streams.fetch_sub(1);
            res.set_header("Retry-After", "5");
            fail(res, 503, fmt::format("all {} live streams are in use", options.maxStreams));
            return false;
        }
        return true;
    }

    void routes();
    void takeRoutes();
};

void WebServer::State::routes() {
    State* s = this;
    const auto staticFile = [s](const fs::path& root, const std::string& name, const char* mime) {
        return [s, root, name, mime](const httplib::Request&, httplib::Response& res) {
            bool ok = false;
            std::string text = readFile(root / name, ok);
            if (!ok) {
                fail(res, 404, fmt::format("{} is not installed ({})", name, root.string()));
                return;
            }
            res.set_header("Cache-Control", "no-cache");
            res.set_content(std::move(text), mime);
        };
    };
    server.Get("/", staticFile(options.webRoot, "index.html", "text/html; charset=utf-8"));
    server.Get("/index.html",
               staticFile(options.webRoot, "index.html", "text/html; charset=utf-8"));
    server.Get("/app.js", staticFile(options.webRoot, "app.js", "text/javascript"));
    server.Get("/style.css", staticFile(options.webRoot, "style.css", "text/css"));
    server.Get("/three/three.min.js",
               staticFile(options.threeRoot, "three.min.js", "text/javascript"));

    server.Get("/api/session", [s](const httplib::Request& req, httplib::Response& res) {
        const auto csrf = s->sessions.csrfOf(cookieValue(req, kSessionCookie));
        Json j{{"password_required", s->passwordRequired},
               {"authenticated", csrf.has_value()},
               {"board", s->board.name},
               {"version", s->options.version}};
        if (csrf) {
            j["csrf"] = *csrf;
        }
        reply(res, 200, j);
    });
    server.Post("/api/login", [s](const httplib::Request& req, httplib::Response& res) {
        if (!s->passwordRequired && !isLoopbackHost(hostOf(req.get_header_value("Host")))) {
            fail(res, 403, "this hub has no password: only http://127.0.0.1 may use it");
            return;
        }
        auto b = s->parseBody(req, res);
        if (!b) {
            return;
        }
        if (s->passwordRequired) {
            const auto pw = b->value("password", Json());
            std::lock_guard lock(s->loginMutex);
            if (!pw.is_string() || !checkPassword(s->options.stateDir, pw.get<std::string>())) {
                // Held under the lock: at most one guess a second.
                std::this_thread::sleep_for(std::chrono::seconds(1));
                fail(res, 401, "wrong password");
                return;
            }
        }
        const auto [token, csrf] = s->sessions.create();
        res.set_header("Set-Cookie",
                       fmt::format("{}={}; HttpOnly; SameSite=Strict; Path=/; Max-Age=43200",
                                   kSessionCookie, token));
        reply(res, 200, Json{{"csrf", csrf}});
    });
    server.Post("/api/logout", [s](const httplib::Request& req, httplib::Response& res) {
        if (!s->authorize(req, res, true)) {
            return;
        }
        s->sessions.remove(cookieValue(req, kSessionCookie));
        res.set_header("Set-Cookie", fmt::format("{}=; HttpOnly; SameSite=Strict; Path=/; "
                                                 "Max-Age=0",
                                                 kSessionCookie));
        reply(res, 200, Json{{"ok", true}});
    });

    server.Get("/api/state", [s](const httplib::Request& req, httplib::Response& res) {
        if (!s->authorize(req, res, false)) {
            return;
        }
        std::string text;
        {
            std::lock_guard lock(s->mutex);
            text = s->stateJson;
        }
        res.set_header("Cache-Control", "no-store");
        res.set_content(std::move(text), "application/json");
    });
    server.Get("/api/skeleton", [s](const httplib::Request& req, httplib::Response& res) {
        if (s->authorize(req, res, false)) {
            reply(res, 200, s->skeletonJson());
        }
    });
    server.Get("/api/events", [s](const httplib::Request& req, httplib::Response& res) {
        if (!s->authorize(req, res, false) || !s->takeStream(res)) {
            return;
        }
        auto last = std::make_shared<std::uint64_t>(0);
        res.set_header("Cache-Control", "no-store");
        res.set_chunked_content_provider(
            "text/event-stream",
            [s, last](std::size_t, httplib::DataSink& sink) {
                std::string text;
                {
                    std::unique_lock lock(s->mutex);
                    s->cv.wait_for(lock, std::chrono::seconds(1),
                                   [&] { return s->stopping || s->stateSequence != *last; });
                    if (s->stopping) {
                        return false;
                    }
                    if (s->stateSequence == *last) {
                        return sink.write(kIdle.data(), kIdle.size());  // notices a client gone
                    }
                    *last = s->stateSequence;
                    text = "data: " + s->stateJson + "\n\n";
                }
                return sink.write(text.data(), text.size());
            },
            [s](bool) { s->streams.fetch_sub(1); });
    });
    server.Get("/api/poses", [s](const httplib::Request& req, httplib::Response& res) {
        if (!s->authorize(req, res, false) || !s->takeStream(res)) {
            return;
        }
        auto last = std::make_shared<std::uint64_t>(0);
        const auto period = std::chrono::milliseconds(
            static_cast<int>(1000.0 / std::clamp(s->options.poseHz, 1.0, 120.0)));
        res.set_header("Cache-Control", "no-store");
        res.set_chunked_content_provider(
            "text/event-stream",
            [s, last, period](std::size_t, httplib::DataSink& sink) {
                if (s->waitStopping(period)) {
                    return false;
                }
                PoseFrame p;
                if (s->hub.poses().latest(p) == 0 || p.serial == *last) {
                    return sink.write(kIdle.data(), kIdle.size());
                }
                *last = p.serial;
                const std::string text = poseEvent(p);
                return sink.write(text.data(), text.size());
            },
            [s](bool) { s->streams.fetch_sub(1); });
    });
    server.Get("/api/preview.jpg", [s](const httplib::Request& req, httplib::Response& res) {
        if (!s->authorize(req, res, false)) {
            return;
        }
        const auto jpeg = s->options.preview ? s->options.preview->latest(nullptr) : nullptr;
        if (!jpeg) {
            fail(res, 503, s->options.preview ? "no preview frame yet" : "the preview is off");
            return;
        }
        res.set_header("Cache-Control", "no-store");
        res.set_content(reinterpret_cast<const char*>(jpeg->data()), jpeg->size(), "image/jpeg");
    });
    server.Get("/api/preview.mjpeg", [s](const httplib::Request& req, httplib::Response& res) {
        if (!s->authorize(req, res, false)) {
            return;
        }
        if (!s->options.preview) {
            fail(res, 503, "the preview is off");
            return;
        }
        if (!s->takeStream(res)) {
            return;
        }
        auto last = std::make_shared<std::uint64_t>(0);
        res.set_chunked_content_provider(
            fmt::format("multipart/x-mixed-replace; boundary={}", kBoundary),
            [s, last](std::size_t, httplib::DataSink& sink) {
                const auto& slot = *s->options.preview;
                (void)slot.waitNewer(*last, 1000);
                if (s->waitStopping(std::chrono::milliseconds(0))) {
                    return false;
                }
                std::uint64_t seq = 0;
                const auto jpeg = slot.latest(&seq);
                if (!jpeg || seq == *last) {
                    return sink.is_writable();
                }
                *last = seq;
                const std::string head =
                    fmt::format("--{}\r\nContent-Type: image/jpeg\r\nContent-Length: {}\r\n\r\n",
                                kBoundary, jpeg->size());
                return sink.write(head.data(), head.size()) &&
                       sink.write(reinterpret_cast<const char*>(jpeg->data()), jpeg->size()) &&
                       sink.write("\r\n", 2);
            },
            [s](bool) { s->streams.fetch_sub(1); });
    });

    // Commands.
    const auto command = [s](auto fn) {
        return [s, fn](const httplib::Request& req, httplib::Response& res) {
            if (!s->authorize(req, res, true)) {
                return;
            }
            auto b = s->parseBody(req, res);
            if (b) {
                fn(*b, res);
            }
        };
    };
    const auto takeJson = [](const TakeInfo& t) {
        return Json{{"name", t.name},
                    {"file", t.path.filename().string()},
                    {"records", t.records},
                    {"error", t.error != 0 ? errnoText(t.error) : ""}};
    };
    server.Post("/api/take/start", command([s, takeJson](const Json& b, httplib::Response& res) {
                    const Json name = b.value("name", Json(""));
                    if (!name.is_string()) {
                        fail(res, 400, "name: expected a string");
                        return;
                    }
                    auto t = s->hub.startTake(name.get<std::string>());
                    if (!t) {
                        fail(res, statusFor(t.error()), t.error().message);
                        return;
                    }
                    s->setCurrentTake(t->path.filename().string());
                    reply(res, 200, takeJson(*t));
                }));
    server.Post("/api/take/stop", command([s, takeJson](const Json&, httplib::Response& res) {
                    auto t = s->hub.stopTake();
                    s->setCurrentTake({});
                    if (!t) {
                        fail(res, t.error().code == ENOENT ? 409 : statusFor(t.error()),
                             t.error().message);
                        return;
                    }
                    reply(res, 200, takeJson(*t));
                }));
    server.Post("/api/take/marker", command([s](const Json& b, httplib::Response& res) {
                    const Json label = b.value("label", Json(""));
                    if (!label.is_string() || label.get<std::string>().size() > 256) {
                        fail(res, 400, "label: expected a string of at most 256 characters");
                        return;
                    }
                    auto r = s->hub.marker(label.get<std::string>());
                    if (!r) {
                        fail(res, r.error().code == ENOENT ? 409 : statusFor(r.error()),
                             r.error().message);
                        return;
                    }
                    reply(res, 200, Json{{"ok", true}});
                }));
    server.Post(
        "/api/calibrate", command([s](const Json& b, httplib::Response& res) {
            const Json pose = b.value("pose", Json());
            const Json tIn = b.value("countdown_s", Json(5.0));
            const Json nIn = b.value("n_countdown_s", Json(15.0));
            const auto valid = [](const Json& j) {
                return j.is_number() && j.get<double>() >= 0 && j.get<double>() <= 120;
            };
            if (!pose.is_string() || !valid(tIn) || !valid(nIn)) {
                fail(res, 400,
                     "expected {\"pose\": \"tpose\"|\"npose\"|\"t+n\", \"countdown_s\": "
                     "0-120, \"n_countdown_s\": 0-120}");
                return;
            }
            const std::string kind = pose.get<std::string>();
            const double t = tIn.get<double>();
            const double n = nIn.get<double>();
            Result<void> r;
            if (kind == "tpose" || kind == "npose") {
                r = s->hub.calibrateBody(
                    kind == "tpose" ? body::ReferencePoseKind::T : body::ReferencePoseKind::N,
                    durationFromSeconds(t));
            } else if (kind == "t+n") {
                if (n <= t) {
                    fail(res, 400, "n_countdown_s must be after countdown_s");
                    return;
                }
                r = s->hub.calibrateBodyTPlusN(durationFromSeconds(t), durationFromSeconds(n));
            } else {
                fail(res, 400, fmt::format("pose: expected tpose, npose or t+n, got '{}'", kind));
                return;
            }
            if (!r) {
                fail(res, statusFor(r.error()), r.error().message);
                return;
            }
            {
                std::lock_guard lock(s->calibrationMutex);
                const auto now = SteadyClock::now();
                const auto after = [&](double sec) {
                    return now + std::chrono::duration_cast<SteadyClock::duration>(
                                     std::chrono::duration<double>(sec));
                };
                s->calibrationKind = kind;
                s->tAt = kind == "npose" ? std::nullopt : std::optional(after(t));
                s->nAt = kind == "npose" ? std::optional(after(t))
                                         : (kind == "t+n" ? std::optional(after(n)) : std::nullopt);
            }
            reply(res, 200, Json{{"ok", true}});
        }));
    server.Post("/api/heading-reset", command([s](const Json&, httplib::Response& res) {
                    auto r = s->hub.headingReset();
                    if (!r) {
                        fail(res, statusFor(r.error()), r.error().message);
                        return;
                    }
                    reply(res, 200, Json{{"ok", true}});
                }));
    takeRoutes();
}

void WebServer::State::takeRoutes() {
    State* s = this;
    server.Get("/api/takes", [s](const httplib::Request& req, httplib::Response& res) {
        if (!s->authorize(req, res, false)) {
            return;
        }
        const std::string recording = s->currentTakeName();
        Json list = Json::array();
        for (const auto& t : listTakes(s->options.recordings)) {
            Json j{{"file", t.name},
                   {"bytes", t.bytes},
                   {"modified", t.modifiedUnixS},
                   {"recording", t.name == recording}};
            if (t.name != recording) {
                // Each summary reads the whole take: kept while the file is unchanged.
                std::optional<RecordingSummary> summary;
                {
                    std::lock_guard lock(s->summaryMutex);
                    auto it = s->summaries.find(t.name);
                    if (it != s->summaries.end() && it->second.bytes == t.bytes &&
                        it->second.modified == t.modifiedUnixS) {
                        summary = it->second.summary;
                    }
                }
                if (!summary) {
                    auto made = summarizeRecording((s->options.recordings / t.name).string());
                    if (made) {
                        summary = *made;
                        std::lock_guard lock(s->summaryMutex);
                        s->summaries[t.name] = {t.bytes, t.modifiedUnixS, *made};
                    } else {
                        j["summary_error"] = made.error().message;
                    }
                }
                if (summary) {
                    j["duration_s"] = summary->durationS;
                    j["records"] = summary->records;
                    j["poses"] = summary->poses;
                    j["markers"] = summary->markers;
                    j["damaged_ranges"] = summary->damagedRanges;
                    j["info"] = summary->text;
                }
            }
            list.push_back(std::move(j));
        }
        reply(res, 200, Json{{"takes", list}});
    });
    server.Get(R"(/api/takes/([^/]+)/raw)",
               [s](const httplib::Request& req, httplib::Response& res) {
                   if (!s->authorize(req, res, false)) {
                       return;
                   }
                   const std::string name = req.matches[1];
                   auto path = resolveTake(s->options.recordings, name);
                   if (!path) {
                       fail(res, statusFor(path.error()), path.error().message);
                       return;
                   }
                   streamFile(res, *path, "application/octet-stream", name, false);
               });
    server.Get(R"(/api/takes/([^/]+)/export)",
               [s](const httplib::Request& req, httplib::Response& res) {
                   if (!s->authorize(req, res, false)) {
                       return;
                   }
                   const std::string name = req.matches[1];
                   auto path = resolveTake(s->options.recordings, name);
                   if (!path) {
                       fail(res, statusFor(path.error()), path.error().message);
                       return;
                   }
                   exporter::ExportOptions o;
                   const auto format = exporter::parseFormat(req.get_param_value("format"));
                   if (!format) {
                       fail(res, 400, "format: expected bvh, glb, csv or sto");
                       return;
                   }
                   o.format = *format;
                   std::string error;
                   o.track.rateHz = numberParam(req, "rate", error);
                   o.track.fromS = numberParam(req, "from", error);
                   o.track.toS = numberParam(req, "to", error);
                   if (o.track.rateHz && *o.track.rateHz <= 0) {
                       error = "rate: expected a number > 0";
                   }
                   if (req.has_param("names")) {
                       // Only the built-in maps: a map file would be a path on the hub.
                       o.names = req.get_param_value("names");
                       if (o.names != "hanim" && o.names != "cmu" && o.names != "unity") {
                           error = "names: expected hanim, cmu or unity";
                       }
                   }
                   if (req.has_param("units")) {
                       const std::string u = req.get_param_value("units");
                       if (u != "m" && u != "cm") {
                           error = "units: expected m or cm";
                       }
                       o.unitsPerM = u == "cm" ? 100 : 1;
                   }
                   o.referenceFrame = req.get_param_value("reference_frame") == "1";
                   if (o.referenceFrame && o.format != exporter::Format::Bvh) {
                       error = "reference_frame is for bvh only";
                   }
                   if (!error.empty()) {
                       fail(res, 400, error);
                       return;
                   }
                   std::unique_lock lock(s->exportMutex, std::defer_lock);
                   if (!lock.try_lock_for(std::chrono::seconds(30))) {
                       res.set_header("Retry-After", "10");
                       fail(res, 503, "another export is running; try again");
                       return;
                   }
                   const fs::path dir = s->options.stateDir / "exports";
                   std::error_code ec;
                   fs::create_directories(dir, ec);
                   const fs::path out = dir / (randomToken().substr(0, 16) + extensionOf(o.format));
                   {
                       std::lock_guard g(s->exportStatusMutex);
                       s->exportStatus = {{"take", name},
                                          {"format", std::string(formatName(o.format))},
                                          {"stage", "reading"},
                                          {"fraction", 0.0}};
                   }
                   auto summary = exporter::exportRecording(
                       path->string(), out.string(), o, [s](std::string_view stage, double f) {
                           std::lock_guard g(s->exportStatusMutex);
                           s->exportStatus["stage"] = std::string(stage);
                           s->exportStatus["fraction"] = f;
                       });
                   {
                       std::lock_guard g(s->exportStatusMutex);
                       s->exportStatus = nullptr;
                   }
                   lock.unlock();
                   if (!summary) {
                       fs::remove(out, ec);
                       fail(res, statusFor(summary.error()), summary.error().message);
                       return;
                   }
                   res.set_header("X-Caphub-Frames", std::to_string(summary->frames));
                   streamFile(res, out, mimeOf(o.format),
                              fs::path(name).stem().string() + extensionOf(o.format), true);
               });
    server.Get(R"(/api/takes/([^/]+))", [s](const httplib::Request& req, httplib::Response& res) {
        if (!s->authorize(req, res, false)) {
            return;
        }
        auto path = resolveTake(s->options.recordings, req.matches[1]);
        if (!path) {
            fail(res, statusFor(path.error()), path.error().message);
            return;
        }
        auto summary = summarizeRecording(path->string());
        if (!summary) {
            fail(res, 422, summary.error().message);
            return;
        }
        reply(res, 200,
              Json{{"file", path->filename().string()},
                   {"duration_s", summary->durationS},
                   {"records", summary->records},
                   {"poses", summary->poses},
                   {"markers", summary->markers},
                   {"info", summary->text}});
    });
    server.Post(
        R"(/api/takes/([^/]+)/delete)", [s](const httplib::Request& req, httplib::Response& res) {
            if (!s->authorize(req, res, true)) {
                return;
            }
            auto b = s->parseBody(req, res);
            if (!b) {
                return;
            }
            const std::string name = req.matches[1];
            const Json confirm = b->value("confirm", Json());
            if (!confirm.is_string() || confirm.get<std::string>() != name) {
                fail(res, 400, "to delete a take, give its file name again as \"confirm\"");
                return;
            }
            auto path = resolveTake(s->options.recordings, name);
            if (!path) {
                fail(res, statusFor(path.error()), path.error().message);
                return;
            }
            if (name == s->currentTakeName()) {
                fail(res, 409, "the take is being recorded: stop it first");
                return;
            }
            std::error_code ec;
            if (!fs::remove(*path, ec) || ec) {
                fail(res, 500, fmt::format("cannot delete '{}': {}", name, ec.message()));
                return;
            }
            {
                std::lock_guard lock(s->summaryMutex);
                s->summaries.erase(name);
            }
            log::logger(log::Category::Firmware).info("take deleted from the web: {}", name);
            reply(res, 200, Json{{"deleted", name}});
        });
}

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
    if (options.threads < 4 || options.maxStreams < 1 || options.maxStreams > options.threads - 2) {
        return Error{EINVAL, "expected at least 4 threads and at most threads - 2 streams"};
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
    // One request per connection: an idle keep-alive connection holds a worker thread until it
    // times out, and 24 such clients would leave none for anyone else.
    s->server.set_keep_alive_max_count(1);
    s->server.set_payload_max_length(s->options.maxBodyBytes);
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
    s->routes();
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
