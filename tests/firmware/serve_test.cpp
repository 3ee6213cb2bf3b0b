// caphub serve's HTTP API end to end on the virtual suit, driven with httplib's client as the
// page drives it: login, body calibration, a take with a marker, the take list with its summary,
// exports downloaded and parsed, deletion with confirmation; and its security: no session or no
// CSRF token -> 401/403 with nothing changed, downloads only from the recordings folder, no
// network listening without a password, and 50 concurrent clients all served while the capture
// loses no sample; the guided sensor calibration through the API on the virtual suit, saved in
// the state folder and applied at the next start of `caphub serve`.
// clang-format off
// Before <httplib.h>: it includes <resolv.h>, whose `_res` macro breaks Eigen's headers after it.
#include "firmware/serve/web_server.h"
// clang-format on

#include <array>
#include <atomic>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <thread>

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <httplib.h>
#include <netinet/in.h>
#include <nlohmann/json.hpp>
#include <poll.h>
#include <sys/socket.h>
#include <tiny_gltf.h>
#include <unistd.h>

#include "board/loader.h"
#include "board/sim/bvh.h"
#include "board/sim/virtual_suit.h"
#include "firmware/calibration_file.h"
#include "firmware/serve/auth.h"
#include "firmware/serve/takes.h"
#include "tests/firmware/cli_run.h"

namespace caphub::firmware::serve {
namespace {

namespace fs = std::filesystem;
using Json = nlohmann::json;
using std::chrono::milliseconds;

// A running Hub on the virtual suit (10 sensors, real time) with its web server on a free port.
struct ServeRig {
    board::Board board;
    SimulatedClock clock;
    board::SuitHardware suit;
    fs::path dir;
    fs::path recordings;
    fs::path stateDir;
    std::unique_ptr<Hub> hub;
    std::unique_ptr<WebServer> web;

    std::shared_ptr<render::JpegFrameSlot> preview = std::make_shared<render::JpegFrameSlot>();

    explicit ServeRig(const std::string& name, const std::string& password = {},
                      double requestTimeoutS = 10)
        : clock(MonotonicClock().now(), 1.0),
          dir(fs::path(::testing::TempDir()) / ("caphub-serve-" + name)),
          recordings(dir / "recordings"),
          stateDir(dir / "state") {
        fs::remove_all(dir);
        fs::create_directories(recordings);
        auto loaded = board::loadBoardFile(CAPHUB_SOURCE_DIR "/board/sim-upper10.toml");
        EXPECT_TRUE(loaded.ok());
        board = *loaded.board;
        auto built = board::sim::buildVirtualSuit(board, clock, nullptr);
        EXPECT_TRUE(built.ok()) << built.error().message;
        suit = std::move(*built);
        if (!password.empty()) {
            EXPECT_TRUE(setPassword(stateDir, password).ok());
        }
        HubOptions o;
        o.recordings = recordings;
        o.softwareVersion = "serve-test";
        o.statusPath = dir / "status.json";
        hub = std::make_unique<Hub>(board, clock, suit, std::move(o));
        hub->start();
        WebOptions w;
        w.port = 0;
        w.recordings = recordings;
        w.stateDir = stateDir;
        w.webRoot = CAPHUB_SOURCE_DIR "/firmware/web";
        w.version = "serve-test";
        w.stateHz = 10;
        w.preview = preview;
        w.requestTimeoutS = requestTimeoutS;
        auto started = WebServer::start(*hub, board, w);
        EXPECT_TRUE(started.ok()) << started.error().message;
        if (started) {
            web = std::move(*started);
        }
    }
    ~ServeRig() {
        if (web) {
            web->stop();
        }
        hub->requestStop();
        (void)hub->wait();
    }
    int port() const { return web ? web->port() : -1; }
    std::size_t caps() const {
        std::size_t n = 0;
        for (const auto& e : fs::directory_iterator(recordings)) {
            n += e.path().extension() == ".cap";
        }
        return n;
    }
};

// A client with a session: the cookie and CSRF token of a login.
struct Session {
    httplib::Client client;
    std::string cookie;
    std::string csrf;

