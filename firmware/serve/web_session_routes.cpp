// The page's files, login and logout, and the access check every other route goes through.
#include <fstream>
#include <sstream>

#include <fmt/format.h>

#include "firmware/serve/takes.h"
#include "firmware/serve/web_state.h"

namespace caphub::firmware::serve {

namespace fs = std::filesystem;

namespace {

std::string readFile(const fs::path& p, bool& ok) {
    std::ifstream in(p, std::ios::binary);
    std::stringstream s;
    s << in.rdbuf();
    ok = static_cast<bool>(in);
    return s.str();
}

Handler staticFile(const fs::path& root, const std::string& name, const char* mime) {
    return [root, name, mime](const httplib::Request&, httplib::Response& res) {
        bool ok = false;
        std::string text = readFile(root / name, ok);
        if (!ok) {
            fail(res, 404, fmt::format("{} is not installed ({})", name, root.string()));
            return;
        }
        res.set_header("Cache-Control", "no-cache");
        res.set_content(std::move(text), mime);
    };
}

}  // namespace

bool WebServer::State::authorize(const httplib::Request& req, httplib::Response& res,
                                 bool changesState) {
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

std::optional<Json> WebServer::State::parseBody(const httplib::Request& req,
                                                httplib::Response& res) {
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
    } catch (const Json::exception& e) {
        // A number no double holds (1e400) and the like: the client's error, not the hub's.
        fail(res, 400, fmt::format("request body: {}", e.what()));
    }
    return std::nullopt;
}

Handler WebServer::State::guarded(Handler fn) {
    return [this, fn = std::move(fn)](const httplib::Request& req, httplib::Response& res) {
        if (authorize(req, res, false)) {
            fn(req, res);
        }
    };
}

Handler WebServer::State::command(std::function<void(const Json&, httplib::Response&)> fn) {
    return [this, fn = std::move(fn)](const httplib::Request& req, httplib::Response& res) {
        if (!authorize(req, res, true)) {
            return;
        }
        if (auto b = parseBody(req, res)) {
            fn(*b, res);
        }
    };
}

Handler WebServer::State::takeHandler(
    bool changesState, std::function<void(const httplib::Request&, httplib::Response&,
                                          const std::string&, const fs::path&)>
                           fn) {
    return [this, changesState, fn = std::move(fn)](const httplib::Request& req,
                                                    httplib::Response& res) {
        if (!authorize(req, res, changesState)) {
            return;
        }
        const std::string name = req.matches[1];
        auto path = resolveTake(options.recordings, name);
        if (!path) {
            failWith(res, path.error());
            return;
        }
        fn(req, res, name, *path);
    };
}

void WebServer::State::sessionRoutes() {
    State* s = this;
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
        // Only as JSON: a page on another site can send text/plain or a form to this address
        // without asking (no CORS preflight), and 32 such logins evicted the user's session
        // from the table; a JSON body needs the preflight this server never grants.
        const std::string type = req.get_header_value("Content-Type");
        if (type.substr(0, type.find(';')) != "application/json") {
            fail(res, 415, "a login is a JSON body (Content-Type: application/json)");
            return;
        }
        auto b = s->parseBody(req, res);
        if (!b) {
            return;
        }
        if (s->passwordRequired) {
            // At most one guess a second from each address, refused without waiting: a wrong
            // guess used to hold its worker for a second under the lock, and thirty clients
            // guessing starved every other request, a right password included.
            const auto now = std::chrono::steady_clock::now();
            {
                std::lock_guard guess(s->guessMutex);
                std::erase_if(s->nextGuess, [now](const auto& e) { return e.second <= now; });
                if (const auto it = s->nextGuess.find(req.remote_addr); it != s->nextGuess.end()) {
                    const double waitS = std::chrono::duration<double>(it->second - now).count();
                    res.set_header("Retry-After", "1");
                    fail(res, 429,
                         fmt::format("a wrong password from here just now: try again in {:.1f} s",
                                     waitS));
                    return;
                }
            }
            const auto pw = b->value("password", Json());
            bool right = false;
            {
                std::lock_guard lock(s->loginMutex);
                right = pw.is_string() && checkPassword(s->options.stateDir, pw.get<std::string>());
            }
            if (!right) {
                std::lock_guard guess(s->guessMutex);
                s->nextGuess[req.remote_addr] = now + std::chrono::seconds(1);
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
}

}  // namespace caphub::firmware::serve
