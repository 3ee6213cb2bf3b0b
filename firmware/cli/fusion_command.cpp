// caphub fusion replay: runs the orientation filter over recorded IMU data in the BROAD layout,
// writes the estimate, and scores it against the ground truth when the file has one.
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include "firmware/cli/app.h"
#include "firmware/cli/commands.h"
#include "firmware/io/broad_csv.h"
#include "fusion/evaluation.h"
#include "fusion/smoother.h"

namespace caphub::firmware {

namespace {

struct ReplayOptions {
    std::vector<std::string> inputs;
    std::string output;
    double rateHz = 0.0;
    bool fixed = false;
    bool summary = false;
    bool smooth = false;
};

// The non-causal estimate (fusion/smoother.h) over the samples fed at every `decimation`-th
// row, held between, one per row like runFilter's.
std::vector<Quatd> smoothedEstimate(const std::vector<fusion::ImuSample>& samples, int decimation,
                                    const fusion::FilterParams& params) {
    std::vector<fusion::SmootherSample> fed;
    for (std::size_t i = 0; i < samples.size(); i += static_cast<std::size_t>(decimation)) {
        fusion::SmootherSample s;
        // The filter takes float: the same rounding as the causal run.
        s.gyrRadS = samples[i].gyrRadS.cast<float>().cast<double>();
        s.accMps2 = samples[i].accMps2.cast<float>().cast<double>();
        s.magUt = samples[i].magUt.cast<float>().cast<double>();
        s.magFresh = true;
        fed.push_back(s);
    }
    const auto q = fusion::smoothOrientations(fed, params);
    std::vector<Quatd> out(samples.size());
    for (std::size_t i = 0; i < samples.size(); ++i) {
        out[i] = q[i / static_cast<std::size_t>(decimation)];
    }
    return out;
}

Result<void> writeEstimate(const std::string& path, const BroadTrial& trial,
                           const std::vector<Quatd>& q) {
    std::unique_ptr<std::FILE, int (*)(std::FILE*)> f(std::fopen(path.c_str(), "w"), &std::fclose);
    if (!f) {
        return errnoError(-errno, fmt::format("create '{}'", path));
    }
    fmt::print(f.get(), "t,qw,qx,qy,qz\n");
    for (std::size_t i = 0; i < q.size(); ++i) {
        fmt::print(f.get(), "{:.6f},{:.9f},{:.9f},{:.9f},{:.9f}\n", trial.samples[i].tS, q[i].w(),
                   q[i].x(), q[i].y(), q[i].z());
    }
    if (std::fflush(f.get()) != 0 || std::ferror(f.get())) {
        return errnoError(-errno, fmt::format("write '{}'", path));
    }
    return {};
}

// "rejected 1 gyroscope sample and 2 magnetometer samples (...)", or empty when none was.
std::string describeRejections(const fusion::FilterRejections& r) {
    std::vector<std::string> parts;
    const auto add = [&parts](std::uint32_t n, const char* what) {
        if (n > 0) {
            parts.push_back(fmt::format("{} {} sample{}", n, what, n == 1 ? "" : "s"));
        }
    };
    add(r.gyr, "gyroscope");
    add(r.acc, "accelerometer");
    add(r.mag, "magnetometer");
    if (parts.empty() && r.stateResets == 0) {
        return {};
    }
    std::string text = "rejected ";
    for (std::size_t i = 0; i < parts.size(); ++i) {
        text += (i == 0 ? "" : (i + 1 == parts.size() ? " and " : ", ")) + parts[i];
    }
    if (parts.empty()) {
        text += "no sample";
    }
    text += " (not finite or beyond the sensors' range: docs/fusion.md, \"Input validation\")";
    if (r.stateResets > 0) {
        text += fmt::format("; the filter restarted {} time{} from a non-finite state",
                            r.stateResets, r.stateResets == 1 ? "" : "s");
    }
    return text;
}

int runReplay(const ReplayOptions& o) {
    if (!o.output.empty() && o.inputs.size() != 1) {
        fmt::print(stderr, "caphub fusion replay: --out takes exactly one --in file\n");
        return kExitUsage;
    }
    if (o.inputs.size() > 1 && !o.summary) {
        fmt::print(stderr, "caphub fusion replay: several --in files need --summary\n");
        return kExitUsage;
    }
    const auto variant = o.fixed ? fusion::FilterVariant::Fixed : fusion::FilterVariant::Float;
    struct Row {
        std::string name;
        fusion::BroadErrors e;
        fusion::BroadErrors smoothed;
    };
    std::vector<Row> rows;
    for (const auto& in : o.inputs) {
        auto trial = readBroadCsv(in);
        if (!trial) {
            fmt::print(stderr, "caphub fusion replay: {}\n", trial.error().message);
            return kExitUsage;
        }
        int decimation = 1;
        if (o.rateHz > 0.0) {
            if (o.rateHz > trial->rateHz * 1.0001) {
                fmt::print(stderr,
                           "caphub fusion replay: --rate-hz {:g} is above the file's rate {:g} "
                           "Hz ({})\n",
                           o.rateHz, trial->rateHz, in);
                return kExitUsage;
            }
            decimation = std::max(1, static_cast<int>(std::lround(trial->rateHz / o.rateHz)));
        }
        const double fedHz = trial->rateHz / decimation;
        fusion::FilterParams params;
        params.gyrRateHz = params.accRateHz = params.magRateHz = fedHz;
        if (const char* bad = fusion::invalidFilterParameter(params)) {
            fmt::print(stderr,
                       "caphub fusion replay: {}: the filter cannot run at {:g} Hz ({} must lie "
                       "within 0.6 Hz and 20 kHz)\n",
                       in, fedHz, bad);
            return kExitUsage;
        }
        fusion::FilterRejections rejected;
        const auto estimate = fusion::runFilter(trial->samples, trial->rateHz, decimation, variant,
                                                params, &rejected);
        if (const std::string r = describeRejections(rejected); !r.empty()) {
            fmt::print(stderr, "caphub fusion replay: {}: {}\n", in, r);
        }
        std::vector<Quatd> smoothed;
        if (o.smooth) {
            smoothed = smoothedEstimate(trial->samples, decimation, params);
        }
        if (!o.output.empty()) {
            if (auto r = writeEstimate(o.output, *trial, o.smooth ? smoothed : estimate); !r) {
                fmt::print(stderr, "caphub fusion replay: {}\n", r.error().message);
                return exitCodeForCreate(r.error().code);
            }
        }
        if (trial->hasTruth()) {
            rows.push_back({trial->name,
                            fusion::broadMetric(estimate, trial->truth, trial->movement),
                            o.smooth ? fusion::broadMetric(smoothed, trial->truth, trial->movement)
                                     : fusion::BroadErrors{}});
        } else if (o.summary) {
            fmt::print(stderr, "caphub fusion replay: {} has no ground truth: not scored\n", in);
        }
        if (rows.size() == 1 && o.inputs.size() == 1) {
            fmt::print("filter {} at {:.2f} Hz (every {} of {:.3f} Hz)\n",
                       o.fixed ? "fixed" : "float", trial->rateHz / decimation, decimation,
                       trial->rateHz);
        }
    }
    if (rows.empty()) {
        return kExitOk;
    }
    if (o.smooth) {
        fmt::print("{:<48} {:>9} {:>9} {:>8} {:>9} {:>9}\n", "trial (RMSE over movement, deg)",
                   "causal", "smoothed", "change", "heading", "incl");
        double c = 0.0;
        double s = 0.0;
        for (const auto& r : rows) {
            fmt::print("{:<48} {:>9.3f} {:>9.3f} {:>7.1f}% {:>9.3f} {:>9.3f}\n", r.name,
                       r.e.totalDeg, r.smoothed.totalDeg,
                       (r.smoothed.totalDeg / r.e.totalDeg - 1) * 100, r.smoothed.headingDeg,
                       r.smoothed.inclinationDeg);
            c += r.e.totalDeg;
            s += r.smoothed.totalDeg;
        }
        const double n = static_cast<double>(rows.size());
        fmt::print("{:<48} {:>9.3f} {:>9.3f} {:>7.1f}%\n", fmt::format("mean of {}", rows.size()),
                   c / n, s / n, (s / c - 1) * 100);
        return kExitOk;
    }
    fmt::print("{:<48} {:>9} {:>9} {:>9}\n", "trial (RMSE over movement, deg)", "total", "heading",
               "incl");
    double t = 0.0;
    double h = 0.0;
    double i = 0.0;
    for (const auto& r : rows) {
        fmt::print("{:<48} {:>9.3f} {:>9.3f} {:>9.3f}\n", r.name, r.e.totalDeg, r.e.headingDeg,
                   r.e.inclinationDeg);
        t += r.e.totalDeg;
        h += r.e.headingDeg;
        i += r.e.inclinationDeg;
    }
    if (rows.size() > 1) {
        const double n = static_cast<double>(rows.size());
        fmt::print("{:<48} {:>9.3f} {:>9.3f} {:>9.3f}\n", fmt::format("mean of {}", rows.size()),
                   t / n, h / n, i / n);
    }
    return kExitOk;
}

}  // namespace

void addFusionCommand(CLI::App& app, int& exitCode) {
    CLI::App* fusion = app.add_subcommand(
        "fusion", "Run the orientation filter on recorded IMU data and score it");
    fusion->require_subcommand(1);
    auto opts = std::make_shared<ReplayOptions>();
    CLI::App* replay = fusion->add_subcommand(
        "replay",
        "Run the filter over BROAD-layout files (t, gyr, acc, mag[, opt quaternion, movement]); "
        "print the BROAD RMSE when the file has ground truth");
    // Checked when read (hal/core/input_file.h), with the same words as every other input.
    replay->add_option("--in", opts->inputs, "Input file(s), .csv or .csv.gz")->required();
    replay->add_option("--out", opts->output,
                       "Write the estimate here: t,qw,qx,qy,qz (sensor -> earth, ENU), one row per "
                       "input row");
    replay
        ->add_option("--rate-hz", opts->rateHz,
                     "Feed every k-th sample to run at about this rate (holds the estimate "
                     "between)")
        ->check(CLI::PositiveNumber);
    replay->add_flag("--fixed", opts->fixed, "Run the fixed-point (Q-format) filter");
    replay->add_flag("--summary", opts->summary, "Several --in files: a row each and the mean");
    replay->add_flag("--smooth", opts->smooth,
                     "Also the non-causal estimate (forward and backward runs combined, "
                     "fusion/smoother.h): scored beside the causal filter; --out writes it");
    replay->callback([opts, &exitCode] { exitCode = runReplay(*opts); });
}

}  // namespace caphub::firmware