    explicit Session(int port, const std::string& password = {}) : client("127.0.0.1", port) {
        client.set_read_timeout(60, 0);  // an export on a loaded machine
        const Json body = password.empty() ? Json::object() : Json{{"password", password}};
        auto r = client.Post("/api/login", body.dump(), "application/json");
        EXPECT_TRUE(r && r->status == 200) << (r ? r->body : "no answer");
        if (r && r->status == 200) {
            const std::string set = r->get_header_value("Set-Cookie");
            cookie = set.substr(0, set.find(';'));
            csrf = Json::parse(r->body)["csrf"].get<std::string>();
        }
    }
    httplib::Headers headers(bool withCsrf = true) const {
        httplib::Headers h{{"Cookie", cookie}};
        if (withCsrf) {
            h.emplace("X-CSRF-Token", csrf);
        }
        return h;
    }
    httplib::Result get(const std::string& path) { return client.Get(path.c_str(), headers()); }
    httplib::Result post(const std::string& path, const Json& body = Json::object()) {
        return client.Post(path.c_str(), headers(), body.dump(), "application/json");
    }
    Json state() {
        auto r = get("/api/state");
        EXPECT_TRUE(r && r->status == 200);
        return r ? Json::parse(r->body) : Json();
    }
};

// Polls the state (at most 30 s of real time) until `done` holds.
template <typename F>
bool waitForState(Session& s, F done) {
    for (int i = 0; i < 300; ++i) {
        if (done(s.state())) {
            return true;
        }
        std::this_thread::sleep_for(milliseconds(100));
    }
    return false;
}

std::string status(const httplib::Result& r) {
    return r ? std::to_string(r->status) + " " + r->body : "no answer";
}

TEST(ServeAuth, OnlyLoopbackAddressesAndLocalhostAreThisMachine) {
    for (const char* host : {"127.0.0.1", "127.1.2.3", "::1", "0:0:0:0:0:0:0:1", "localhost"}) {
        EXPECT_TRUE(isLoopbackHost(host)) << host;
    }
    for (const char* host : {"127.0.0.1.evil.example", "127.evil.com", "127.0.0.1@evil.com", "",
                             "128.0.0.1", "::2", "localhost.evil.com", "0.0.0.0", "::"}) {
        EXPECT_FALSE(isLoopbackHost(host)) << host;
    }
}

TEST(Serve, RunsCalibrationATakeWithAMarkerAndDownloadsItsExportsEndToEnd) {
    ServeRig rig("e2e");
    ASSERT_GT(rig.port(), 0);
    Session s(rig.port());

    // The page's files and three.js's path are served.
    auto page = s.client.Get("/");
    ASSERT_TRUE(page && page->status == 200);
    EXPECT_NE(page->body.find("/three/three.min.js"), std::string::npos);

    ASSERT_TRUE(waitForState(s, [](const Json& j) {
        return j.contains("sensors") && !j["sensors"].empty() && j["sensors"][0]["online"] == true;
    }));
    // A countdown the page can show: the N-pose in 30 s (then replaced by a T-pose at once).
    auto later = s.post("/api/calibrate", {{"pose", "npose"}, {"countdown_s", 30}});
    ASSERT_TRUE(later && later->status == 200) << status(later);
    Json countdown;
    ASSERT_TRUE(waitForState(s, [&](const Json& j) {
        countdown = j["body"]["countdown"];
        return countdown["kind"] == "npose";
    }));
    EXPECT_EQ(countdown["kind"], "npose");
    EXPECT_TRUE(countdown["t_in_s"].is_null());
    EXPECT_GT(countdown["n_in_s"].get<double>(), 15.0);  // generous: a loaded machine
    EXPECT_LE(countdown["n_in_s"].get<double>(), 30.0);
    auto cal = s.post("/api/calibrate", {{"pose", "tpose"}, {"countdown_s", 0}});
    ASSERT_TRUE(cal && cal->status == 200) << status(cal);
    EXPECT_TRUE(waitForState(
        s, [](const Json& j) { return j["body"]["request"]["state"] != "not started"; }));
    auto badCal = s.post("/api/calibrate", {{"pose", "splits"}});
    ASSERT_TRUE(badCal);
    EXPECT_EQ(badCal->status, 400);
    auto heading = s.post("/api/heading-reset");
    ASSERT_TRUE(heading && heading->status == 200) << status(heading);
    // It settles, done or failed with the reason (this rig's suit lies at rest: its pelvis'
    // forward axis may be vertical).
    EXPECT_TRUE(waitForState(s, [](const Json& j) {
        const Json& r = j["body"]["heading_reset"];
        return r["state"] == "done" ||
               (r["state"] == "failed" && !r["message"].get<std::string>().empty());
    }));

    auto start = s.post("/api/take/start", {{"name", "walk-1"}});
    ASSERT_TRUE(start && start->status == 200) << status(start);
    const std::string file = Json::parse(start->body)["file"].get<std::string>();
    EXPECT_TRUE(file.ends_with("-walk-1.cap")) << file;
    ASSERT_TRUE(waitForState(s, [](const Json& j) {
        return j["take"].is_object() && j["take"]["records"].get<std::uint64_t>() >= 2000;
    }));
    auto marker = s.post("/api/take/marker", {{"label", "heel strike"}});
    ASSERT_TRUE(marker && marker->status == 200) << status(marker);
    ASSERT_TRUE(waitForState(s, [](const Json& j) {
        return j["take"].is_object() && j["take"]["records"].get<std::uint64_t>() >= 4000;
    }));
    auto stop = s.post("/api/take/stop");
    ASSERT_TRUE(stop && stop->status == 200) << status(stop);
    auto stopAgain = s.post("/api/take/stop");
    ASSERT_TRUE(stopAgain);
    EXPECT_EQ(stopAgain->status, 409);

    // The list: the take with its `caphub info` summary.
    auto list = s.get("/api/takes");
    ASSERT_TRUE(list && list->status == 200);
    const Json takes = Json::parse(list->body)["takes"];
    ASSERT_EQ(takes.size(), 1u);
    ASSERT_TRUE(takes[0].contains("markers")) << takes[0].dump();
    EXPECT_EQ(takes[0]["file"], file);
    EXPECT_EQ(takes[0]["markers"], 1);
    EXPECT_GT(takes[0]["poses"].get<int>(), 30);
    EXPECT_NE(takes[0]["info"].get<std::string>().find("marker: heel strike"), std::string::npos);

    // The raw take, byte for byte.
    auto raw = s.get("/api/takes/" + file + "/raw");
    ASSERT_TRUE(raw && raw->status == 200);
    std::ifstream in(rig.recordings / file, std::ios::binary);
    const std::string onDisk((std::istreambuf_iterator<char>(in)), {});
    EXPECT_EQ(raw->body, onDisk);

    // BVH: parses with the virtual suit's BVH reader, with as many frames as the export made.
    auto bvh = s.get("/api/takes/" + file + "/export?format=bvh&units=cm");
    ASSERT_TRUE(bvh && bvh->status == 200) << status(bvh);
    const fs::path bvhFile = rig.dir / "download.bvh";
    std::ofstream(bvhFile, std::ios::binary) << bvh->body;
    auto clip = board::sim::loadBvh(bvhFile.string());
    ASSERT_TRUE(clip.ok()) << clip.error().message;
    EXPECT_EQ(std::to_string(clip->frameCount), bvh->get_header_value("X-Caphub-Frames"));
    EXPECT_GT(clip->frameCount, 30);
    EXPECT_GE(clip->findJoint("humanoid_root"), 0);

    // glb: loads with tinygltf, with the skin, its joints and one animation.
    auto glb = s.get("/api/takes/" + file + "/export?format=glb");
    ASSERT_TRUE(glb && glb->status == 200) << status(glb);
    tinygltf::TinyGLTF loader;
    tinygltf::Model model;
    std::string err;
    std::string warn;
    ASSERT_TRUE(loader.LoadBinaryFromMemory(
        &model, &err, &warn, reinterpret_cast<const unsigned char*>(glb->body.data()),
        static_cast<unsigned int>(glb->body.size())))
        << err;
    ASSERT_EQ(model.skins.size(), 1u);
    EXPECT_EQ(model.skins[0].joints.size(), static_cast<std::size_t>(body::kSegmentCount));
    EXPECT_EQ(model.animations.size(), 1u);

    auto badFormat = s.get("/api/takes/" + file + "/export?format=fbx");
    ASSERT_TRUE(badFormat);
    EXPECT_EQ(badFormat->status, 400);
    auto mapFile = s.get("/api/takes/" + file + "/export?format=bvh&names=/etc/passwd");
    ASSERT_TRUE(mapFile);
    EXPECT_EQ(mapFile->status, 400);
    auto reference = s.get("/api/takes/" + file + "/export?format=bvh&reference_frame=2");
    ASSERT_TRUE(reference);
    EXPECT_EQ(reference->status, 400);  // was taken as 0
    // Said of the take and the query, not of the hub's folders and the command line.
    auto window = s.get("/api/takes/" + file + "/export?format=bvh&from=5&to=1");
    ASSERT_TRUE(window);
    EXPECT_EQ(window->status, 400);
    const std::string why = Json::parse(window->body).value("error", "");
    EXPECT_EQ(why, "'" + file + "': to 1: expected seconds >= from (5)");

    // Deleting needs the name again.
    auto unconfirmed = s.post("/api/takes/" + file + "/delete", {{"confirm", "yes"}});
    ASSERT_TRUE(unconfirmed);
    EXPECT_EQ(unconfirmed->status, 400);
    EXPECT_TRUE(fs::exists(rig.recordings / file));
    auto deleted = s.post("/api/takes/" + file + "/delete", {{"confirm", file}});
    ASSERT_TRUE(deleted && deleted->status == 200) << status(deleted);
    EXPECT_FALSE(fs::exists(rig.recordings / file));
}

TEST(Serve, LivePosesArriveAsServerSentEventsThatMove) {
    ServeRig rig("poses");
    Session s(rig.port());
    std::vector<std::uint64_t> serials;
    std::string buffer;
    auto r = s.client.Get("/api/poses", s.headers(false), [&](const char* data, std::size_t n) {
        buffer.append(data, n);
        std::size_t end = 0;
        while ((end = buffer.find("\n\n")) != std::string::npos) {
            const std::string event = buffer.substr(0, end);
            buffer.erase(0, end + 2);
            if (event.starts_with("data: ")) {
                const Json j = Json::parse(event.substr(6));
                EXPECT_EQ(j["p"].size(), static_cast<std::size_t>(body::kSegmentCount));
                EXPECT_EQ(j["q"].size(), static_cast<std::size_t>(body::kSegmentCount));
                serials.push_back(j["serial"].get<std::uint64_t>());
            }
        }
        return serials.size() < 5;  // enough: the client hangs up
    });
    ASSERT_GE(serials.size(), 5u);
    for (std::size_t i = 1; i < serials.size(); ++i) {
        EXPECT_GT(serials[i], serials[i - 1]);
    }
}

TEST(Serve, TheStateIsPushedAsServerSentEvents) {
    ServeRig rig("events");
    Session s(rig.port());
    std::string stream;
    int states = 0;
    (void)s.client.Get("/api/events", s.headers(false), [&](const char* data, std::size_t n) {
        stream.append(data, n);
        std::size_t end = 0;
        while ((end = stream.find("\n\n")) != std::string::npos) {
            const std::string event = stream.substr(0, end);
            stream.erase(0, end + 2);
            EXPECT_EQ(event.find('\0'), std::string::npos);
            if (event.starts_with("data: ")) {
                const Json j = Json::parse(event.substr(6));
                EXPECT_TRUE(j.contains("body") && j.contains("take")) << event;
                ++states;
            } else {
                EXPECT_EQ(event, ": idle");
            }
        }
        return states < 3;
    });
    EXPECT_EQ(states, 3);
}

TEST(Serve, ThePreviewIsServedAsTheLatestJpegAndAsAnMjpegStream) {
    ServeRig rig("preview");
    Session s(rig.port());
    auto none = s.get("/api/preview.jpg");
    ASSERT_TRUE(none);
    EXPECT_EQ(none->status, 503);  // no frame yet
    render::Image image(64, 48);
    ASSERT_TRUE(rig.preview->publish(image).ok());
    auto jpg = s.get("/api/preview.jpg");
    ASSERT_TRUE(jpg && jpg->status == 200);
    EXPECT_EQ(jpg->get_header_value("Content-Type"), "image/jpeg");
    ASSERT_GT(jpg->body.size(), 4u);
    EXPECT_EQ(static_cast<unsigned char>(jpg->body[0]), 0xFF);
    EXPECT_EQ(static_cast<unsigned char>(jpg->body[1]), 0xD8);  // a JPEG's start of image
    // The stream: each newly published frame as one part.
    std::atomic<bool> reading{true};
    std::thread publisher([&] {
        for (int i = 0; i < 200 && reading; ++i) {
            (void)rig.preview->publish(image);
            std::this_thread::sleep_for(milliseconds(20));
        }
    });
    std::string stream;
    (void)s.client.Get(
        "/api/preview.mjpeg", s.headers(false), [&](const char* data, std::size_t n) {
            stream.append(data, n);
            std::size_t parts = 0;
            for (std::size_t at = 0;
                 (at = stream.find("Content-Type: image/jpeg", at)) != std::string::npos; ++at) {
                ++parts;
            }
            return parts < 3;
        });
    reading = false;
    publisher.join();
    EXPECT_NE(stream.find("--caphubframe"), std::string::npos);
}

TEST(Serve, WithoutASessionOrItsCsrfTokenCommandsAreRefusedAndNothingChanges) {
    ServeRig rig("auth");
    Session s(rig.port());
    httplib::Client anon("127.0.0.1", rig.port());
    const std::string body = Json{{"name", "x"}}.dump();

    auto noCookie = anon.Post("/api/take/start", body, "application/json");
    ASSERT_TRUE(noCookie);
    EXPECT_EQ(noCookie->status, 401);
    auto noCookieState = anon.Get("/api/state");
    ASSERT_TRUE(noCookieState);
    EXPECT_EQ(noCookieState->status, 401);
    auto forged = anon.Post("/api/take/start", {{"Cookie", "caphub_session=" + randomToken()}},
                            body, "application/json");
    ASSERT_TRUE(forged);
    EXPECT_EQ(forged->status, 401);
    auto noCsrf = anon.Post("/api/take/start", s.headers(false), body, "application/json");
    ASSERT_TRUE(noCsrf);
    EXPECT_EQ(noCsrf->status, 403);
    auto wrongCsrf =
        anon.Post("/api/take/start", {{"Cookie", s.cookie}, {"X-CSRF-Token", randomToken()}}, body,
                  "application/json");
    ASSERT_TRUE(wrongCsrf);
    EXPECT_EQ(wrongCsrf->status, 403);
    // A page served from elsewhere that resolves to this machine (DNS rebinding).
    auto rebound = anon.Post("/api/login", {{"Host", "evil.example:80"}}, "{}", "application/json");
    ASSERT_TRUE(rebound);
    EXPECT_EQ(rebound->status, 403);
    // ... by a name that starts like a loopback address (a prefix test let these in).
    for (const char* host : {"127.0.0.1.evil.example:18080", "127.evil.com", "127.0.0.1@evil.com",
                             "127.0.0.1 evil.com"}) {
        auto named = anon.Post("/api/login", {{"Host", host}}, "{}", "application/json");
        ASSERT_TRUE(named) << host;
        EXPECT_EQ(named->status, 403) << host;
    }
    // Too large a body.
    auto huge = s.post("/api/take/marker", {{"label", std::string(100000, 'x')}});
    ASSERT_TRUE(huge);
    EXPECT_EQ(huge->status, 413);
    // What the HTTP layer answers itself says why, as every other error does (it was empty).
    EXPECT_EQ(Json::parse(huge->body).value("error", ""), "the request body is over its limit");
    auto unknown = anon.Get("/api/no-such-route");
    ASSERT_TRUE(unknown);
    EXPECT_EQ(unknown->status, 404);
    EXPECT_EQ(Json::parse(unknown->body).value("error", ""),
              "no such route: GET /api/no-such-route");

    std::this_thread::sleep_for(milliseconds(300));
    EXPECT_EQ(rig.caps(), 0u);
    EXPECT_TRUE(s.state()["take"].is_null());
    // The same request with both tokens works.
    auto ok = s.post("/api/take/start", {{"name", "x"}});
    ASSERT_TRUE(ok && ok->status == 200) << status(ok);
    EXPECT_EQ(rig.caps(), 1u);
}

TEST(Serve, DownloadsComeOnlyFromTheRecordingsFolder) {
    ServeRig rig("paths");
    Session s(rig.port());
    std::ofstream(rig.dir / "secret.cap") << "not for the web";
    fs::create_symlink(rig.dir / "secret.cap", rig.recordings / "link.cap");
    fs::create_directories(rig.recordings / "sub");
    std::ofstream(rig.recordings / "sub" / "inner.cap") << "x";

    const auto code = [&](const std::string& path) {
        auto r = s.get(path);
        EXPECT_TRUE(r && r->body.find("not for the web") == std::string::npos) << path;
        return r ? r->status : -1;
    };
    EXPECT_EQ(code("/api/takes/link.cap/raw"), 403);  // a symlink out
    EXPECT_EQ(code("/api/takes/..secret.cap/raw"), 400);
    EXPECT_EQ(code("/api/takes/.hidden.cap/raw"), 400);
    EXPECT_EQ(code("/api/takes/status.json/raw"), 400);  // not a take
    // httplib decodes %2F before routing: these become paths no route matches.
    EXPECT_EQ(code("/api/takes/..%2Fsecret.cap/raw"), 404);
    EXPECT_EQ(code("/api/takes/%2E%2E%2Fsecret.cap/raw"), 404);
    EXPECT_EQ(code("/api/takes/../secret.cap/raw"), 404);
    EXPECT_EQ(code("/api/takes/%2Fetc%2Fpasswd/raw"), 404);
    EXPECT_EQ(code("/api/takes/sub%2Finner.cap/raw"), 404);
    EXPECT_EQ(code("/api/takes/..%2Fsecret.cap/export?format=bvh"), 404);
    EXPECT_EQ(code("/api/takes/link.cap/export?format=bvh"), 403);
    EXPECT_EQ(code("/api/takes/missing.cap/raw"), 404);
    // The same rule as a function, with what a client cannot send through the router.
    EXPECT_EQ(resolveTake(rig.recordings, "../secret.cap").error().code, EINVAL);
    EXPECT_EQ(resolveTake(rig.recordings, "/etc/passwd").error().code, EINVAL);
    EXPECT_EQ(resolveTake(rig.recordings, "sub/inner.cap").error().code, EINVAL);
    EXPECT_EQ(resolveTake(rig.recordings, "link.cap").error().code, EPERM);
    auto del = s.post("/api/takes/link.cap/delete", {{"confirm", "link.cap"}});
    ASSERT_TRUE(del);
    EXPECT_EQ(del->status, 403);
    EXPECT_TRUE(fs::exists(rig.dir / "secret.cap"));
    EXPECT_TRUE(fs::is_symlink(rig.recordings / "link.cap"));
    // The list leaves the symlink out.
    auto list = s.get("/api/takes");
    ASSERT_TRUE(list && list->status == 200);
    EXPECT_EQ(list->body.find("link.cap"), std::string::npos);
}

// A byte that is not UTF-8 in a path echoed into an error (`GET /%FF`, no login needed) threw
// from the JSON library inside the HTTP library's error handler, where nothing catches: the
// hub aborted, taking the capture with it. A take whose file name is not UTF-8 made the take
// list a 500. Both are answered, the bytes replaced by U+FFFD.
TEST(Serve, BytesThatAreNotUtf8AreAnsweredNotFatal) {
    ServeRig rig("utf8");
    httplib::Client anyone("127.0.0.1", rig.port());
    auto bad = anyone.Get("/%FF");
    ASSERT_TRUE(bad) << "no answer: the server is gone";
    EXPECT_EQ(bad->status, 404);
    const Json error = Json::parse(bad->body);
    EXPECT_EQ(error["error"].get<std::string>(), "no such route: GET /\xEF\xBF\xBD");
    auto after = anyone.Get("/api/session");
    ASSERT_TRUE(after) << "the server did not survive";
    EXPECT_EQ(after->status, 200);

    Session s(rig.port());
    std::ofstream(rig.recordings / "\xE9t\xE9.cap") << "a take named in Latin-1";
    auto list = s.get("/api/takes");
    ASSERT_TRUE(list) << "no answer";
    EXPECT_EQ(list->status, 200) << list->body;
    EXPECT_NE(list->body.find("\xEF\xBF\xBDt\xEF\xBF\xBD.cap"), std::string::npos) << list->body;
    // Nor does a take's description name the hub's folders (the export's errors do not).
    EXPECT_EQ(list->body.find(rig.recordings.string()), std::string::npos) << list->body;
}

// A login is JSON only: a page on another site can POST text/plain here without asking, and
// 32 such logins evicted the user's session. One range per download: 500 overlapping ranges
// sent a take 500 times over. A number no double holds in a body was a 500.
TEST(Serve, CrossSiteLoginsManyRangesAndHugeNumbersAreRefused) {
    ServeRig rig("refusals");
    httplib::Client c("127.0.0.1", rig.port());
    auto plain = c.Post("/api/login", "{}", "text/plain");
    ASSERT_TRUE(plain);
    EXPECT_EQ(plain->status, 415) << plain->body;
    EXPECT_FALSE(plain->has_header("Set-Cookie"));
    auto form = c.Post("/api/login", "password=x", "application/x-www-form-urlencoded");
    ASSERT_TRUE(form);
    EXPECT_EQ(form->status, 415) << form->body;
    Session s(rig.port());  // application/json: logs in

    std::string take(1000, 'x');
    for (std::size_t i = 0; i < take.size(); ++i) {
        take[i] = static_cast<char>('a' + i % 26);
    }
    std::ofstream(rig.recordings / "ranges.cap", std::ios::binary) << take;
    const auto ranged = [&](const std::string& range) {
        httplib::Headers h = s.headers();
        h.emplace("Range", range);
        return s.client.Get("/api/takes/ranges.cap/raw", h);
    };
    auto one = ranged("bytes=10-19");
    ASSERT_TRUE(one);
    EXPECT_EQ(one->status, 206);
    EXPECT_EQ(one->body, take.substr(10, 10));
    std::string many = "bytes=0-999";
    for (int i = 0; i < 100; ++i) {
        many += ",0-999";
    }
    auto amplified = ranged(many);
    ASSERT_TRUE(amplified);
    EXPECT_EQ(amplified->status, 416);
    EXPECT_LT(amplified->body.size(), 200u);
    auto none = ranged("bytes=-0");
    ASSERT_TRUE(none);
    EXPECT_EQ(none->status, 416);
    auto whole = s.get("/api/takes/ranges.cap/raw");
    ASSERT_TRUE(whole);
    EXPECT_EQ(whole->body, take);

    auto overflow = s.client.Post("/api/calibrate", s.headers(),
                                  R"({"pose": "tpose", "countdown_s": 1e400})", "application/json");
    ASSERT_TRUE(overflow);
    EXPECT_EQ(overflow->status, 400) << overflow->body;
}

TEST(Serve, ListeningBeyondThisMachineNeedsAPasswordThatIsThenRequired) {
    ServeRig rig("password");
    WebOptions w;
    w.host = "0.0.0.0";
    w.port = 0;
    w.recordings = rig.recordings;
    w.stateDir = rig.dir / "no-password-here";
    auto refused = WebServer::start(*rig.hub, rig.board, w);
    ASSERT_FALSE(refused.ok());
    EXPECT_EQ(refused.error().code, EPERM);
    EXPECT_NE(refused.error().message.find("--set-password"), std::string::npos);

    EXPECT_FALSE(setPassword(rig.stateDir, "short").ok());
    // The hash takes a C string: this one would have been "abc".
    const auto nul = setPassword(rig.stateDir, std::string("abc\0defghij", 11));
    ASSERT_FALSE(nul.ok());
    EXPECT_EQ(nul.error().message, "the password cannot contain a NUL byte");
    ASSERT_TRUE(setPassword(rig.stateDir, "correct horse").ok());
    EXPECT_EQ(fs::status(passwordFile(rig.stateDir)).permissions() & fs::perms::group_all,
              fs::perms::none);
    std::ifstream stored(passwordFile(rig.stateDir));
    const std::string hash((std::istreambuf_iterator<char>(stored)), {});
    EXPECT_EQ(hash.find("correct horse"), std::string::npos);
    EXPECT_TRUE(hash.starts_with("$argon2id$")) << hash;

    // A server started with the password set requires it, also on loopback.
    WebOptions l;
    l.port = 0;
    l.recordings = rig.recordings;
    l.stateDir = rig.stateDir;
    auto web = WebServer::start(*rig.hub, rig.board, l);
    ASSERT_TRUE(web.ok()) << web.error().message;
    httplib::Client c("127.0.0.1", (*web)->port());
    auto wrong = c.Post("/api/login", R"({"password": "wrong horse"})", "application/json");
    ASSERT_TRUE(wrong);
    EXPECT_EQ(wrong->status, 401);
    EXPECT_TRUE(wrong->get_header_value("Set-Cookie").empty());
    // A second guess from the same address within a second is refused at once, right or not.
    auto again = c.Post("/api/login", R"({"password": "correct horse"})", "application/json");
    ASSERT_TRUE(again);
    EXPECT_EQ(again->status, 429);
    EXPECT_TRUE(again->get_header_value("Set-Cookie").empty());
    std::this_thread::sleep_for(std::chrono::milliseconds(1100));
    auto none = c.Post("/api/login", "{}", "application/json");
    ASSERT_TRUE(none);
    EXPECT_EQ(none->status, 401);
    std::this_thread::sleep_for(std::chrono::milliseconds(1100));
    Session right((*web)->port(), "correct horse");
    EXPECT_FALSE(right.csrf.empty());
    EXPECT_TRUE(right.state().contains("sensors"));
}

// A connection to the server's port that sends `head` and then one byte every `everyMs` until
// the server closes it or `forMs` have passed; returns how long the server kept it (ms).
int trickle(int port, const std::string& head, int everyMs, int forMs) {
    const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(static_cast<std::uint16_t>(port));
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    const auto t0 = std::chrono::steady_clock::now();
    const auto since = [&t0] {
        return static_cast<int>(
            std::chrono::duration_cast<milliseconds>(std::chrono::steady_clock::now() - t0)
                .count());
    };
    if (::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) {
        ::close(fd);
        return -1;
    }
    bool open = ::send(fd, head.data(), head.size(), MSG_NOSIGNAL) > 0;
    while (open && since() < forMs) {
        pollfd p{fd, POLLIN, 0};
        if (::poll(&p, 1, everyMs) > 0) {
            char c;
            open = ::recv(fd, &c, 1, MSG_DONTWAIT) > 0;  // closed (or an answer: the end)
            break;
        }
        open = ::send(fd, "x", 1, MSG_NOSIGNAL) == 1;
    }
    const int held = since();
    ::close(fd);
    return held;
}

// Clients sending their requests a byte at a time (slowloris) held every worker for as long as
// they kept sending: the page and the API went unanswered. A request must now arrive within
// its deadline (here 2 s), after which its connection is closed and the worker freed.
TEST(Serve, ClientsSendingTheirRequestsAByteAtATimeDoNotHoldTheWorkers) {
    ServeRig rig("slow-requests", {}, 2.0);
    Session s(rig.port());
    constexpr int kSlow = 30;  // more than the 24 workers
    std::vector<int> held(kSlow, 0);
    std::vector<std::thread> slow;
    for (int i = 0; i < kSlow; ++i) {
        slow.emplace_back([&, i] {
            held[static_cast<std::size_t>(i)] = trickle(
                rig.port(), "GET /api/state HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Slow: ", 300, 12000);
        });
    }
    std::this_thread::sleep_for(milliseconds(500));  // every worker reading a slow request
    const auto t0 = std::chrono::steady_clock::now();
    httplib::Client c("127.0.0.1", rig.port());
    c.set_read_timeout(20, 0);
    c.set_connection_timeout(20, 0);
    auto r = c.Get("/api/state", s.headers());
    const double waitedS =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    for (auto& t : slow) {
        t.join();
    }
    EXPECT_EQ(status(r).substr(0, 3), "200") << status(r);
    // Answered once the slow requests' deadline freed a worker: about 1.5 s, not the 12 s they
    // would have gone on for.
    EXPECT_LT(waitedS, 5.0);
    for (int i = 0; i < kSlow; ++i) {
        EXPECT_GE(held[static_cast<std::size_t>(i)], 0) << "client " << i << " did not connect";
        EXPECT_LT(held[static_cast<std::size_t>(i)], 6000) << "client " << i;
    }
    std::cout << "a request among " << kSlow << " trickling clients answered in " << waitedS
              << " s\n";
}

// Clients that asked for a download and then read it slowly (here: not at all) each held a
// worker for as long as they went on, and enough of them held every worker. Downloads now
// have their own slots (WebOptions::maxDownloads, 6): the seventh is refused at once, the API
// is still answered, and a slot comes back when its client goes.
TEST(Serve, ClientsReadingDownloadsSlowlyHoldOnlyTheDownloadSlots) {
    ServeRig rig("slow-downloads");
    Session s(rig.port());
    // A take larger than the sockets' buffers hold.
    constexpr std::uintmax_t kBytes = 64u << 20;
    std::ofstream(rig.recordings / "big.cap").close();
    fs::resize_file(rig.recordings / "big.cap", kBytes);
    const std::string request =
        "GET /api/takes/big.cap/raw HTTP/1.1\r\nHost: 127.0.0.1\r\n"
        "Cookie: " +
        s.cookie + "\r\n\r\n";
    constexpr int kSlots = 6;
    std::vector<int> stuck;
    for (int i = 0; i < kSlots; ++i) {
        const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
        const int small = 4096;
        ::setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &small, sizeof small);
        sockaddr_in a{};
        a.sin_family = AF_INET;
        a.sin_port = htons(static_cast<std::uint16_t>(rig.port()));
        a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
        ASSERT_EQ(::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a), 0);
        ASSERT_EQ(::send(fd, request.data(), request.size(), MSG_NOSIGNAL),
                  static_cast<ssize_t>(request.size()));
        stuck.push_back(fd);
    }
    // Each holds its slot once its answer has begun.
    for (int fd : stuck) {
        pollfd p{fd, POLLIN, 0};
        ASSERT_EQ(::poll(&p, 1, 10000), 1);
    }
    auto refused = s.get("/api/takes/big.cap/raw");
    ASSERT_TRUE(refused);
    EXPECT_EQ(refused->status, 503);
    EXPECT_NE(refused->body.find("all 6 downloads are in use"), std::string::npos) << refused->body;
    EXPECT_EQ(status(s.get("/api/state")).substr(0, 3), "200");
    ::close(stuck.front());
    stuck.erase(stuck.begin());
    int code = -1;
    std::size_t got = 0;
    for (int i = 0; i < 50 && code != 200; ++i) {
        auto r = s.get("/api/takes/big.cap/raw");
        code = r ? r->status : -1;
        got = r ? r->body.size() : 0;
        if (code != 200) {
            std::this_thread::sleep_for(milliseconds(100));
        }
    }
    EXPECT_EQ(code, 200);
    EXPECT_EQ(got, kBytes);
    for (int fd : stuck) {
        ::close(fd);
    }
}

