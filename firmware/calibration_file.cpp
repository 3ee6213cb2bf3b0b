#include "firmware/calibration_file.h"

#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>

#include <Eigen/SVD>
#include <fmt/format.h>
#include <toml++/toml.h>

#include "hal/core/input_file.h"
#include "hal/core/output_fd.h"

namespace caphub::firmware {

namespace {

// Example:
//   format = 1
//   [sensors.l_forearm]
//   gyro_bias_rad_s = [0.001, -0.002, 0.0005]
//   gyro_matrix = [[1.01, 0.02, 0.0], [-0.01, 0.99, 0.01], [0.0, 0.0, 1.0]]
//   acc_offset_m_s2 = [0.05, -0.02, 0.1]
//   acc_matrix = [[0.998, 0.01, 0.0], [0.01, 1.002, 0.0], [0.0, 0.0, 0.999]]
//   mag_hard_iron_ut = [12.0, -3.5, 40.2]
//   mag_soft_iron = [[1.01, 0.02, 0.0], [0.02, 0.99, 0.01], [0.0, 0.01, 1.0]]
//   mag_quality_pct = 0.8
//   mag_coverage = 0.92
// Files of earlier builds give the accelerometer's per-axis scale instead of its matrix:
//   acc_scale = [1.002, 0.998, 1.001]   (acc = (raw - offset) / scale)

// A TOML key: bare when it can be, else a basic string with " and \ escaped.
std::string tomlKey(const std::string& name) {
    bool bare = !name.empty();
    for (char ch : name) {
        bare = bare && (std::isalnum(static_cast<unsigned char>(ch)) || ch == '_' || ch == '-');
    }
    if (bare) {
        return name;
    }
    std::string out = "\"";
    for (char ch : name) {
        if (ch == '"' || ch == '\\') {
            out += '\\';
        }
        out += ch;
    }
    return out + "\"";
}

std::string where(const std::string& origin, const toml::node& n) {
    const auto& s = n.source();
    return fmt::format("{}:{}:{}", origin, s.begin.line, s.begin.column);
}

Error at(const std::string& origin, const toml::node& n, const std::string& what) {
    return Error{EINVAL, fmt::format("{}: {}", where(origin, n), what)};
}

Result<double> number(const std::string& origin, const toml::node& n, const std::string& key) {
    if (auto v = n.value<double>(); v && std::isfinite(*v)) {
        return *v;
    }
    return at(origin, n, fmt::format("'{}': expected a finite number", key));
}

Result<Vec3d> vec3(const std::string& origin, const toml::node& n, const std::string& key) {
    const toml::array* a = n.as_array();
    if (a == nullptr || a->size() != 3) {
        return at(origin, n, fmt::format("'{}': expected an array of 3 numbers", key));
    }
    Vec3d v;
    for (std::size_t i = 0; i < 3; ++i) {
        auto x = number(origin, *a->get(i), key);
        if (!x) {
            return x.error();
        }
        v[static_cast<Eigen::Index>(i)] = *x;
    }
    return v;
}

Result<Eigen::Matrix3d> mat3(const std::string& origin, const toml::node& n,
                             const std::string& key) {
    const toml::array* a = n.as_array();
    if (a == nullptr || a->size() != 3) {
        return at(origin, n, fmt::format("'{}': expected 3 rows of 3 numbers", key));
    }
    Eigen::Matrix3d m;
    for (std::size_t r = 0; r < 3; ++r) {
        auto row = vec3(origin, *a->get(r), key);
        if (!row) {
            return row.error();
        }
        m.row(static_cast<Eigen::Index>(r)) = row->transpose();
    }
    return m;
}

// What a file may say of a sensor: bounds an order of magnitude beyond any MEMS part's
// datasheet, so that a typing slip or a damaged file (a bias of 1e300) is refused with its line
// instead of turning every sample it corrects into noise or overflow.
constexpr double kMaxGyroBiasRadS = 0.5;   // 29 deg/s; parts' zero-rate offsets reach 5 deg/s
constexpr double kMaxAccOffsetMps2 = 5.0;  // 0.5 g; parts' zero-g offsets reach 0.1 g
constexpr double kMaxHardIronUt = 5000.0;  // beyond a magnetometer's range (AK09916: 4912 uT)
// The axes matrices' singular values (a scale): the calibrators refuse 1 +- 0.2.
constexpr double kMinAxesScale = 0.5;
constexpr double kMaxAxesScale = 2.0;
// The soft-iron matrix's: a strong distortion of the field, not a tenfold one.
constexpr double kMinSoftIronScale = 0.1;
constexpr double kMaxSoftIronScale = 10.0;

Result<void> withinMagnitude(const std::string& origin, const toml::node& n, const std::string& key,
                             const Vec3d& v, double max, const char* unit) {
    if (v.cwiseAbs().maxCoeff() > max) {
        return at(origin, n,
                  fmt::format("'{}': {:g} {} is beyond what a sensor has (at most {:g})", key,
                              v.cwiseAbs().maxCoeff(), unit, max));
    }
    return {};
}

Result<void> withinScale(const std::string& origin, const toml::node& n, const std::string& key,
                         const Eigen::Matrix3d& m, double min, double max) {
    if (!(std::abs(m.determinant()) > 1e-9)) {
        return at(origin, n, fmt::format("'{}': the matrix is singular", key));
    }
    const Vec3d sv = Eigen::JacobiSVD<Eigen::Matrix3d>(m).singularValues();
    if (sv.minCoeff() < min || sv.maxCoeff() > max) {
        return at(origin, n,
                  fmt::format("'{}': the matrix scales by {:.3g} to {:.3g}; a calibration "
                              "scales by {:g} to {:g}",
                              key, sv.minCoeff(), sv.maxCoeff(), min, max));
    }
    return {};
}

Result<fusion::SensorCalibration> parseSensor(const std::string& origin, const std::string& name,
                                              const toml::table& t) {
    fusion::SensorCalibration c;
    for (const auto& [k, node] : t) {
        const std::string key(k.str());
        const std::string full = fmt::format("sensors.{}.{}", name, key);
        if (key == "gyro_bias_rad_s") {
            auto v = vec3(origin, node, full);
            if (!v) {
                return v.error();
            }
            if (auto ok = withinMagnitude(origin, node, full, *v, kMaxGyroBiasRadS, "rad/s"); !ok) {
                return ok.error();
            }
            c.gyroBiasRadS = *v;
            c.hasGyro = true;
        } else if (key == "acc_offset_m_s2" || key == "acc_scale") {
            auto v = vec3(origin, node, full);
            if (!v) {
                return v.error();
            }
            if (key == "acc_scale") {
                if ((v->array() < kMinAxesScale).any() || (v->array() > kMaxAxesScale).any()) {
                    return at(origin, node,
                              fmt::format("'{}': expected scales from {:g} to {:g}", full,
                                          kMinAxesScale, kMaxAxesScale));
                }
                if (t.contains("acc_matrix")) {
                    return at(origin, node,
                              fmt::format("'{}': give acc_scale or acc_matrix, not both", full));
                }
                c.accMatrix = v->cwiseInverse().asDiagonal();
            } else {
                if (auto ok = withinMagnitude(origin, node, full, *v, kMaxAccOffsetMps2, "m/s^2");
                    !ok) {
                    return ok.error();
                }
                c.accOffsetMps2 = *v;
            }
            c.hasAccel = true;
        } else if (key == "acc_matrix" || key == "gyro_matrix") {
            auto m = mat3(origin, node, full);
            if (!m) {
                return m.error();
            }
            if (auto ok = withinScale(origin, node, full, *m, kMinAxesScale, kMaxAxesScale); !ok) {
                return ok.error();
            }
            if (key == "acc_matrix") {
                c.accMatrix = *m;
                c.hasAccel = true;
            } else {
                c.gyroMatrix = *m;
                c.hasGyroAxes = true;
            }
        } else if (key == "mag_hard_iron_ut") {
            auto v = vec3(origin, node, full);
            if (!v) {
                return v.error();
            }
            if (auto ok = withinMagnitude(origin, node, full, *v, kMaxHardIronUt, "uT"); !ok) {
                return ok.error();
            }
            c.magHardIronUt = *v;
            c.hasMag = true;
        } else if (key == "mag_soft_iron") {
            auto m = mat3(origin, node, full);
            if (!m) {
                return m.error();
            }
            if (auto ok = withinScale(origin, node, full, *m, kMinSoftIronScale, kMaxSoftIronScale);
                !ok) {
                return ok.error();
            }
            c.magSoftIron = *m;
            c.hasMag = true;
        } else if (key == "mag_quality_pct" || key == "mag_coverage") {
            auto v = number(origin, node, full);
            if (!v) {
                return v.error();
            }
            const double max = key == "mag_quality_pct" ? 100.0 : 1.0;
            if (!(*v >= 0.0 && *v <= max)) {
                return at(origin, node, fmt::format("'{}': expected 0 to {:g}", full, max));
            }
            (key == "mag_quality_pct" ? c.magQualityPct : c.magCoverage) = *v;
        } else {
            return at(origin, node,
                      fmt::format("unknown key '{}' (expected gyro_bias_rad_s, gyro_matrix, "
                                  "acc_offset_m_s2, acc_matrix, acc_scale, mag_hard_iron_ut, "
                                  "mag_soft_iron, mag_quality_pct, mag_coverage)",
                                  full));
        }
    }
    return c;
}

}  // namespace

Result<CalibrationSet> parseCalibration(std::string_view text, const std::string& origin) {
    toml::table root;
    try {
        root = toml::parse(text, origin);
    } catch (const toml::parse_error& e) {
        const auto& b = e.source().begin;
        return Error{EINVAL,
                     fmt::format("{}:{}:{}: {}", origin, b.line, b.column, e.description())};
    }
    const toml::node* format = root.get("format");
    if (format == nullptr) {
        return Error{EINVAL, fmt::format("{}: missing 'format = {}'", origin, kCalibrationFormat)};
    }
    if (format->value<std::int64_t>() != std::optional<std::int64_t>(kCalibrationFormat)) {
        return at(origin, *format,
                  fmt::format("'format': expected {} (the version this build reads)",
                              kCalibrationFormat));
    }
    CalibrationSet set;
    for (const auto& [k, node] : root) {
        const std::string key(k.str());
        if (key == "format") {
            continue;
        }
        if (key != "sensors") {
            return at(origin, node,
                      fmt::format("unknown key '{}' (expected format, sensors)", key));
        }
        const toml::table* sensors = node.as_table();
        if (sensors == nullptr) {
            return at(origin, node, "'sensors': expected a table of sensor tables");
        }
        for (const auto& [name, sensorNode] : *sensors) {
            const toml::table* t = sensorNode.as_table();
            if (t == nullptr) {
                return at(origin, sensorNode,
                          fmt::format("'sensors.{}': expected a table", name.str()));
            }
            auto c = parseSensor(origin, std::string(name.str()), *t);
            if (!c) {
                return c.error();
            }
            set.emplace(std::string(name.str()), *c);
        }
    }
    return set;
}

Result<CalibrationSet> readCalibrationFile(const std::filesystem::path& path) {
    auto text = readInputFile(path);
    if (!text) {
        return text.error();
    }
    return parseCalibration(*text, path.string());
}

std::string formatCalibration(const CalibrationSet& set) {
    auto v3 = [](const Vec3d& v) {
        return fmt::format("[{:.17g}, {:.17g}, {:.17g}]", v.x(), v.y(), v.z());
    };
    auto m3 = [&v3](const Eigen::Matrix3d& m) {
        return fmt::format("[{}, {}, {}]", v3(m.row(0).transpose()), v3(m.row(1).transpose()),
                           v3(m.row(2).transpose()));
    };
    std::string out = fmt::format("# caphub sensor calibration\nformat = {}\n", kCalibrationFormat);
    for (const auto& [name, c] : set) {
        out += fmt::format("\n[sensors.{}]\n", tomlKey(name));
        if (c.hasGyro) {
            out += fmt::format("gyro_bias_rad_s = {}\n", v3(c.gyroBiasRadS));
        }
        if (c.hasGyroAxes) {
            out += fmt::format("gyro_matrix = {}\n", m3(c.gyroMatrix));
        }
        if (c.hasAccel) {
            out += fmt::format("acc_offset_m_s2 = {}\nacc_matrix = {}\n", v3(c.accOffsetMps2),
                               m3(c.accMatrix));
        }
        if (c.hasMag) {
            out += fmt::format("mag_hard_iron_ut = {}\n", v3(c.magHardIronUt));
            out += fmt::format("mag_soft_iron = {}\n", m3(c.magSoftIron));
            out += fmt::format("mag_quality_pct = {:.17g}\nmag_coverage = {:.17g}\n",
                               c.magQualityPct, c.magCoverage);
        }
    }
    return out;
}

Result<void> writeCalibrationFile(const std::filesystem::path& given, const CalibrationSet& set) {
    const std::string text = formatCalibration(set);
    // A symbolic link stays one: the file it names is replaced.
    std::error_code ec;
    const std::filesystem::path path = std::filesystem::is_symlink(given, ec)
                                           ? std::filesystem::weakly_canonical(given, ec)
                                           : given;
    // Written whole: into PATH.part (a regular file, never through a link or into a FIFO), renamed
    // over the file when complete, so that a failed or interrupted write leaves it as it was.
    return replaceFileWhole(path, path.string() + ".part", text);
}

std::vector<std::optional<fusion::SensorCalibration>> calibrationsFor(
    const board::Board& board, const CalibrationSet& set, std::vector<std::string>* unknown) {
    std::vector<std::optional<fusion::SensorCalibration>> out(board.sensors.size());
    for (std::size_t i = 0; i < board.sensors.size(); ++i) {
        if (auto it = set.find(board.sensors[i].name); it != set.end()) {
            out[i] = it->second;
        }
    }
    if (unknown != nullptr) {
        for (const auto& [name, cal] : set) {
            bool found = false;
            for (const auto& s : board.sensors) {
                found = found || s.name == name;
            }
            if (!found) {
                unknown->push_back(name);
            }
        }
    }
    return out;
}

}  // namespace caphub::firmware
