#include "firmware/runtime/status_stage.h"

#include <algorithm>
#include <cstdlib>

#include <nlohmann/json.hpp>
#include <sys/stat.h>
#include <unistd.h>

#include "board/bus_budget.h"
#include "firmware/runtime/thread_policy.h"
#include "hal/core/log.h"
#include "hal/core/output_fd.h"

namespace caphub::firmware {

namespace fs = std::filesystem;

fs::path defaultStatusPath() {
    if (const char* env = std::getenv("CAPHUB_STATUS"); env != nullptr && *env != '\0') {
        return env;
    }
    std::error_code ec;
    if (fs::is_directory("/run/caphub", ec)) {
        return "/run/caphub/status.json";
    }
    return fs::temp_directory_path(ec) / "caphub-status.json";
}

StatusStage::StatusStage(const board::Board& board, const Capture& capture,
                         const RecorderStage* recorder, fs::path path, Clock& clock)
    : board_(board),
      capture_(capture),
      recorder_(recorder),
      path_(std::move(path)),
      clock_(clock),
      samples_(board.sensors.size(), 0),
      samplesAtLastWrite_(board.sensors.size(), 0),
      events_(board.sensors.size(), 0),
      writer_("caphub-status",
              [this](const StatusSnapshot& snap) { writeFile(statusJson(snap)); }) {
    for (const auto& load : board::computeBusLoads(board)) {
        plannedLoad_.push_back(load.utilisation);
    }
}

StatusStage::~StatusStage() = default;

void StatusStage::onSample(const SensorSample& s) {
    const auto i = static_cast<std::size_t>(s.sensor);
    if (i < samples_.size()) {
        ++samples_[i];
    }
    latency_.add(clock_.now() - s.sample.t);
}

void StatusStage::onEvent(const RuntimeEvent& e) {
    if (e.sensor >= 0 && static_cast<std::size_t>(e.sensor) < events_.size()) {
        ++events_[static_cast<std::size_t>(e.sensor)];
    }
}

void StatusStage::onTick(Timestamp now) {
    if (first_) {
        first_ = false;
        started_ = now;
        lastWrite_ = now;
        publish(now, true);
        return;
    }
    if (now - lastWrite_ >= std::chrono::seconds(1)) {
        publish(now, true);
    }
}

void StatusStage::finish(Timestamp now) {
    if (first_) {
        started_ = now;
        lastWrite_ = now;
        first_ = false;
    }
    publish(now, false);
    writer_.flush();
}

StatusSnapshot StatusStage::latest() const {
    return writer_.latest();
}

std::uint64_t StatusStage::written() const {
    return writer_.written();
}

StatusSnapshot StatusStage::snapshot(Timestamp now, bool running) const {
    StatusSnapshot s;
    s.board = board_.name;
    s.running = running;
    s.uptimeS = toSeconds(now - started_);
    const double sinceWrite = std::max(1e-9, toSeconds(now - lastWrite_));
    for (const auto& w : capture_.workers()) {
        for (std::size_t k = 0; k < w->sensorCount(); ++k) {
            const auto i = static_cast<std::size_t>(w->hardware().sensors[k].sensor);
            const auto& c = w->counters(k);
            StatusSnapshot::Sensor o;
            o.name = board_.sensors[i].name;
            o.segment = std::string(board::segmentName(board_.sensors[i].segment));
            o.online = c.online.load();
            o.samples = samples_[i];
            o.rateHz = static_cast<double>(samples_[i] - samplesAtLastWrite_[i]) / sinceWrite;
            o.configuredHz = board_.sensors[i].achievedOdrHz;
            o.readErrors = c.readErrors.load();
            o.dropped = c.dropped.load();
            o.lost = c.lost.load();
            o.events = events_[i];
            if (fusion_ != nullptr) {
                o.heading = key(fusion_->magMode(static_cast<int>(i)));
                o.headingLearning = fusion_->magLearning(static_cast<int>(i));
            }
            s.sensors.push_back(std::move(o));
        }
    }
    for (const auto& w : capture_.workers()) {
        const auto b = static_cast<std::size_t>(w->hardware().bus);
        StatusSnapshot::Bus o;
        o.name = board_.buses[b].name;
        o.plannedLoad = b < plannedLoad_.size() ? plannedLoad_[b] : 0.0;
        if (const hal::BusCounters* c = w->hardware().counters()) {
            o.counted = true;
            o.transactions = c->transactions.load();
            o.bytes = c->bytes.load();
            o.errors = c->errors.load();
        }
        s.buses.push_back(std::move(o));
    }
    s.latency = latency_;  // a copy: the percentiles are sorted on the writer thread
    if (const RecordingWriter* w = recorder_ != nullptr ? recorder_->current() : nullptr) {
        const auto st = w->stats();
        s.recording = StatusSnapshot::Recording{
            st.records, st.bytesWritten, st.durableRecords, st.syncs,
            recorder_->error() == 0 ? std::string() : errnoText(recorder_->error())};
    }
    return s;
}

void StatusStage::publish(Timestamp now, bool running) {
    StatusSnapshot s = snapshot(now, running);
    lastWrite_ = now;
    samplesAtLastWrite_ = samples_;
    writer_.publish(std::move(s));
}

std::string statusJson(const StatusSnapshot& s) {
    nlohmann::ordered_json doc;
    doc["board"] = s.board;
    doc["running"] = s.running;
    doc["uptime_s"] = s.uptimeS;
    nlohmann::ordered_json sensors = nlohmann::ordered_json::array();
    for (const auto& o : s.sensors) {
        nlohmann::ordered_json j;
        j["name"] = o.name;
        j["segment"] = o.segment;
        j["online"] = o.online;
        j["samples"] = o.samples;
        j["rate_hz"] = o.rateHz;
        j["configured_hz"] = o.configuredHz;
        j["read_errors"] = o.readErrors;
        j["dropped"] = o.dropped;
        j["lost"] = o.lost;
        j["events"] = o.events;
        if (!o.heading.empty()) {
            j["heading"] = o.heading;
        }
        if (const auto& l = o.headingLearning) {
            // docs/serve.md: what a gyroscope-only heading waits for before its step.
            nlohmann::ordered_json h;
            h["waiting_for"] = l->waitingFor;
            h["readings_s"] = l->readingsS;
            h["needed_s"] = l->neededS;
            if (l->solved) {
                h["spread"] = l->spread;
                h["needed_spread"] = l->neededSpread;
                h["residual_pct"] = l->residualPct;
                h["max_residual_pct"] = l->maxResidualPct;
                h["field_ut"] = l->fieldUt;
            }
            j["heading_learning"] = h;
        }
        sensors.push_back(j);
    }
    doc["sensors"] = sensors;
    nlohmann::ordered_json buses = nlohmann::ordered_json::array();
    for (const auto& o : s.buses) {
        nlohmann::ordered_json bus;
        bus["name"] = o.name;
        bus["planned_load"] = o.plannedLoad;
        if (o.counted) {
            bus["transactions"] = o.transactions;
            bus["bytes"] = o.bytes;
            bus["errors"] = o.errors;
        }
        buses.push_back(bus);
    }
    doc["buses"] = buses;
    if (const std::size_t n = s.latency.size(); n > 0) {
        const auto ms = [](Duration d) { return toSeconds(d) * 1e3; };
        doc["latency_ms"] = {{"window", n},
                             {"p50", ms(s.latency.percentile(0.5))},
                             {"p99", ms(s.latency.percentile(0.99))},
                             {"max", ms(s.latency.max())}};
    }
    if (s.recording) {
        const auto& r = *s.recording;
        doc["recording"] = {{"records", r.records},
                            {"bytes", r.bytes},
                            {"durable_records", r.durableRecords},
                            {"syncs", r.syncs},
                            {"error", r.error}};
    } else {
        doc["recording"] = nullptr;
    }
    // A byte that is not UTF-8 (a path) is written as U+FFFD: the JSON library throws on it.
    return doc.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) + "\n";
}

void StatusStage::writeFile(const std::string& text) {
    std::error_code ec;
    // Only a regular file (or none) is replaced: a device or a FIFO given as the status file (or
    // put there since) is left as it is.
    struct stat st {};
    if (::lstat(path_.c_str(), &st) == 0 && !S_ISREG(st.st_mode)) {
        ec = std::make_error_code(std::errc::invalid_argument);
    }
    // Per process: two captures sharing a status path never write into each other's file.
    if (!ec) {
        const fs::path tmp = fs::path(path_.string() + "." + std::to_string(getpid()) + ".tmp");
        if (auto written = replaceFileWhole(path_, tmp, text); !written) {
            ec = std::error_code(written.error().code, std::generic_category());
        }
    }
    if (ec && error_.empty()) {
        error_ = ec.message();
        log::logger(log::Category::Firmware)
            .warn("status file {}: {} (the capture goes on)", path_.string(), error_);
    }
}

}  // namespace caphub::firmware