TEST(Serve, FiftyConcurrentClientsAreAllServedWhileTheCaptureLosesNoSample) {
    ServeRig rig("load");
    Session s(rig.port());
    ASSERT_TRUE(waitForState(s, [](const Json& j) { return j.contains("pose_latency_ms"); }));
    constexpr int kClients = 50;
    std::atomic<int> served{0};
    std::atomic<int> failed{0};
    std::atomic<int> streamed{0};
    std::vector<std::thread> clients;
    const auto t0 = std::chrono::steady_clock::now();
    for (int i = 0; i < kClients; ++i) {
        clients.emplace_back([&, i] {
            httplib::Client c("127.0.0.1", rig.port());
            c.set_connection_timeout(30, 0);
            c.set_read_timeout(30, 0);
            const httplib::Headers h{{"Cookie", s.cookie}};
            if (i % 5 == 0) {
                // Every fifth holds a pose stream for a while (10 streams of the 12 allowed).
                int events = 0;
                (void)c.Get("/api/poses", h, [&](const char* data, std::size_t n) {
                    events += static_cast<int>(std::string_view(data, n).find("data: ") !=
                                               std::string_view::npos);
                    return events < 30;
                });
                (events >= 30 ? streamed : failed).fetch_add(1);
                return;
            }
            for (int k = 0; k < 10; ++k) {
                auto r = c.Get(k % 5 == 4 ? "/api/takes" : "/api/state", h);
                (r && r->status == 200 ? served : failed).fetch_add(1);
            }
        });
    }
    for (auto& t : clients) {
        t.join();
    }
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    EXPECT_EQ(failed.load(), 0);
    EXPECT_EQ(served.load(), 40 * 10);
    EXPECT_EQ(streamed.load(), 10);
    const Json after = s.state();
    rig.web->stop();
    rig.hub->requestStop();
    const CaptureStats stats = rig.hub->wait();
    EXPECT_EQ(stats.dropped, 0u);
    EXPECT_EQ(stats.lost, 0u);
    EXPECT_GT(stats.samples, 0u);
    std::cout << "50 clients: " << served.load() << " requests and " << streamed.load()
              << " pose streams served in " << seconds << " s; capture: " << stats.samples
              << " samples, " << stats.dropped << " dropped, " << stats.lost
              << " lost; pose latency p99 " << after["pose_latency_ms"]["p99"] << " ms\n";
}

