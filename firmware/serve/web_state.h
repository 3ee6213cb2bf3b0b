// The inside of `caphub serve`'s HTTP side (not part of the API): the server's shared state and
// the helpers every group of routes uses. The routes are grouped by concept, each group in a
// file of its own:
//   web_session_routes.cpp   the page's files, login, logout, the access check
//   web_live_routes.cpp      the state document (polled and as events), poses, the preview
//   web_command_routes.cpp   commands into the Hub: takes, markers, body calibration, heading
//   web_take_routes.cpp      the take list, each take's summary, downloads, exports, deletion
//   web_sensor_calibration_routes.cpp   the guided sensor calibration
#pragma once

// clang-format off
// First: Eigen (through the Hub) before httplib, whose <resolv.h> defines _res, a name Eigen
// uses as a parameter.
#include "firmware/serve/web_server.h"
// clang-format on

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <filesystem>
#include <functional>
#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

#include <httplib.h>
#include <nlohmann/json.hpp>

#include "firmware/cli/info.h"
#include "firmware/serve/auth.h"
#include "firmware/serve/request_deadline.h"
#include "firmware/serve/web_server.h"

namespace caphub::firmware::serve {

using Json = nlohmann::ordered_json;
using SteadyClock = std::chrono::steady_clock;

inline constexpr const char* kSessionCookie = "caphub_session";
inline constexpr const char* kCsrfHeader = "X-CSRF-Token";

// A JSON answer (never cached).
void reply(httplib::Response& res, int status, const Json& body);
// {"error": message}.
void fail(httplib::Response& res, int status, const std::string& message);
// The HTTP status for an error of a Hub command or a file operation.
int statusFor(const Error& e);
// fail() with the error's status and message.
void failWith(httplib::Response& res, const Error& e);
std::string cookieValue(const httplib::Request& req, const std::string& name);
// The host part of a Host header ("127.0.0.1:8080", "[::1]:8080", "localhost").
std::string hostOf(const std::string& header);
// Streams a file in 64 KiB pieces as a download; `removeAfter` deletes it when the response is
// done (or could not start), and `done` (a download slot's release) is called then too.
void streamFile(httplib::Response& res, const std::filesystem::path& path, const std::string& mime,
                const std::string& downloadName, bool removeAfter, std::function<void()> done);
// A query parameter as a number >= 0 (none: nullopt); a bad one sets `error`.
std::optional<double> numberParam(const httplib::Request& req, const char* key, std::string& error);

using Handler = std::function<void(const httplib::Request&, httplib::Response&)>;

struct WebServer::State {
    State(Hub& h, const board::Board& b, WebOptions o) : hub(h), board(b), options(std::move(o)) {}

    Hub& hub;
    const board::Board& board;
    WebOptions options;
    RequestDeadlineServer server;
    std::thread listener;
    std::thread stateReader;
    int port = 0;
    int listenSocket = -1;
    bool passwordRequired = false;
    Sessions sessions;
    std::mutex loginMutex;  // one password check at a time (each costs 64 MiB and ~0.1 s)
    // After a wrong password, when each client address may guess again (a guess before then is
    // answered 429 at once: no worker waits, and other clients log in as before).
    std::mutex guessMutex;
    std::map<std::string, std::chrono::steady_clock::time_point> nextGuess;

    // The latest state document, for every client.
    std::mutex mutex;
    std::condition_variable cv;
    std::string stateJson = "{}";
    std::uint64_t stateSequence = 0;
    bool stopping = false;

    std::atomic<int> streams{0};
    std::atomic<int> downloads{0};

    // The body calibration's countdown, for the page (wall time).
    std::mutex calibrationMutex;
    std::string calibrationKind;
    std::optional<SteadyClock::time_point> tAt;
    std::optional<SteadyClock::time_point> nAt;

    // One export at a time: they read whole takes.
    std::timed_mutex exportMutex;
    std::mutex exportStatusMutex;
    Json exportStatus;  // null: none running

    // Each take's summary reads the whole take: kept while the file is unchanged.
    std::mutex summaryMutex;
    struct CachedSummary {
        std::uint64_t bytes = 0;
        std::int64_t modified = 0;
        RecordingSummary summary;
    };
    std::map<std::string, CachedSummary> summaries;

    // The take being recorded, as the commands left it (the state document may be older).
    std::mutex takeMutex;
    std::string takeFile;

    bool waitStopping(std::chrono::milliseconds d) {
        std::unique_lock lock(mutex);
        return cv.wait_for(lock, d, [&] { return stopping; });
    }
    std::string currentTakeName() {
        std::lock_guard lock(takeMutex);
        return takeFile;
    }
    void setCurrentTake(std::string file) {
        std::lock_guard lock(takeMutex);
        takeFile = std::move(file);
    }

    // Checks the request may go on; answers it (401, 403) when not.
    bool authorize(const httplib::Request& req, httplib::Response& res, bool changesState);
    // The request's JSON object (an empty body: {}); answers 400 when it is not one.
    std::optional<Json> parseBody(const httplib::Request& req, httplib::Response& res);
    // A handler run only for a logged-in session (reading).
    Handler guarded(Handler fn);
    // A state-changing handler: logged in, the CSRF header, a JSON object body.
    Handler command(std::function<void(const Json&, httplib::Response&)> fn);
    // A handler of one take, /api/takes/NAME...: logged in and NAME a take of the folder.
    Handler takeHandler(
        bool changesState,
        std::function<void(const httplib::Request&, httplib::Response&, const std::string& name,
                           const std::filesystem::path& path)>
            fn);

    // Reserves one of the stream slots; false (and 503) when all are taken. releaseStream()
    // gives it back (the stream's done-callback).
    bool takeStream(httplib::Response& res);
    std::function<void(bool)> releaseStream();
    // Reserves one of the download slots; false (and 503) when all are taken. The slot is given
    // back by the release streamFile() is handed, or by release() of a slot never handed over.
    class DownloadSlot {
    public:
        DownloadSlot(std::atomic<int>& count, int max, httplib::Response& res);
        ~DownloadSlot() { release(); }
        DownloadSlot(const DownloadSlot&) = delete;
        DownloadSlot& operator=(const DownloadSlot&) = delete;
        bool held() const { return held_; }
        void release();
        // The slot's release, for the download's end (streamFile); this object lets go of it.
        std::function<void()> handOver();

    private:
        std::atomic<int>& count_;
        bool held_ = false;
    };
    // A guarded stream of Server-Sent Events in a stream slot: makeNext() gives each client its
    // writer of the next event (waiting a while for one); the writer's false ends the stream.
    Handler eventStream(std::function<std::function<bool(httplib::DataSink&)>()> makeNext);

    Json buildState(const HubState& h);
    void readStateLoop();
    Json skeletonJson() const;
    // The summary of a take not being recorded, cached while the file is unchanged.
    Result<RecordingSummary> summaryOf(const std::string& name, std::uint64_t bytes,
                                       std::int64_t modified);

    void sessionRoutes();
    void liveRoutes();
    void commandRoutes();
    void takeRoutes();
    void sensorCalibrationRoutes();
};

}  // namespace caphub::firmware::serve
