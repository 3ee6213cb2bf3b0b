#include "firmware/io/xsens_text.h"

#include <array>
#include <charconv>
#include <cmath>
#include <map>
#include <sstream>

#include <fmt/format.h>

#include "board/loader.h"
#include "hal/core/angles.h"
#include "hal/core/input_file.h"

namespace caphub::firmware {

namespace {

// The largest reading accepted: no sensor measures beyond it (m/s^2, rad/s, field units).
constexpr double kMaxXsensValue = 1e6;
// How far a row's Quat_q0..q3 and Mat[r][c] may lie apart when a file has both (deg): the
// files' 6 decimals round an orientation by about 1e-4 deg.
constexpr double kMaxQuatMatrixDisagreementDeg = 0.1;

struct Cell {
    std::string_view text;
    int column = 0;  // 1-based, in characters of the line
};

std::vector<Cell> splitCells(std::string_view line, char sep) {
    std::vector<Cell> out;
    std::size_t start = 0;
    for (;;) {
        const std::size_t end = line.find(sep, start);
        std::string_view cell =
            line.substr(start, end == std::string_view::npos ? end : end - start);
        // Surrounding spaces are not part of a value.
        std::size_t lead = 0;
        while (lead < cell.size() && cell[lead] == ' ') {
            ++lead;
        }
        cell.remove_prefix(lead);
        while (!cell.empty() && cell.back() == ' ') {
            cell.remove_suffix(1);
        }
        out.push_back({cell, static_cast<int>(start + lead) + 1});
        if (end == std::string_view::npos) {
            return out;
        }
        start = end + 1;
    }
}

class Parser {
public:
    explicit Parser(std::string path) : path_(std::move(path)) {}

    Error error(int line, int column, const std::string& what) const {
        return Error{EINVAL, fmt::format("{}:{}:{}: {}", path_, line, column, what)};
    }

    Result<double> number(int line, const Cell& c, std::string_view name) const {
        double v = 0;
        const char* end = c.text.data() + c.text.size();
        const auto [ptr, ec] = std::from_chars(c.text.data(), end, v);
        if (c.text.empty()) {
            return error(line, c.column,
                         fmt::format("{}: expected a number, found an empty cell", name));
        }
        if (ec != std::errc() || ptr != end || !std::isfinite(v)) {
            return error(line, c.column,
                         fmt::format("{}: expected a number, found '{}'", name, c.text));
        }
        // Far beyond any sensor's range, and infinite as the float a recording stores.
        if (std::abs(v) > kMaxXsensValue) {
            return error(line, c.column,
                         fmt::format("{}: {} is out of range (at most {:g} either way)", name,
                                     c.text, kMaxXsensValue));
        }
        return v;
    }

    // "// Update Rate: 100.0Hz" from `at` (where "Update Rate:" starts): the imported chip's
    // 1 to 10000 Hz, written with a point and followed by Hz alone ("59,94Hz" read as 59).
    Result<double> updateRate(int line, std::string_view l, std::size_t at) const {
        const std::string_view rest = l.substr(at + 12);
        std::size_t b = 0;
        while (b < rest.size() && rest[b] == ' ') {
            ++b;
        }
        double hz = 0;
        const auto [ptr, ec] = std::from_chars(rest.data() + b, rest.data() + rest.size(), hz);
        std::string_view unit(ptr, static_cast<std::size_t>(rest.data() + rest.size() - ptr));
        const std::size_t from = unit.find_first_not_of(' ');
        unit = from == std::string_view::npos
                   ? std::string_view()
                   : unit.substr(from, unit.find_last_not_of(' ') - from + 1);
        if (ec != std::errc() || (unit != "Hz" && unit != "hz") || !(hz >= 1 && hz <= 10000)) {
            return error(line, static_cast<int>(at + 13 + b),
                         "Update Rate: expected a rate of 1 to 10000 Hz such as 100.0Hz");
        }
        return hz;
    }