TEST(ServeCli, RefusesNetworkListeningWithoutAPasswordAndABadPort) {
    const fs::path state = fs::path(::testing::TempDir()) / "caphub-serve-cli-state";
    fs::remove_all(state);
    auto r = caphub::testing::caphub(
        "serve --board sim-upper10 --no-preview --listen 0.0.0.0:0 "
        "--state-dir " +
        state.string());
    EXPECT_EQ(r.exitCode, 2) << r.output;
    EXPECT_NE(r.output.find("needs a password"), std::string::npos) << r.output;
    auto bad = caphub::testing::caphub(
        "serve --board sim-upper10 --listen 127.0.0.1:abc "
        "--state-dir " +
        state.string());
    EXPECT_EQ(bad.exitCode, 2) << bad.output;
    EXPECT_NE(bad.output.find("--listen '127.0.0.1:abc'"), std::string::npos) << bad.output;
    auto pw = caphub::testing::shell("printf 'correct horse\\n' | " + std::string(CAPHUB_BINARY) +
                                     " serve --set-password --state-dir " + state.string());
    EXPECT_EQ(pw.exitCode, 0) << pw.output;
    EXPECT_TRUE(hasPassword(state));
    EXPECT_TRUE(checkPassword(state, "correct horse"));
    EXPECT_FALSE(checkPassword(state, "correct horse "));
}

