// The live side: the state document (read from the Hub a few times a second by one thread and
// served from there, polled or as Server-Sent Events), the skeleton, the poses as events, and the
// preview (one JPEG, or MJPEG).
#include <algorithm>
#include <iterator>
#include <memory>

#include <fmt/format.h>

#include "firmware/runtime/status_stage.h"
#include "firmware/serve/sensor_calibration_session.h"
#include "firmware/serve/web_state.h"
#include "fusion/body/skeleton.h"

namespace caphub::firmware::serve {

namespace {

constexpr const char* kBoundary = "caphubframe";
// An SSE comment: keeps a quiet stream writing, so that a client gone is noticed.
constexpr std::string_view kIdle = ": idle\n\n";

std::string poseEvent(const PoseFrame& p) {
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

}  // namespace

Json WebServer::State::buildState(const HubState& h) {
    Json doc = Json::parse(statusJson(h.status));
    doc["version"] = options.version;
    doc["sensor_calibration"] =
        options.sensorCalibration.empty() ? Json(nullptr) : Json(options.sensorCalibration);
    if (options.calibrationSession != nullptr) {
        doc["sensor_calibration_session"] = options.calibrationSession->status();
    }
    // Per sensor: gyroscope clipping episodes (saturation), by board sensor.
    for (auto& sensor : doc["sensors"]) {
        const std::string name = sensor["name"].get<std::string>();
        for (std::size_t i = 0; i < board.sensors.size() && i < h.gyroClipEvents.size(); ++i) {
            if (board.sensors[i].name == name) {
                sensor["gyro_clip_events"] = h.gyroClipEvents[i];
                // A free heading's strap turn found from the joints (docs/body-calibration.md,
                // "Headings from the joints").
                if (i < h.jointTurnDeg.size() && h.jointTurnDeg[i] != 0) {
                    sensor["joint_turn_deg"] = h.jointTurnDeg[i];
                }
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
    bodyJson["heading_reset"] = {{"state", std::string(body::toString(h.headingReset.state))},
                                 {"heading_deg", h.headingReset.headingDeg},
                                 {"message", h.headingReset.message}};
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

void WebServer::State::readStateLoop() {
    const auto period = std::chrono::milliseconds(
        static_cast<int>(1000.0 / std::clamp(options.stateHz, 0.5, 50.0)));
    for (;;) {
        const HubState h = hub.state();
        std::string text = buildState(h).dump(-1, ' ', false, Json::error_handler_t::replace);
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

Json WebServer::State::skeletonJson() const {
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

// Reserves one of the stream slots; false (and 503) when all are taken.
bool WebServer::State::takeStream(httplib::Response& res) {
    if (streams.fetch_add(1) >= options.maxStreams) {
        streams.fetch_sub(1);
        res.set_header("Retry-After", "5");
        fail(res, 503, fmt::format("all {} live streams are in use", options.maxStreams));
        return false;
    }
    return true;
}

void routes();

std::function<void(bool)> WebServer::State::releaseStream() {
    return [this](bool) { streams.fetch_sub(1); };
}

WebServer::State::DownloadSlot::DownloadSlot(std::atomic<int>& count, int max,
                                             httplib::Response& res)
    : count_(count) {
    if (count_.fetch_add(1) >= max) {
        count_.fetch_sub(1);
        res.set_header("Retry-After", "10");
        fail(res, 503, fmt::format("all {} downloads are in use; try again", max));
        return;
    }
    held_ = true;
}

void WebServer::State::DownloadSlot::release() {
    if (held_) {
        held_ = false;
        count_.fetch_sub(1);
    }
}

std::function<void()> WebServer::State::DownloadSlot::handOver() {
    if (!held_) {
        return {};
    }
    held_ = false;
    return [&count = count_] { count.fetch_sub(1); };
}

Handler WebServer::State::eventStream(
    std::function<std::function<bool(httplib::DataSink&)>()> makeNext) {
    return guarded([this, makeNext](const httplib::Request&, httplib::Response& res) {
        if (!takeStream(res)) {
            return;
        }
        res.set_header("Cache-Control", "no-store");
        res.set_chunked_content_provider(
            "text/event-stream",
            [next = std::make_shared<std::function<bool(httplib::DataSink&)>>(makeNext())](
                std::size_t, httplib::DataSink& sink) { return (*next)(sink); },
            releaseStream());
    });
}

void WebServer::State::liveRoutes() {
    State* s = this;
    server.Get("/api/state", guarded([s](const httplib::Request&, httplib::Response& res) {
                   std::string text;
                   {
                       std::lock_guard lock(s->mutex);
                       text = s->stateJson;
                   }
                   res.set_header("Cache-Control", "no-store");
                   res.set_content(std::move(text), "application/json");
               }));
    server.Get("/api/skeleton", guarded([s](const httplib::Request&, httplib::Response& res) {
                   reply(res, 200, s->skeletonJson());
               }));
    server.Get("/api/events", eventStream([s] {
                   return [s, last = std::uint64_t{0}](httplib::DataSink& sink) mutable {
                       std::string text;
                       {
                           std::unique_lock lock(s->mutex);
                           s->cv.wait_for(lock, std::chrono::seconds(1),
                                          [&] { return s->stopping || s->stateSequence != last; });
                           if (s->stopping) {
                               return false;
                           }
                           if (s->stateSequence == last) {
                               // Notices a client gone.
                               return sink.write(kIdle.data(), kIdle.size());
                           }
                           last = s->stateSequence;
                           text = "data: " + s->stateJson + "\n\n";
                       }
                       return sink.write(text.data(), text.size());
                   };
               }));
    const auto posePeriod = std::chrono::milliseconds(
        static_cast<int>(1000.0 / std::clamp(options.poseHz, 1.0, 120.0)));
    server.Get("/api/poses", eventStream([s, posePeriod] {
                   return
                       [s, posePeriod, last = std::uint64_t{0}](httplib::DataSink& sink) mutable {
                           if (s->waitStopping(posePeriod)) {
                               return false;
                           }
                           PoseFrame p;
                           if (s->hub.poses().latest(p) == 0 || p.serial == last) {
                               return sink.write(kIdle.data(), kIdle.size());
                           }
                           last = p.serial;
                           const std::string text = poseEvent(p);
                           return sink.write(text.data(), text.size());
                       };
               }));
    server.Get(
        "/api/preview.jpg", guarded([s](const httplib::Request&, httplib::Response& res) {
            const auto jpeg = s->options.preview ? s->options.preview->latest(nullptr) : nullptr;
            if (!jpeg) {
                fail(res, 503, s->options.preview ? "no preview frame yet" : "the preview is off");
                return;
            }
            res.set_header("Cache-Control", "no-store");
            res.set_content(reinterpret_cast<const char*>(jpeg->data()), jpeg->size(),
                            "image/jpeg");
        }));
    server.Get("/api/preview.mjpeg", guarded([s](const httplib::Request&, httplib::Response& res) {
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
                           const std::string head = fmt::format(
                               "--{}\r\nContent-Type: image/jpeg\r\nContent-Length: {}\r\n\r\n",
                               kBoundary, jpeg->size());
                           return sink.write(head.data(), head.size()) &&
                                  sink.write(reinterpret_cast<const char*>(jpeg->data()),
                                             jpeg->size()) &&
                                  sink.write("\r\n", 2);
                       },
                       s->releaseStream());
               }));
}

}  // namespace caphub::firmware::serve
