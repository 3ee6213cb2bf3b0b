// caphub fusion replay: runs the orientation filter over recorded IMU data in the BROAD layout,
// writes the estimate, and scores it against the ground truth when the file has one.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include "firmware/cli/app.h"
#include "firmware/cli/commands.h"
#include "firmware/cli/number_checks.h"
#include "firmware/cli/smooth_heading_option.h"
#include "firmware/export/output_file.h"
#include "firmware/io/broad_csv.h"
#include "fusion/evaluation.h"
#include "fusion/smoother.h"
#include "fusion/tuning.h"

namespace caphub::firmware {

namespace {

namespace fs = std::filesystem;

struct FusionReplayOptions {
    std::vector<std::string> inputs;
    std::string output;
    double rateHz = 0.0;
    bool fixed = false;
    bool summary = false;
    bool smooth = false;
    std::string smoothHeading = "causal";
};

// The non-causal estimate (fusion/smoother.h) over the samples fed at every `decimation`-th
// row, held between, one per row like runFilter's.
std::vector<Quatd> smoothedEstimate(const std::vector<fusion::ImuSample>& samples, int decimation,
                                    const fusion::FilterParams& params,
                                    const fusion::SmootherOptions& options) {
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
    const auto q = fusion::smoothOrientations(fed, params, options);
    std::vector<Quatd> out(samples.size());
    for (std::size_t i = 0; i < samples.size(); ++i) {
        out[i] = q[i / static_cast<std::size_t>(decimation)];
    }
    return out;
}

// Why the filter cannot be fed `rateHz` (0: the file's rate) from this file, or empty: a rate
// above the file's, or one so low that fewer than two of its samples would be fed (1e-9 Hz
// overflowed the decimation and ran at the file's full rate instead).
std::string rateProblem(double rateHz, const BroadTrial& t) {
    if (rateHz <= 0.0) {
        return {};
    }
    if (rateHz > t.rateHz * 1.0001) {
        return fmt::format("is above the file's rate {:g} Hz", t.rateHz);
    }
    if (std::lround(t.rateHz / rateHz) >= static_cast<long>(t.samples.size())) {
        return fmt::format("feeds the filter fewer than two of the file's {} samples at {:g} Hz",
                           t.samples.size(), t.rateHz);
    }
    return {};
}

// The decimation of a rate rateProblem accepts.
int decimationFor(const BroadTrial& t, double rateHz) {
    return rateHz > 0.0 ? std::max(1, static_cast<int>(std::lround(t.rateHz / rateHz))) : 1;
}

// The estimate as CSV, written as an export is (docs/exports.md): a regular file only, never
// the input itself, via PATH.part renamed over it when complete (Ctrl-C leaves the old file).
Result<void> writeEstimate(const std::string& path, const std::string& input,
                           const BroadTrial& trial, const std::vector<Quatd>& q) {
    auto target = exporter::claimOutputTarget(path, "--out", {input});
    if (!target) {
        return target.error();
    }
    std::string text = "t,qw,qx,qy,qz\n";
    for (std::size_t i = 0; i < q.size(); ++i) {
        text += fmt::format("{:.6f},{:.9f},{:.9f},{:.9f},{:.9f}\n", trial.samples[i].tS, q[i].w(),
                            q[i].x(), q[i].y(), q[i].z());
    }
    return exporter::writeWholeFile(*target, text);
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

int runReplay(const FusionReplayOptions& o) {
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
        if (const std::string bad = rateProblem(o.rateHz, *trial); !bad.empty()) {
            fmt::print(stderr, "caphub fusion replay: --rate-hz {:g} {} ({})\n", o.rateHz, bad, in);
            return kExitUsage;
        }
        const int decimation = decimationFor(*trial, o.rateHz);
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
            fusion::SmootherOptions so;
            fusion::setSmoothHeading(so, o.smoothHeading);
            smoothed = smoothedEstimate(trial->samples, decimation, params, so);
        }
        if (!o.output.empty()) {
            if (auto r = writeEstimate(o.output, in, *trial, o.smooth ? smoothed : estimate); !r) {
                fmt::print(stderr, "caphub fusion replay: {}\n", r.error().message);
                return exitCodeForCreate(r.error().code);
            }
        }
        const fusion::BroadErrors errors =
            fusion::broadMetric(estimate, trial->truth, trial->movement);
        if (trial->hasTruth() && errors.samples == 0) {
            // Scored over no row, the errors would read 0.000: a perfect filter.
            fmt::print(stderr,
                       "caphub fusion replay: {} has no row in movement with the optical truth "
                       "seen: not scored\n",
                       in);
        } else if (trial->hasTruth()) {
            rows.push_back({trial->name, errors,
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

struct CvOptions {
    std::vector<std::string> inputs;
    std::vector<double> ratesHz{0.0, 57.0};  // 0: the file's own rate
    bool noFixed = false;
};

// One trial held in memory for the search.
struct CvTrial {
    BroadTrial trial;
    std::string path;
};

fusion::BroadErrors scoreRun(const CvTrial& t, double rateHz, fusion::FilterVariant v,
                             const fusion::FilterParams& p) {
    const auto est =
        fusion::runFilter(t.trial.samples, t.trial.rateHz, decimationFor(t.trial, rateHz), v, p);
    return fusion::broadMetric(est, t.trial.truth, t.trial.movement);
}

std::string rateName(double rateHz) {
    return rateHz > 0.0 ? fmt::format("{:g} Hz", rateHz) : std::string("the file's rate");
}

// caphub fusion cv: leave-one-out over the trials for the parameters of tuningSearchSpace():
// every candidate is scored on every trial (float) at every rate; the objective of a candidate
// on a trial is its total RMSE averaged over the rates (one parameter set for all rates); each
// trial is then scored with the candidate that is best on the other trials.
int runCv(const CvOptions& o) {
    if (o.inputs.size() < 3) {
        fmt::print(stderr, "caphub fusion cv: leave-one-out needs at least 3 --in files\n");
        return kExitUsage;
    }
    const auto start = std::chrono::steady_clock::now();
    std::vector<CvTrial> trials;
    for (const auto& in : o.inputs) {
        auto trial = readBroadCsv(in);
        if (!trial) {
            fmt::print(stderr, "caphub fusion cv: {}\n", trial.error().message);
            return kExitUsage;
        }
        if (!trial->hasTruth()) {
            fmt::print(stderr, "caphub fusion cv: {} has no ground truth: nothing to score\n", in);
            return kExitUsage;
        }
        // The rows a score counts: the truth scored against itself counts them.
        if (fusion::broadMetric(trial->truth, trial->truth, trial->movement).samples == 0) {
            fmt::print(stderr,
                       "caphub fusion cv: {} has no row in movement with the optical truth "
                       "seen: nothing to score\n",
                       in);
            return kExitUsage;
        }
        for (double r : o.ratesHz) {
            if (const std::string bad = rateProblem(r, *trial); !bad.empty()) {
                fmt::print(stderr, "caphub fusion cv: --rate-hz {:g} {} ({})\n", r, bad, in);
                return kExitUsage;
            }
        }
        trials.push_back({std::move(*trial), in});
    }
    const auto space = fusion::tuningSearchSpace();
    const std::size_t nT = trials.size();
    const std::size_t nR = o.ratesHz.size();
    // errors[c][r][t] (float)
    std::vector<std::vector<std::vector<fusion::BroadErrors>>> errors(
        space.size(),
        std::vector<std::vector<fusion::BroadErrors>>(nR, std::vector<fusion::BroadErrors>(nT)));
    std::vector<std::vector<double>> objective(space.size(), std::vector<double>(nT, 0.0));
    for (std::size_t c = 0; c < space.size(); ++c) {
        for (std::size_t r = 0; r < nR; ++r) {
            for (std::size_t t = 0; t < nT; ++t) {
                errors[c][r][t] = scoreRun(trials[t], o.ratesHz[r], fusion::FilterVariant::Float,
                                           space[c].params);
                objective[c][t] += errors[c][r][t].totalDeg / static_cast<double>(nR);
            }
        }
    }
    const std::vector<std::size_t> loo = fusion::leaveOneOutChoice(objective);
    const std::size_t inSample = fusion::inSampleChoice(objective);

    fmt::print(
        "leave-one-out over {} trials: {} parameter sets (tauAccS x accLpDamping x "
        "headingNoiseDegRtHz, docs/fusion.md); objective: total RMSE, mean over the rates ({})\n",
        nT, space.size(), [&] {
            std::string s;
            for (double r : o.ratesHz) {
                s += (s.empty() ? "" : ", ") + rateName(r);
            }
            return s;
        }());
    fmt::print("defaults (set 0): {}\n", space[0].label);
    fmt::print("in-sample best on all {} (set {}): {}\n", nT, inSample, space[inSample].label);
    fmt::print("{:<48} {}\n", "held-out trial", "set chosen on the other trials");
    for (std::size_t t = 0; t < nT; ++t) {
        fmt::print("{:<48} {:>2}: {}\n", trials[t].trial.name, loo[t], space[loo[t]].label);
    }

    std::vector<fusion::FilterVariant> variants{fusion::FilterVariant::Float};
    if (!o.noFixed) {
        variants.push_back(fusion::FilterVariant::Fixed);
    }
    for (std::size_t r = 0; r < nR; ++r) {
        for (const auto v : variants) {
            const bool fixed = v == fusion::FilterVariant::Fixed;
            // The float figures are the ones the search computed; the fixed ones are run with the
            // float search's choices.
            const auto run = [&](std::size_t c, std::size_t t) {
                return fixed ? scoreRun(trials[t], o.ratesHz[r], v, space[c].params)
                             : errors[c][r][t];
            };
            fmt::print("\n{} at {} (RMSE over movement, deg)\n", fixed ? "fixed" : "float",
                       rateName(o.ratesHz[r]));
            fmt::print("{:<40} {:>26} {:>26} {:>26}\n", "", "defaults (in-sample)",
                       "best on all (in-sample)", "leave-one-out (held-out)");
            fmt::print("{:<40} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8}\n", "trial",
                       "total", "heading", "incl", "total", "heading", "incl", "total", "heading",
                       "incl");
            double sum[9] = {};
            for (std::size_t t = 0; t < nT; ++t) {
                const fusion::BroadErrors e[3] = {run(0, t), run(inSample, t), run(loo[t], t)};
                std::string line = fmt::format("{:<40}", trials[t].trial.name.substr(0, 40));
                for (int k = 0; k < 3; ++k) {
                    line += fmt::format(" {:>8.3f} {:>8.3f} {:>8.3f}", e[k].totalDeg,
                                        e[k].headingDeg, e[k].inclinationDeg);
                    sum[3 * k] += e[k].totalDeg;
                    sum[3 * k + 1] += e[k].headingDeg;
                    sum[3 * k + 2] += e[k].inclinationDeg;
                }
                fmt::print("{}\n", line);
            }
            std::string line = fmt::format("{:<40}", fmt::format("mean of {}", nT));
            for (double x : sum) {
                line += fmt::format(" {:>8.3f}", x / static_cast<double>(nT));
            }
            fmt::print("{}\n", line);
        }
    }
    fmt::print("\n{:.1f} s\n",
               std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
    return kExitOk;
}

}  // namespace

void addFusionCommand(CLI::App& app, int& exitCode) {
    CLI::App* fusion = app.add_subcommand(
        "fusion", "Run the orientation filter on recorded IMU data and score it");
    fusion->require_subcommand(1);
    auto opts = std::make_shared<FusionReplayOptions>();
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
        ->check(finitePositive());
    replay->add_flag("--fixed", opts->fixed, "Run the fixed-point (Q-format) filter");
    replay->add_flag("--summary", opts->summary, "Several --in files: a row each and the mean");
    replay->add_flag("--smooth", opts->smooth,
                     "Also the non-causal estimate (forward and backward runs combined, "
                     "fusion/smoother.h): scored beside the causal filter; --out writes it");
    addSmoothHeadingOption(*replay, opts->smoothHeading, "--smooth");
    replay->callback([opts, &exitCode] { exitCode = runReplay(*opts); });

    auto cv = std::make_shared<CvOptions>();
    CLI::App* cvCmd = fusion->add_subcommand(
        "cv",
        "Leave-one-out over BROAD trials with ground truth for the filter's tunable parameters: "
        "the per-trial and mean held-out errors next to the in-sample ones");
    cvCmd->add_option("--in", cv->inputs, "Trial files (.csv or .csv.gz), at least 3")->required();
    cvCmd
        ->add_option("--rate-hz", cv->ratesHz,
                     "Rates to score at (0: the file's rate); repeatable; the objective is the "
                     "mean over them")
        ->capture_default_str()
        ->check(finiteNonNegative());
    cvCmd->add_flag("--no-fixed", cv->noFixed, "Leave out the fixed-point tables");
    cvCmd->callback([cv, &exitCode] { exitCode = runCv(*cv); });
}

}  // namespace caphub::firmware
