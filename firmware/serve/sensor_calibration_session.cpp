#include "firmware/serve/sensor_calibration_session.h"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

#include "board/sim/scripted_motion.h"
#include "firmware/calibration_file.h"
#include "firmware/sensor_calibration_steps.h"
#include "hal/core/angles.h"
#include "hal/core/log.h"

namespace caphub::firmware::serve {

namespace fs = std::filesystem;
namespace bs = board::sim;
using Json = nlohmann::ordered_json;

namespace {

using hal::kRadToDeg;

const char* kindName(SensorCalibrationKind k) {
    switch (k) {
        case SensorCalibrationKind::Gyro:
            return "gyro";
        case SensorCalibrationKind::Accel:
            return "accel";
        case SensorCalibrationKind::Mag:
            return "mag";
    }
    return "?";
}

// The sensor-frame direction that points up in position k, as a person reads it ("+z", "+x-y+z").
std::string upText(int positions, int k) {
    if (positions == 6) {
        static constexpr const char* kSix[] = {"+z", "-z", "+x", "-x", "+y", "-y"};
        return kSix[std::clamp(k, 0, 5)];
    }
    const Vec3d up = bs::ScriptedMotion::fourteenUp(k);
    std::string text;
    const char* axes = "xyz";
    for (int a = 0; a < 3; ++a) {
        if (std::abs(up[a]) > 0.1) {
            text += fmt::format("{}{}", up[a] > 0 ? '+' : '-', axes[a]);
        }
    }
    return text;
}

double number(const Json& j, const char* key, double fallback, double lo, double hi,
              std::string& error) {
    if (!j.contains(key)) {
        return fallback;
    }
    const Json& v = j[key];
    if (!v.is_number() || v.get<double>() < lo || v.get<double>() > hi) {
        error = fmt::format("{}: expected a number from {:g} to {:g}", key, lo, hi);
        return fallback;
    }
    return v.get<double>();
}

// One kind's calibration of every sensor, merged into `set`: each sensor's row for the page and
// the quality figure of the worst sensor.
struct Computed {
    Json sensors = Json::array();
    int done = 0;
    Json quality;
};

Computed computeAll(SensorCalibrationKind kind, const board::Board& board,
                    const CalibrationSamples& samples, CalibrationSet& set) {
    Computed out;
    double worst = 0;
    double minCoverage = 1;
    for (std::size_t i = 0; i < board.sensors.size(); ++i) {
        const std::string& name = board.sensors[i].name;
        fusion::SensorCalibration cal =
            set.count(name) != 0 ? set[name] : fusion::SensorCalibration{};
        Json row{{"name", name}};
        std::string failure;
        switch (kind) {
            case SensorCalibrationKind::Gyro: {
                const auto g = calibrateGyroBias(samples, i, cal);
                if (!g) {
                    failure = g.error().message;
                    break;
                }
                const double stdDps = g->stdRadS.maxCoeff() * kRadToDeg;
                row["samples"] = g->samples;
                row["bias_dps"] = g->biasRadS.norm() * kRadToDeg;
                row["noise_dps"] = stdDps;
                worst = std::max(worst, stdDps);
                break;
            }
            case SensorCalibrationKind::Accel: {
                const auto a = calibrateAxes(samples, i, cal);
                if (!a) {
                    failure = a.error().message;
                    break;
                }
                row["positions"] = a->heldPositions;
                row["residual_mps2"] = a->acc.residualMps2;
                row["gyro_axes"] = a->gyro.has_value();
                worst = std::max(worst, a->acc.residualMps2);
                break;
            }
            case SensorCalibrationKind::Mag: {
                const auto m = calibrateMagnetometer(samples, i, cal);
                if (!m) {
                    failure = m.error().message;
                    break;
                }
                row["readings"] = samples.mag[i].size();
                row["quality_pct"] = m->fit.qualityPct;
                row["coverage"] = m->fit.coverage;
                row["aligned"] = m->align.has_value();
                worst = std::max(worst, m->fit.qualityPct);
                minCoverage = std::min(minCoverage, m->fit.coverage);
                break;
            }
        }
        row["ok"] = failure.empty();
        if (!failure.empty()) {
            row["error"] = failure;
        } else {
            set[name] = cal;
            ++out.done;
        }
        out.sensors.push_back(std::move(row));
    }
    switch (kind) {
        case SensorCalibrationKind::Gyro:
            out.quality = {{"figure", "gyroscope noise at rest, worst sensor"},
                           {"value", worst},
                           {"unit", "deg/s"}};
            break;
        case SensorCalibrationKind::Accel:
            out.quality = {{"figure",
                            "RMS miss of |acceleration| from g over the positions, worst "
                            "sensor"},
                           {"value", worst},
                           {"unit", "m/s^2"}};
            break;
        case SensorCalibrationKind::Mag:
            out.quality = {{"figure", "RMS scatter of the corrected field strength, worst sensor"},
                           {"value", worst},
                           {"unit", "%"},
                           {"coverage", minCoverage}};
            break;
    }
    return out;
}

}  // namespace

Result<SensorCalibrationRequest> parseSensorCalibrationRequest(const Json& j) {
    SensorCalibrationRequest r;
    const Json kind = j.value("kind", Json());
    if (!kind.is_string()) {
        return Error{EINVAL, "kind: expected \"gyro\", \"accel\" or \"mag\""};
    }
    const std::string k = kind.get<std::string>();
    if (k == "gyro") {
        r.kind = SensorCalibrationKind::Gyro;
    } else if (k == "accel") {
        r.kind = SensorCalibrationKind::Accel;
    } else if (k == "mag") {
        r.kind = SensorCalibrationKind::Mag;
    } else {
        return Error{EINVAL, fmt::format("kind: expected gyro, accel or mag, got '{}'", k)};
    }
    std::string error;
    const double positions = number(j, "positions", 6, 6, 14, error);
    if (positions != 6 && positions != 14) {
        error = "positions: expected 6 or 14";
    }
    r.positions = static_cast<int>(positions);
    r.holdS = number(j, "hold_s", r.holdS, 2.0, 10.0, error);
    r.moveS = number(j, "move_s", r.moveS, 0.5, 10.0, error);
    r.durationS = number(j, "duration_s", 0, 3.0, 300.0, error);
    if (!error.empty()) {
        return Error{EINVAL, error};
    }
    return r;
}

SensorCalibrationSession::SensorCalibrationSession(const board::Board& board, Clock& clock,
                                                   SampleTap& tap,
                                                   std::shared_ptr<CalibrationMotion> motion,
                                                   fs::path file, std::string inForce)
    : board_(board),
      clock_(clock),
      tap_(tap),
      motion_(std::move(motion)),
      file_(std::move(file)),
      inForce_(std::move(inForce)) {}

SensorCalibrationSession::~SensorCalibrationSession() {
    cancel();
    if (worker_.joinable()) {
        worker_.join();
    }
}

Result<void> SensorCalibrationSession::start(SensorCalibrationRequest request) {
    std::lock_guard lock(mutex_);
    if (running_) {
        return Error{EBUSY, fmt::format("a {} calibration is running: wait for it or cancel it",
                                        procedure_.value("kind", std::string("sensor")))};
    }
    if (worker_.joinable()) {
        worker_.join();  // the last one has ended
    }
    if (motion_) {
        request.leadS = 0.5;  // the virtual subject is ready at once
    }
    running_ = true;
    cancel_ = false;
    procedure_ = {{"kind", kindName(request.kind)},
                  {"stage", "starting"},
                  {"progress", 0.0},
                  {"instruction", ""},
                  {"step", ""}};
    worker_ = std::thread([this, request] { run(request); });
    return {};
}

void SensorCalibrationSession::cancel() {
    std::lock_guard lock(mutex_);
    cancel_ = true;
}

Json SensorCalibrationSession::status() const {
    std::lock_guard lock(mutex_);
    return Json{{"in_force", inForce_.empty() ? Json(nullptr) : Json(inForce_)},
                {"file", file_.string()},
                {"saved", saved_.empty() ? Json(nullptr) : Json(saved_)},
                {"applies", saved_.empty() ? "" : "at the next start of caphub serve"},
                {"virtual_suit", motion_ != nullptr},
                {"running", running_},
                {"procedure", procedure_}};
}

void SensorCalibrationSession::setStage(const std::string& stage, double progress,
                                        const std::string& instruction, const std::string& step) {
    std::lock_guard lock(mutex_);
    procedure_["stage"] = stage;
    procedure_["progress"] = std::clamp(progress, 0.0, 1.0);
    procedure_["instruction"] = instruction;
    procedure_["step"] = step;
}

void SensorCalibrationSession::run(SensorCalibrationRequest r) {
    const bool positions = r.kind == SensorCalibrationKind::Accel;
    const bs::Script script =
        r.kind == SensorCalibrationKind::Gyro ? bs::Script::Rest
        : positions ? (r.positions == 14 ? bs::Script::FourteenPositions : bs::Script::SixPositions)
                    : bs::Script::Tumble;
    bs::ScriptTiming timing;
    timing.holdS = r.holdS;
    timing.moveS = r.moveS;
    double durationS = r.durationS;
    if (positions) {
        durationS = static_cast<double>(bs::ScriptedMotion(script, timing).durationNs()) * 1e-9;
    } else if (durationS <= 0) {
        durationS = r.kind == SensorCalibrationKind::Gyro ? 5.0 : 30.0;
    }
    timing.tumbleS = durationS;
    const Timestamp start = clock_.now() + durationFromSeconds(r.leadS);
    const Timestamp end = start + durationFromSeconds(durationS);
    if (motion_) {
        motion_->play(script, timing, start);
    }
    {
        std::lock_guard lock(mutex_);
        procedure_["duration_s"] = durationS;
        if (positions) {
            procedure_["positions"] = r.positions;
            procedure_["hold_s"] = r.holdS;
            procedure_["move_s"] = r.moveS;
        }
    }
    const std::string todo =
        r.kind == SensorCalibrationKind::Gyro
            ? "Lay every sensor still on a table (off the body) and do not touch them."
        : positions
            ? fmt::format(
                  "Hold each sensor still with the face shown pointing up for {:g} s, then "
                  "turn it smoothly to the next within {:g} s.",
                  r.holdS, r.moveS)
            : "Turn each sensor slowly through every direction, away from metal and magnets.";

    CalibrationSamples samples(board_);
    tap_.open();
    bool cancelled = false;
    for (;;) {
        SensorSample s;
        while (tap_.pop(s)) {
            if (s.sample.t >= start && s.sample.t <= end) {
                samples.add(s);
            }
        }
        const Timestamp now = clock_.now();
        {
            std::lock_guard lock(mutex_);
            cancelled = cancel_;
        }
        if (cancelled || now > end + std::chrono::milliseconds(300)) {
            break;
        }
        const double elapsed = toSeconds(now - start);
        std::string step;
        std::string instruction = todo;
        if (elapsed < 0) {
            step = fmt::format("get ready: {:.0f} s", std::ceil(-elapsed));
        } else if (positions) {
            const double period = r.holdS + r.moveS;
            const int k = std::min(r.positions - 1, static_cast<int>(elapsed / period));
            const bool holding = elapsed - k * period < r.holdS || k == r.positions - 1;
            step = holding ? fmt::format("position {} of {}: {} up, hold still", k + 1, r.positions,
                                         upText(r.positions, k))
                           : fmt::format("turn to position {}: {} up", k + 2,
                                         upText(r.positions, k + 1));
        } else {
            step = fmt::format("{:.0f} s left", std::max(0.0, durationS - elapsed));
        }
        setStage(elapsed < 0 ? "waiting" : "measuring", elapsed / durationS, instruction, step);
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    tap_.close();
    if (motion_) {
        motion_->stop();
    }
    const std::uint64_t dropped = tap_.dropped();
    if (cancelled) {
        setStage("cancelled", 0, "Cancelled: nothing was saved.", "");
        std::lock_guard lock(mutex_);
        running_ = false;
        return;
    }
    setStage("computing", 1, "Computing the calibration.", "");

    // Merged into the kept file: the other kinds and sensors stay.
    CalibrationSet set;
    std::string error;
    std::error_code ec;
    if (fs::exists(file_, ec)) {
        auto existing = readCalibrationFile(file_);
        if (existing) {
            set = std::move(*existing);
        } else {
            error = existing.error().message;
        }
    }
    Computed computed;
    if (error.empty()) {
        computed = computeAll(r.kind, board_, samples, set);
    }
    const int done = computed.done;
    std::string saved;
    if (error.empty() && done > 0) {
        fs::create_directories(file_.parent_path(), ec);  // the state folder's first use
        if (auto w = writeCalibrationFile(file_, set); !w) {
            error = w.error().message;
        } else {
            saved = file_.string();
        }
    } else if (error.empty()) {
        error = "no sensor was calibrated; nothing was saved";
    }
    const std::size_t n = board_.sensors.size();
    {
        std::lock_guard lock(mutex_);
        procedure_["stage"] = error.empty() ? "done" : "failed";
        procedure_["progress"] = 1.0;
        procedure_["step"] = "";
        procedure_["instruction"] =
            error.empty() ? fmt::format(
                                "{} of {} sensors calibrated; saved in {}; applied at the "
                                "next start of caphub serve.",
                                done, n, saved)
                          : error;
        procedure_["result"] = {{"calibrated", done},
                                {"sensors_total", n},
                                {"quality", computed.quality},
                                {"samples_dropped", dropped},
                                {"sensors", computed.sensors},
                                {"file", saved.empty() ? Json(nullptr) : Json(saved)},
                                {"error", error}};
        if (!saved.empty()) {
            saved_ = saved;
        }
        running_ = false;
    }
    log::logger(log::Category::Firmware)
        .info("sensor calibration {}: {} of {} sensors{}", kindName(r.kind), done, n,
              saved.empty() ? fmt::format(" ({})", error) : " saved in " + saved);
}

}  // namespace caphub::firmware::serve
