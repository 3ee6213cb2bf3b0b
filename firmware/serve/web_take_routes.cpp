// The takes: the list (each with its `caphub info` summary), one take's summary, the raw .cap,
// exports made on demand (one at a time, with progress in the state), deletion with confirmation.
// Every name a client sends goes through resolveTake (takes.h).
#include <fmt/format.h>

#include "firmware/export/export.h"
#include "firmware/serve/takes.h"
#include "firmware/serve/web_state.h"
#include "hal/core/log.h"

namespace caphub::firmware::serve {

namespace fs = std::filesystem;

namespace {

// A take's description for the page: its file name where the text names the hub's own path
// (the export's errors hide the hub's folders too).
std::string withoutHubPath(std::string text, const fs::path& takePath) {
    const std::string full = takePath.string();
    const std::string name = takePath.filename().string();
    for (std::size_t at = text.find(full); !full.empty() && at != std::string::npos;
         at = text.find(full, at + name.size())) {
        text.replace(at, full.size(), name);
    }
    return text;
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

}  // namespace

Result<RecordingSummary> WebServer::State::summaryOf(const std::string& name, std::uint64_t bytes,
                                                     std::int64_t modified) {
    {
        std::lock_guard lock(summaryMutex);
        auto it = summaries.find(name);
        if (it != summaries.end() && it->second.bytes == bytes && it->second.modified == modified) {
            return it->second.summary;
        }
    }
    auto made = summarizeRecording((options.recordings / name).string());
    if (made) {
        std::lock_guard lock(summaryMutex);
        summaries[name] = {bytes, modified, *made};
    }
    return made;
}

void WebServer::State::takeRoutes() {
    State* s = this;
    server.Get("/api/takes", guarded([s](const httplib::Request&, httplib::Response& res) {
                   const std::string recording = s->currentTakeName();
                   Json list = Json::array();
                   for (const auto& t : listTakes(s->options.recordings)) {
                       Json j{{"file", t.name},
                              {"bytes", t.bytes},
                              {"modified", t.modifiedUnixS},
                              {"recording", t.name == recording}};
                       if (t.name != recording) {
                           const auto summary = s->summaryOf(t.name, t.bytes, t.modifiedUnixS);
                           if (summary) {
                               j["duration_s"] = summary->durationS;
                               j["records"] = summary->records;
                               j["poses"] = summary->poses;
                               j["markers"] = summary->markers;
                               j["damaged_ranges"] = summary->damagedRanges;
                               j["info"] =
                                   withoutHubPath(summary->text, s->options.recordings / t.name);
                           } else {
                               j["summary_error"] = withoutHubPath(summary.error().message,
                                                                   s->options.recordings / t.name);
                           }
                       }
                       list.push_back(std::move(j));
                   }
                   reply(res, 200, Json{{"takes", list}});
               }));
    server.Get(R"(/api/takes/([^/]+)/raw)",
               takeHandler(false, [s](const httplib::Request&, httplib::Response& res,
                                      const std::string& name, const fs::path& path) {
                   State::DownloadSlot slot(s->downloads, s->options.maxDownloads, res);
                   if (!slot.held()) {
                       return;
                   }
                   streamFile(res, path, "application/octet-stream", name, false, slot.handOver());
               }));
    server.Get(R"(/api/takes/([^/]+)/export)",
               takeHandler(false, [s](const httplib::Request& req, httplib::Response& res,
                                      const std::string& name, const fs::path& path) {
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
                   const std::string reference = req.get_param_value("reference_frame");
                   if (!reference.empty() && reference != "0" && reference != "1") {
                       error = "reference_frame: expected 0 or 1";  // "2" was taken as 0
                   }
                   o.referenceFrame = reference == "1";
                   if (o.referenceFrame && o.format != exporter::Format::Bvh) {
                       error = "reference_frame is for bvh only";
                   }
                   if (!error.empty()) {
                       fail(res, 400, error);
                       return;
                   }
                   State::DownloadSlot slot(s->downloads, s->options.maxDownloads, res);
                   if (!slot.held()) {
                       return;
                   }
                   // Answered at once: a request waiting up to 30 s for the export before it held a
                   // worker thread, and 26 of them left none for anyone else.
                   std::unique_lock lock(s->exportMutex, std::defer_lock);
                   if (!lock.try_lock()) {
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
                       path.string(), out.string(), o, [s](std::string_view stage, double f) {
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
                       // Said of the take and the query's parameters, not of the hub's paths
                       // and the command line's options.
                       std::string message = summary.error().message;
                       for (const auto& [from, to] :
                            {std::pair<std::string, std::string>{path.string(), name},
                             {"--rate", "rate"},
                             {"--from", "from"},
                             {"--to", "to"}}) {
                           for (auto at = message.find(from); at != std::string::npos;
                                at = message.find(from, at + to.size())) {
                               message.replace(at, from.size(), to);
                           }
                       }
                       // A take with nothing to export (no poses) is the request's, not the hub's.
                       const int code = summary.error().code;
                       fail(res, code == ENODATA ? 422 : statusFor(summary.error()), message);
                       return;
                   }
                   res.set_header("X-Caphub-Frames", std::to_string(summary->frames));
                   streamFile(res, out, mimeOf(o.format),
                              fs::path(name).stem().string() + extensionOf(o.format), true,
                              slot.handOver());
               }));
    server.Get(R"(/api/takes/([^/]+))",
               takeHandler(false, [](const httplib::Request&, httplib::Response& res,
                                     const std::string&, const fs::path& path) {
                   auto summary = summarizeRecording(path.string());
                   if (!summary) {
                       fail(res, 422, withoutHubPath(summary.error().message, path));
                       return;
                   }
                   reply(res, 200,
                         Json{{"file", path.filename().string()},
                              {"duration_s", summary->durationS},
                              {"records", summary->records},
                              {"poses", summary->poses},
                              {"markers", summary->markers},
                              {"info", withoutHubPath(summary->text, path)}});
               }));
    server.Post(
        R"(/api/takes/([^/]+)/delete)",
        takeHandler(true, [s](const httplib::Request& req, httplib::Response& res,
                              const std::string& name, const fs::path& path) {
            auto b = s->parseBody(req, res);
            if (!b) {
                return;
            }
            const Json confirm = b->value("confirm", Json());
            if (!confirm.is_string() || confirm.get<std::string>() != name) {
                fail(res, 400, "to delete a take, give its file name again as \"confirm\"");
                return;
            }
            // Asked of the hub, in turn with its commands: a take whose start was still being
            // carried out was deleted under its writer (the page's own record of it came late).
            if (auto deleted = s->hub.deleteTakeFile(path); !deleted) {
                fail(res, deleted.error().code == EBUSY ? 409 : 500, deleted.error().message);
                return;
            }
            {
                std::lock_guard lock(s->summaryMutex);
                s->summaries.erase(name);
            }
            log::logger(log::Category::Firmware).info("take deleted from the web: {}", name);
            reply(res, 200, Json{{"deleted", name}});
        }));
}

}  // namespace caphub::firmware::serve
