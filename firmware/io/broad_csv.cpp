#include "firmware/io/broad_csv.h"

#include <algorithm>
#include <array>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string_view>

#include <fmt/format.h>
#include <unistd.h>
#include <zlib.h>

#include "hal/core/input_file.h"
#include "hal/core/output_fd.h"

namespace caphub::firmware {

namespace {

constexpr std::array<std::string_view, 15> kColumns = {
    "t",     "gyr_x", "gyr_y", "gyr_z", "acc_x", "acc_y", "acc_z",   "mag_x",
    "mag_y", "mag_z", "opt_w", "opt_x", "opt_y", "opt_z", "movement"};
constexpr std::size_t kImuColumns = 10;

struct GzCloser {
    void operator()(gzFile f) const { gzclose(f); }
};
using GzFile = std::unique_ptr<std::remove_pointer_t<gzFile>, GzCloser>;

// Reads one line (without the newline) of any length; false at end of file.
bool readLine(gzFile f, std::string& line) {
    line.clear();
    char buf[4096];
    while (gzgets(f, buf, sizeof buf) != nullptr) {
        line += buf;
        if (!line.empty() && line.back() == '\n') {
            line.pop_back();
            if (!line.empty() && line.back() == '\r') {
                line.pop_back();
            }
            return true;
        }
    }
    return !line.empty();
}

std::vector<std::string_view> splitCommas(std::string_view s) {
    std::vector<std::string_view> out;
    std::size_t start = 0;
    while (true) {
        const std::size_t p = s.find(',', start);
        out.push_back(
            s.substr(start, p == std::string_view::npos ? std::string_view::npos : p - start));
        if (p == std::string_view::npos) {
            break;
        }
        start = p + 1;
    }
    return out;
}

std::string_view trim(std::string_view s) {
    while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) {
        s.remove_prefix(1);
    }
    while (!s.empty() && (s.back() == ' ' || s.back() == '\t')) {
        s.remove_suffix(1);
    }
    return s;
}

// A number, "nan" accepted only when allowNan.
constexpr double kMaxBroadTimeS = 1e6;
constexpr double kMaxBroadValue = 1e6;

bool parseNumber(std::string_view s, bool allowNan, double& out) {
    s = trim(s);
    if (s.empty()) {
        return false;
    }
    if (s == "nan" || s == "NaN" || s == "NAN") {
        if (!allowNan) {
            return false;
        }
        out = std::nan("");
        return true;
    }
    const char* end = s.data() + s.size();
    const auto r = std::from_chars(s.data(), end, out);
    return r.ec == std::errc{} && r.ptr == end && std::isfinite(out);
}

// "file:line:column: what" (column 1-based, in characters of the line).
Error lineError(const std::filesystem::path& path, std::size_t line, const std::string& what,
                std::size_t column = 1) {
    return Error{EINVAL, fmt::format("{}:{}:{}: {}", path.string(), line, column, what)};
}

// The column (1-based) where a field, a view into `line`, starts.
std::size_t columnOf(const std::string& line, std::string_view field) {
    return static_cast<std::size_t>(field.data() - line.data()) + 1;
}

// The column just past the last character of `line` (where a missing field would start).
std::size_t endColumn(const std::string& line) {
    return line.size() + 1;
}

// "sampling_rate_hz=285.714286" inside the comment line.
double rateFromComment(std::string_view comment) {
    const std::string_view key = "sampling_rate_hz=";
    const std::size_t p = comment.find(key);
    if (p == std::string_view::npos) {
        return 0.0;
    }
    std::string_view rest = comment.substr(p + key.size());
    const std::size_t e = rest.find_first_of(";, ");
    rest = rest.substr(0, e);
    double v = 0.0;
    return parseNumber(rest, false, v) && v > 0.0 ? v : 0.0;
}

std::string nameFromComment(std::string_view comment) {
    const std::string_view key = "BROAD trial ";
    const std::size_t p = comment.find(key);
    if (p == std::string_view::npos) {
        return {};
    }
    std::string_view rest = comment.substr(p + key.size());
    return std::string(trim(rest.substr(0, rest.find(';'))));
}

}  // namespace

