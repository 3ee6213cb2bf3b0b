#include "firmware/runtime/status_stage.h"

#include <algorithm>
#include <cstdlib>
#include <fstream>

#include <nlohmann/json.hpp>
#include <unistd.h>

#include "board/bus_budget.h"
#include "hal/core/log.h"

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
      events_(board.sensors.size(), 0) {
    for (const auto& load : board::computeBusLoads(board)) {
        plannedLoad_.push_back(load.utilisation);
    }
}

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
        write(now, true);
        return;
    }
    if (now - lastWrite_ >= std::chrono::seconds(1)) {
        write(now, true);
    }
}

void StatusStage::finish(Timestamp now) {
    write(now, false);
}

std::string StatusStage::json(Timestamp now, bool running) const {
    nlohmann::ordered_json doc;
    doc["board"] = board_.name;
    doc["running"] = running;
    doc["uptime_s"] = toSeconds(now - started_);
    const double sinceWrite = std::max(1e-9, toSeconds(now - lastWrite_));
    nlohmann::ordered_json sensors = nlohmann::ordered_json::array();
    for (const auto& w : capture_.workers()) {
        for (std::size_t k = 0; k < w->sensorCount(); ++k) {
            const auto i = static_cast<std::size_t>(w->hardware().sensors[k].sensor);
            const auto& c = w->counters(k);
            nlohmann::ordered_json s;
            s["name"] = board_.sensors[i].name;
            s["segment"] = std::string(board::segmentName(board_.sensors[i].segment));
            s["online"] = c.online.load();
            s["samples"] = samples_[i];
            s["rate_hz"] = static_cast<double>(samples_[i] - samplesAtLastWrite_[i]) / sinceWrite;
            s["configured_hz"] = board_.sensors[i].achievedOdrHz;
            s["read_errors"] = c.readErrors.load();
            s["dropped"] = c.dropped.load();
            s["lost"] = c.lost.load();
            s["events"] = events_[i];
            sensors.push_back(s);
        }
    }
    doc["sensors"] = sensors;
    nlohmann::ordered_json buses = nlohmann::ordered_json::array();
    for (const auto& w : capture_.workers()) {
        const auto b = static_cast<std::size_t>(w->hardware().bus);
        nlohmann::ordered_json bus;
        bus["name"] = board_.buses[b].name;
        bus["planned_load"] = b < plannedLoad_.size() ? plannedLoad_[b] : 0.0;
        if (const hal::BusCounters* c = w->hardware().counters()) {
            bus["transactions"] = c->transactions.load();
            bus["bytes"] = c->bytes.load();
            bus["errors"] = c->errors.load();
        }
        buses.push_back(bus);
    }
    doc["buses"] = buses;
    if (const std::size_t n = latency_.size(); n > 0) {
        const auto ms = [](Duration d) { return toSeconds(d) * 1e3; };
        doc["latency_ms"] = {{"window", n},
                             {"p50", ms(latency_.percentile(0.5))},
                             {"p99", ms(latency_.percentile(0.99))},
                             {"max", ms(latency_.max())}};
    }
    if (recorder_ != nullptr) {
        const auto st = recorder_->writer().stats();
        doc["recording"] = {
            {"records", st.records},
            {"bytes", st.bytesWritten},
            {"durable_records", st.durableRecords},
            {"syncs", st.syncs},
            {"error", recorder_->error() == 0 ? "" : errnoText(recorder_->error())}};
    } else {
        doc["recording"] = nullptr;
    }
    return doc.dump(2) + "\n";
}

void StatusStage::write(Timestamp now, bool running) {
    const std::string text = json(now, running);
    lastWrite_ = now;
    samplesAtLastWrite_ = samples_;
    // Per process: two captures sharing a status path never write into each other's file.
    const fs::path tmp = fs::path(path_.string() + "." + std::to_string(getpid()) + ".tmp");
    std::error_code ec;
    {
        std::ofstream out(tmp, std::ios::trunc);
        out << text;
        if (!out) {
            ec = std::make_error_code(std::errc::io_error);
        }
    }
    if (!ec) {
        fs::rename(tmp, path_, ec);
    }
    if (ec && error_.empty()) {
        error_ = ec.message();
        log::logger(log::Category::Firmware)
            .warn("status file {}: {} (the capture goes on)", path_.string(), error_);
    }
}

}  // namespace caphub::firmware
