// Commands into the running Hub: start and stop a take, a marker, the body's calibration (with
// its countdown, for the page) and the heading reset.
#include <fmt/format.h>

#include "firmware/serve/web_state.h"

namespace caphub::firmware::serve {

namespace {

Json takeJson(const TakeInfo& t) {
    return Json{{"name", t.name},
                {"file", t.path.filename().string()},
                {"records", t.records},
                {"error", t.error != 0 ? errnoText(t.error) : ""}};
}

// A command on the take being recorded: none is a conflict (409), not a missing resource.
void failNoTake(httplib::Response& res, const Error& e) {
    fail(res, e.code == ENOENT ? 409 : statusFor(e), e.message);
}

}  // namespace

void WebServer::State::commandRoutes() {
    State* s = this;
    server.Post("/api/take/start", command([s](const Json& b, httplib::Response& res) {
                    const Json name = b.value("name", Json(""));
                    if (!name.is_string()) {
                        fail(res, 400, "name: expected a string");
                        return;
                    }
                    auto t = s->hub.startTake(name.get<std::string>());
                    if (!t) {
                        failWith(res, t.error());
                        return;
                    }
                    s->setCurrentTake(t->path.filename().string());
                    reply(res, 200, takeJson(*t));
                }));
    server.Post("/api/take/stop", command([s](const Json&, httplib::Response& res) {
                    auto t = s->hub.stopTake();
                    s->setCurrentTake({});
                    if (!t) {
                        failNoTake(res, t.error());
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
                        failNoTake(res, r.error());
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
                failWith(res, r.error());
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
                        failWith(res, r.error());
                        return;
                    }
                    reply(res, 200, Json{{"ok", true}});
                }));
    takeRoutes();
}

}  // namespace caphub::firmware::serve