Result<BroadTrial> readBroadCsv(const std::filesystem::path& path) {
    // Opened as every input file is (a directory, a device or a FIFO without a writer is said
    // so, not waited on), then read through zlib, which reads a plain file as it is.
    auto opened = openInputFile(path);
    if (!opened) {
        return opened.error();
    }
    const int fd = ::dup(::fileno(*opened));
    std::fclose(*opened);
    errno = 0;
    GzFile f(fd >= 0 ? gzdopen(fd, "rb") : nullptr);
    if (!f) {
        if (fd >= 0) {
            ::close(fd);
        }
        return errnoError(errno != 0 ? -errno : -ENOMEM, fmt::format("open '{}'", path.string()));
    }
    BroadTrial trial;
    trial.name = path.filename().string();
    for (const char* ext : {".gz", ".csv"}) {
        if (trial.name.size() > std::string_view(ext).size() && trial.name.ends_with(ext)) {
            trial.name.resize(trial.name.size() - std::string_view(ext).size());
        }
    }

    std::string line;
    std::size_t lineNo = 0;
    // Comment lines, then the header.
    bool haveHeader = false;
    std::size_t columns = 0;
    while (readLine(f.get(), line)) {
        ++lineNo;
        const std::string_view l = trim(line);
        if (l.empty()) {
            continue;
        }
        if (l.front() == '#') {
            if (const double r = rateFromComment(l); r > 0.0) {
                trial.rateHz = r;
            }
            if (auto n = nameFromComment(l); !n.empty()) {
                trial.name = n;
            }
            continue;
        }
        const auto fields = splitCommas(l);
        if (fields.size() != kImuColumns && fields.size() != kColumns.size()) {
            return lineError(path, lineNo,
                             fmt::format("expected a header of {} or {} columns ({}), got {}",
                                         kImuColumns, kColumns.size(),
                                         "t,gyr_x,gyr_y,gyr_z,acc_x,acc_y,acc_z,mag_x,mag_y,mag_z"
                                         "[,opt_w,opt_x,opt_y,opt_z,movement]",
                                         fields.size()));
        }
        for (std::size_t i = 0; i < fields.size(); ++i) {
            if (trim(fields[i]) != kColumns[i]) {
                return lineError(path, lineNo,
                                 fmt::format("header column {}: expected '{}', got '{}'", i + 1,
                                             kColumns[i], trim(fields[i])),
                                 columnOf(line, fields[i]));
            }
        }
        columns = fields.size();
        haveHeader = true;
        break;
    }
    if (!haveHeader) {
        return lineError(path, lineNo + 1, "expected the header line, found the end of the file");
    }
    const bool withTruth = columns == kColumns.size();

    double v[15];
    while (readLine(f.get(), line)) {
        ++lineNo;
        const std::string_view l = trim(line);
        if (l.empty() || l.front() == '#') {
            continue;
        }
        const auto fields = splitCommas(l);
        if (fields.size() != columns) {
            return lineError(
                path, lineNo, fmt::format("expected {} fields, got {}", columns, fields.size()),
                fields.size() > columns ? columnOf(line, fields[columns]) : endColumn(line));
        }
        for (std::size_t i = 0; i < columns; ++i) {
            const bool nanOk = i >= kImuColumns && i < kImuColumns + 4;  // opt_* may be nan
            if (!parseNumber(fields[i], nanOk, v[i])) {
                return lineError(path, lineNo,
                                 fmt::format("field '{}': expected a {}number, got '{}'",
                                             kColumns[i], nanOk ? "" : "finite ", trim(fields[i])),
                                 columnOf(line, fields[i]));
            }
            // What a sample can hold: a reading far beyond any sensor's range would be infinite
            // as the float a recording stores, and a time beyond 1e6 s (11 days) overflows the
            // capture clock's nanoseconds once a rate multiplies it.
            const double limit = i == 0 ? kMaxBroadTimeS : kMaxBroadValue;
            if (std::abs(v[i]) > limit) {
                return lineError(path, lineNo,
                                 fmt::format("field '{}': {} is out of range (at most {:g} either "
                                             "way)",
                                             kColumns[i], trim(fields[i]), limit),
                                 columnOf(line, fields[i]));
            }
        }
        fusion::ImuSample s;
        s.tS = v[0];
        s.gyrRadS = Vec3d(v[1], v[2], v[3]);
        s.accMps2 = Vec3d(v[4], v[5], v[6]);
        s.magUt = Vec3d(v[7], v[8], v[9]);
        if (!trial.samples.empty() && !(s.tS > trial.samples.back().tS)) {
            return lineError(path, lineNo,
                             fmt::format("expected t to increase, got {} after {}", s.tS,
                                         trial.samples.back().tS),
                             columnOf(line, fields[0]));
        }
        trial.samples.push_back(s);
        if (withTruth) {
            if (v[14] != 0.0 && v[14] != 1.0) {
                return lineError(
                    path, lineNo,
                    fmt::format("field 'movement': expected 0 or 1, got '{}'", trim(fields[14])),
                    columnOf(line, fields[14]));
            }
            trial.truth.emplace_back(v[10], v[11], v[12], v[13]);
            trial.movement.push_back(v[14] == 1.0);
        }
    }
    int zerr = Z_OK;
    const char* zmsg = gzerror(f.get(), &zerr);
    if (zerr != Z_OK && zerr != Z_STREAM_END) {
        return lineError(path, lineNo, fmt::format("read error: {}", zmsg ? zmsg : "unknown"));
    }
    if (trial.samples.size() < 2) {
        return lineError(path, lineNo, "expected at least two samples");
    }
    if (trial.rateHz <= 0.0) {
        // No rate in the comment: the median sample spacing.
        std::vector<double> dt;
        dt.reserve(trial.samples.size() - 1);
        for (std::size_t i = 1; i < trial.samples.size(); ++i) {
            dt.push_back(trial.samples[i].tS - trial.samples[i - 1].tS);
        }
        std::nth_element(dt.begin(), dt.begin() + static_cast<std::ptrdiff_t>(dt.size() / 2),
                         dt.end());
        trial.rateHz = 1.0 / dt[dt.size() / 2];
    }
    return trial;
}