// `caphub serve` in the background, on a free port: its pid and port from its first lines.
struct ServeProcess {
    FILE* pipe = nullptr;
    int pid = -1;
    int port = -1;
    std::string firstLine;

    explicit ServeProcess(const std::string& args) {
        pipe = popen(("sh -c 'echo $$; exec " + std::string(CAPHUB_BINARY) + " serve " + args +
                      " --listen 127.0.0.1:0' 2>&1")
                         .c_str(),
                     "r");
        if (pipe == nullptr) {
            return;
        }
        std::array<char, 4096> line{};
        if (fgets(line.data(), line.size(), pipe) != nullptr) {
            pid = std::atoi(line.data());
        }
        // The URL line (warnings may come first).
        while (fgets(line.data(), line.size(), pipe) != nullptr) {
            firstLine = line.data();
            const auto at = firstLine.find("http://127.0.0.1:");
            if (at != std::string::npos) {
                port = std::atoi(firstLine.c_str() + at + 17);
                break;
            }
        }
    }
    // SIGTERM, then the rest of its output.
    std::string stop() {
        std::string rest;
        if (pipe == nullptr) {
            return rest;
        }
        if (pid > 0) {
            ::kill(pid, SIGTERM);
        }
        std::array<char, 4096> buf{};
        std::size_t n = 0;
        while ((n = fread(buf.data(), 1, buf.size(), pipe)) > 0) {
            rest.append(buf.data(), n);
        }
        pclose(pipe);
        pipe = nullptr;
        return rest;
    }
    ~ServeProcess() { (void)stop(); }
};