    Result<XsensFile> run(const std::string& text) {
        XsensFile f;
        f.path = path_;
        f.deviceId = xsensDeviceId(path_);
        std::istringstream in(text);
        std::string raw;
        int line = 0;
        std::map<std::string, int> col;  // column name -> index
        std::vector<std::string> names;
        bool header = false;
        std::int64_t unwrapped = 0;
        std::uint16_t previous = 0;
        bool first = true;
        while (std::getline(in, raw)) {
            ++line;
            if (!raw.empty() && raw.back() == '\r') {
                raw.pop_back();
            }
            const std::string_view l(raw);
            if (!header) {
                if (l.rfind("//", 0) == 0) {
                    if (const auto at = l.find("Update Rate:"); at != std::string_view::npos) {
                        auto hz = updateRate(line, l, at);
                        if (!hz) {
                            return hz.error();
                        }
                        if (f.rateHz > 0 && *hz != f.rateHz) {
                            return error(line, static_cast<int>(at) + 1,
                                         fmt::format("a second Update Rate ({:g} Hz after {:g} "
                                                     "Hz): which one the samples were taken at "
                                                     "is not known",
                                                     *hz, f.rateHz));
                        }
                        f.rateHz = *hz;
                    }
                    continue;
                }
                if (l.empty()) {
                    continue;
                }
                f.separator = l.find('\t') != std::string_view::npos ? '\t' : ',';
                for (const auto& c : splitCells(l, f.separator)) {
                    if (!c.text.empty() &&
                        !col.emplace(std::string(c.text), static_cast<int>(names.size())).second) {
                        return error(line, c.column,
                                     fmt::format("a second {} column: which one holds the "
                                                 "readings is not known",
                                                 c.text));
                    }
                    names.emplace_back(c.text);
                }
                for (const char* need :
                     {"PacketCounter", "Acc_X", "Acc_Y", "Acc_Z", "Gyr_X", "Gyr_Y", "Gyr_Z"}) {
                    if (col.count(need) == 0) {
                        return error(line, 1,
                                     fmt::format("the header has no {} column (expected "
                                                 "PacketCounter, Acc_X..Z, Gyr_X..Z; Mag_X..Z, "
                                                 "Quat_q0..q3 or Mat[r][c] optional)",
                                                 need));
                    }
                }
                f.hasMag = col.count("Mag_X") && col.count("Mag_Y") && col.count("Mag_Z");
                const bool quat = col.count("Quat_q0") && col.count("Quat_q1") &&
                                  col.count("Quat_q2") && col.count("Quat_q3");
                if (quat && hasMatrix(col)) {
                    f.orientationColumns = "quaternion and matrix";
                } else if (quat) {
                    f.orientationColumns = "quaternion";
                } else if (hasMatrix(col)) {
                    f.orientationColumns = "matrix";
                }
                if (f.rateHz <= 0) {
                    return error(line, 1,
                                 "no '// Update Rate: ...Hz' line before the header: the sample "
                                 "times need the rate");
                }
                header = true;
                continue;
            }
            if (l.empty()) {
                continue;
            }
            const auto cells = splitCells(l, f.separator);
            if (cells.size() != names.size()) {
                return error(line, 1,
                             fmt::format("expected {} cells as in the header, found {}",
                                         names.size(), cells.size()));
            }
            const auto at = [&](const char* name) -> const Cell& {
                return cells[static_cast<std::size_t>(col.at(name))];
            };
            auto counter = number(line, at("PacketCounter"), "PacketCounter");
            if (!counter) {
                return counter.error();
            }
            if (*counter < 0 || *counter > 65535 || std::floor(*counter) != *counter) {
                return error(line, at("PacketCounter").column,
                             fmt::format("PacketCounter: expected an integer 0-65535, found '{}'",
                                         at("PacketCounter").text));
            }
            const auto pc = static_cast<std::uint16_t>(*counter);
            if (first) {
                f.firstCounter = pc;
                first = false;
            } else {
                const auto step = static_cast<std::uint16_t>(pc - previous);
                if (step == 0 || step > 32768) {
                    return error(line, at("PacketCounter").column,
                                 fmt::format("PacketCounter {} after {}: expected a later packet "
                                             "(repeated or out of order)",
                                             pc, previous));
                }
                if (step > 1) {
                    f.gaps.push_back({line, unwrapped, step - 1});
                    f.lostPackets += step - 1;
                }
                unwrapped += step;
            }
            previous = pc;
            XsensSample s;
            s.packet = unwrapped;
            for (int i = 0; i < 3; ++i) {
                const std::array<const char*, 3> acc = {"Acc_X", "Acc_Y", "Acc_Z"};
                const std::array<const char*, 3> gyr = {"Gyr_X", "Gyr_Y", "Gyr_Z"};
                auto a = number(line, at(acc[static_cast<std::size_t>(i)]),
                                acc[static_cast<std::size_t>(i)]);
                if (!a) {
                    return a.error();
                }
                auto g = number(line, at(gyr[static_cast<std::size_t>(i)]),
                                gyr[static_cast<std::size_t>(i)]);
                if (!g) {
                    return g.error();
                }
                s.accMps2[i] = *a;
                s.gyrRadps[i] = *g;
            }
            if (f.hasMag) {
                Eigen::Vector3d m;
                const std::array<const char*, 3> mag = {"Mag_X", "Mag_Y", "Mag_Z"};
                for (int i = 0; i < 3; ++i) {
                    auto v = number(line, at(mag[static_cast<std::size_t>(i)]),
                                    mag[static_cast<std::size_t>(i)]);
                    if (!v) {
                        return v.error();
                    }
                    m[i] = *v;
                }
                s.mag = m;
            }
            std::optional<Eigen::Quaterniond> fromQuat;
            if (f.orientationColumns.starts_with("quaternion")) {
                std::array<double, 4> q{};
                const std::array<const char*, 4> qn = {"Quat_q0", "Quat_q1", "Quat_q2", "Quat_q3"};
                for (std::size_t i = 0; i < 4; ++i) {
                    auto v = number(line, at(qn[i]), qn[i]);
                    if (!v) {
                        return v.error();
                    }
                    q[i] = *v;
                }
                const Eigen::Quaterniond quat(q[0], q[1], q[2], q[3]);  // q0 is w
                if (std::abs(quat.norm() - 1) > 0.01) {
                    return error(line, at("Quat_q0").column,
                                 fmt::format("Quat_q0..q3: expected a unit quaternion, norm {:.4f}",
                                             quat.norm()));
                }
                fromQuat = quat.normalized();
                s.qEarthSensor = fromQuat;
            }
            if (f.orientationColumns.ends_with("matrix")) {
                Eigen::Matrix3d r;
                for (int i = 0; i < 3; ++i) {
                    for (int j = 0; j < 3; ++j) {
                        const std::string name = fmt::format("Mat[{}][{}]", i + 1, j + 1);
                        auto v = number(line, cells[static_cast<std::size_t>(col.at(name))], name);
                        if (!v) {
                            return v.error();
                        }
                        r(i, j) = *v;
                    }
                }
                const Cell& m11 = cells[static_cast<std::size_t>(col.at("Mat[1][1]"))];
                if ((r.transpose() * r - Eigen::Matrix3d::Identity()).norm() > 0.01 ||
                    r.determinant() < 0) {
                    return error(line, m11.column, "Mat[r][c]: expected a rotation matrix");
                }
                const Eigen::Quaterniond fromMatrix = Eigen::Quaterniond(r).normalized();
                if (fromQuat) {
                    // Both written: one orientation in two forms, equal to the file's 4-6
                    // decimals. Apart, the file says two things and neither is taken.
                    const double deg = fromQuat->angularDistance(fromMatrix) * hal::kRadToDeg;
                    if (deg > kMaxQuatMatrixDisagreementDeg) {
                        return error(line, m11.column,
                                     fmt::format("Mat[r][c] is {:.2f} deg from Quat_q0..q3 on the "
                                                 "same row (at most {:g}): which one is the "
                                                 "vendor's orientation?",
                                                 deg, kMaxQuatMatrixDisagreementDeg));
                    }
                } else {
                    s.qEarthSensor = fromMatrix;
                }
            }
            f.samples.push_back(s);
        }
        if (!header) {
            return error(line, 1, "no header row (PacketCounter, Acc_X, ...)");
        }
        if (f.samples.empty()) {
            return error(line, 1, "no data row after the header");
        }
        return f;
    }

private:
    static bool hasMatrix(const std::map<std::string, int>& col) {
        for (int i = 1; i <= 3; ++i) {
            for (int j = 1; j <= 3; ++j) {
                if (col.count(fmt::format("Mat[{}][{}]", i, j)) == 0) {
                    return false;
                }
            }
        }
        return true;
    }

    std::string path_;
};

}  // namespace

std::string xsensDeviceId(const std::filesystem::path& path) {
    const std::string stem = path.stem().string();
    const auto at = stem.rfind('_');
    return at == std::string::npos ? stem : stem.substr(at + 1);
}

Result<XsensFile> readXsensText(const std::filesystem::path& path) {
    auto text = readInputFile(path);
    if (!text) {
        return text.error();
    }
    // The device id names the sensor in the board the import makes, and files after it.
    if (const std::string problem = board::nameProblem("the Xsens device", xsensDeviceId(path));
        !problem.empty()) {
        return Error{EINVAL, fmt::format("{}: {} (from the file name's last '_' part)",
                                         path.string(), problem)};
    }
    return Parser(path.string()).run(*text);
}

}  // namespace caphub::firmware