Result<void> writeBroadCsv(const std::filesystem::path& path, const BroadTrial& trial) {
    return writeBroadCsv(path, trial, path.extension() == ".gz");
}

Result<void> writeBroadCsv(const std::filesystem::path& path, const BroadTrial& trial, bool gz) {
    auto fd = createOutputFd(path);
    if (!fd) {
        return fd.error();
    }
    errno = 0;
    GzFile f(gzdopen(*fd, gz ? "wb6" : "wT"));
    if (!f) {
        ::close(*fd);
        return errnoError(errno != 0 ? -errno : -EIO, fmt::format("create '{}'", path.string()));
    }
    const bool truth = trial.hasTruth();
    std::string out =
        fmt::format("# BROAD trial {}; sampling_rate_hz={:.6f}\n", trial.name, trial.rateHz);
    for (std::size_t i = 0; i < (truth ? kColumns.size() : kImuColumns); ++i) {
        out += fmt::format("{}{}", i == 0 ? "" : ",", kColumns[i]);
    }
    out += '\n';
    auto flush = [&](bool force) -> bool {
        if (!force && out.size() < (1 << 16)) {
            return true;
        }
        const bool ok =
            out.empty() || gzwrite(f.get(), out.data(), static_cast<unsigned>(out.size())) ==
                               static_cast<int>(out.size());
        out.clear();
        return ok;
    };
    for (std::size_t i = 0; i < trial.samples.size(); ++i) {
        const auto& s = trial.samples[i];
        out += fmt::format("{:.6f},{:.9g},{:.9g},{:.9g},{:.9g},{:.9g},{:.9g},{:.9g},{:.9g},{:.9g}",
                           s.tS, s.gyrRadS.x(), s.gyrRadS.y(), s.gyrRadS.z(), s.accMps2.x(),
                           s.accMps2.y(), s.accMps2.z(), s.magUt.x(), s.magUt.y(), s.magUt.z());
        if (truth) {
            const Quatd& q = trial.truth[i];
            auto num = [](double x) { return std::isfinite(x) ? fmt::format("{:.9g}", x) : "nan"; };
            out += fmt::format(",{},{},{},{},{}", num(q.w()), num(q.x()), num(q.y()), num(q.z()),
                               trial.movement[i] ? 1 : 0);
        }
        out += '\n';
        if (!flush(false)) {
            return Error{EIO, fmt::format("write '{}': failed", path.string())};
        }
    }
    if (!flush(true)) {
        return Error{EIO, fmt::format("write '{}': failed", path.string())};
    }
    if (gzclose(f.release()) != Z_OK) {
        return Error{EIO, fmt::format("close '{}': failed", path.string())};
    }
    return {};
}

}  // namespace caphub::firmware