// Waits (at most 5 minutes of real time: a debug or sanitizer build computes slowly on a loaded
// machine) until no guided procedure runs; its status, read fresh (the state document may be a
// quarter of a second old).
Json waitForProcedure(Session& s) {
    Json last;
    for (int i = 0; i < 3000; ++i) {
        auto g = s.get("/api/sensor-calibration");
        if (g && g->status == 200) {
            last = Json::parse(g->body);
            if (!last["running"].get<bool>()) {
                break;
            }
        }
        std::this_thread::sleep_for(milliseconds(100));
    }
    return last;
}

// Starts one guided procedure and waits for it to end; its status.
Json runProcedure(Session& s, const Json& request) {
    auto r = s.post("/api/sensor-calibration", request);
    EXPECT_TRUE(r && r->status == 202) << status(r);
    return waitForProcedure(s);
}

TEST(ServeCli, GuidedSensorCalibrationOnTheVirtualSuitIsSavedAndAppliedAtTheNextStart) {
    const fs::path dir = fs::path(::testing::TempDir()) / "caphub-serve-sensor-calibration";
    fs::remove_all(dir);
    fs::create_directories(dir / "recordings");
    const std::string args = "--board sim-upper10 --no-preview --state-dir " +
                             (dir / "state").string() + " --recordings " +
                             (dir / "recordings").string() + " --status-file " +
                             (dir / "status.json").string();
    const fs::path kept = dir / "state" / "calibration.toml";
    {
        ServeProcess serve(args);
        ASSERT_GT(serve.port, 0) << serve.firstLine << serve.stop();
        Session s(serve.port);
        Json st = s.state();
        EXPECT_TRUE(st["sensor_calibration"].is_null());
        EXPECT_TRUE(st["sensor_calibration_session"]["virtual_suit"].get<bool>());

        // Bad requests name the key; one procedure at a time.
        auto bad = s.post("/api/sensor-calibration", Json{{"kind", "accel"}, {"positions", 7}});
        EXPECT_TRUE(bad && bad->status == 400) << status(bad);
        EXPECT_NE(status(bad).find("positions"), std::string::npos);
        auto first = s.post("/api/sensor-calibration", Json{{"kind", "gyro"}});
        EXPECT_TRUE(first && first->status == 202) << status(first);
        auto busy = s.post("/api/sensor-calibration", Json{{"kind", "mag"}});
        EXPECT_TRUE(busy && busy->status == 409) << status(busy);
        auto cancel = s.post("/api/sensor-calibration/cancel");
        EXPECT_TRUE(cancel && cancel->status == 200) << status(cancel);
        EXPECT_EQ(waitForProcedure(s)["procedure"]["stage"], "cancelled");
        EXPECT_FALSE(fs::exists(kept));

        // The three procedures: the virtual subject does each motion.
        const Json gyro = runProcedure(s, Json{{"kind", "gyro"}});
        const Json accel = runProcedure(s, Json{{"kind", "accel"}, {"hold_s", 2}, {"move_s", 1}});
        const Json mag = runProcedure(s, Json{{"kind", "mag"}, {"duration_s", 20}});
        for (const Json* p : {&gyro, &accel, &mag}) {
            const Json& proc = (*p)["procedure"];
            EXPECT_EQ(proc["stage"], "done") << proc.dump(1);
            EXPECT_EQ(proc["result"]["calibrated"], 10) << proc.dump(1);
            EXPECT_EQ(proc["result"]["samples_dropped"], 0) << proc.dump(1);
            EXPECT_EQ((*p)["saved"], kept.string());
        }
        // Quality: the gyroscopes' noise at rest, the accelerometers' miss of g over the six
        // positions, the magnetometers' field-strength scatter after the fit.
        EXPECT_LT(gyro["procedure"]["result"]["quality"]["value"].get<double>(), 0.5);
        EXPECT_LT(accel["procedure"]["result"]["quality"]["value"].get<double>(), 0.05);
        EXPECT_EQ(accel["procedure"]["result"]["sensors"][0]["positions"], 6);
        EXPECT_LT(mag["procedure"]["result"]["quality"]["value"].get<double>(), 3.0);
        EXPECT_EQ(s.state()["sensor_calibration_session"]["applies"],
                  "at the next start of caphub serve");
        const std::string out = serve.stop();
        EXPECT_NE(out.find("sensor calibration mag: 10 of 10 sensors saved"), std::string::npos)
            << out;
    }
    // The file is the one `caphub calibrate` writes: each sensor has all three kinds, and the
    // gyroscope biases are those of the same simulated parts measured by `caphub calibrate`.
    auto set = readCalibrationFile(kept);
    ASSERT_TRUE(set.ok()) << set.error().message;
    ASSERT_EQ(set->size(), 10U);
    for (const auto& [name, cal] : *set) {
        EXPECT_TRUE(cal.hasGyro && cal.hasAccel && cal.hasMag) << name;
    }
    const fs::path reference = dir / "reference.toml";
    auto ref =
        caphub::testing::caphub("calibrate gyro --board sim-upper10 --file " + reference.string());
    ASSERT_EQ(ref.exitCode, 0) << ref.output;
    auto refSet = readCalibrationFile(reference);
    ASSERT_TRUE(refSet.ok());
    for (const auto& [name, cal] : *refSet) {
        EXPECT_LT((cal.gyroBiasRadS - set->at(name).gyroBiasRadS).norm() * 180 / 3.14159, 0.05)
            << name;
    }

    // The next start applies it, and says so.
    ServeProcess again(args);
    ASSERT_GT(again.port, 0) << again.firstLine << again.stop();
    Session s(again.port);
    const Json st = s.state();
    EXPECT_EQ(st["sensor_calibration"], kept.string());
    EXPECT_EQ(st["sensor_calibration_session"]["in_force"], kept.string());
}

}  // namespace
}  // namespace caphub::firmware::serve
