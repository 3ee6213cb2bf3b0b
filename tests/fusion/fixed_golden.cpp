#include "tests/fusion/fixed_golden.h"

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include <zlib.h>

#include "fusion/orientation_filter.h"

namespace caphub::fusion::golden {

namespace {

constexpr int kColumns = 10;  // t, gyr x3, acc x3, mag x3

Error lineError(const std::string& path, std::size_t line, const std::string& what) {
    return Error{EINVAL, path + ":" + std::to_string(line) + ": " + what};
}

// Parses the first kColumns comma-separated numbers of a row into v.
bool parseRow(const std::string& row, double (&v)[kColumns], std::string& why) {
    const char* p = row.c_str();
    for (int i = 0; i < kColumns; ++i) {
        char* end = nullptr;
        errno = 0;
        const double x = std::strtod(p, &end);
        if (end == p || errno == ERANGE || !std::isfinite(x)) {
            why = "expected a finite number in column " + std::to_string(i + 1);
            return false;
        }
        v[i] = x;
        p = end;
        if (i + 1 < kColumns) {
            if (*p != ',') {
                why = "expected ',' after column " + std::to_string(i + 1) + " (" +
                      std::to_string(kColumns) + " columns: t, gyr, acc, mag)";
                return false;
            }
            ++p;
        }
    }
    if (*p != '\0' && *p != ',' && *p != '\r') {
        why = "unexpected text after column " + std::to_string(kColumns);
        return false;
    }
    return true;
}

}  // namespace

Result<std::vector<ImuSample>> readExcerpt(const std::string& path) {
    gzFile f = gzopen(path.c_str(), "rb");  // reads plain files unchanged
    if (f == nullptr) {
        return errnoError(-(errno != 0 ? errno : ENOENT), "open '" + path + "'");
    }
    std::vector<ImuSample> out;
    char buf[4096];
    std::size_t line = 0;
    bool headerSeen = false;
    while (gzgets(f, buf, sizeof buf) != nullptr) {
        ++line;
        std::string row(buf);
        if (row.empty() || row.back() != '\n') {
            if (row.size() + 1 >= sizeof buf) {
                gzclose(f);
                return lineError(path, line, "line longer than 4095 characters");
            }
        } else {
            row.pop_back();
        }
        if (row.empty() || row[0] == '#') {
            continue;
        }
        if (!headerSeen) {
            headerSeen = true;
            if (row.rfind("t,gyr_x,gyr_y,gyr_z,acc_x,acc_y,acc_z,mag_x,mag_y,mag_z", 0) != 0) {
                gzclose(f);
                return lineError(path, line,
                                 "expected the header "
                                 "'t,gyr_x,gyr_y,gyr_z,acc_x,acc_y,acc_z,mag_x,mag_y,mag_z'");
            }
            continue;
        }
        double v[kColumns];
        std::string why;
        if (!parseRow(row, v, why)) {
            gzclose(f);
            return lineError(path, line, why);
        }
        ImuSample s;
        s.tS = v[0];
        s.gyrRadS = Vec3d(v[1], v[2], v[3]);
        s.accMps2 = Vec3d(v[4], v[5], v[6]);
        s.magUt = Vec3d(v[7], v[8], v[9]);
        out.push_back(s);
    }
    int zerr = Z_OK;
    const char* zmsg = gzerror(f, &zerr);
    const std::string zText = zmsg != nullptr ? zmsg : "";
    gzclose(f);
    if (zerr != Z_OK && zerr != Z_STREAM_END) {
        return lineError(path, line + 1, "cannot decompress: " + zText);
    }
    if (out.empty()) {
        return lineError(path, line, "expected at least one data row");
    }
    return out;
}

std::vector<std::int32_t> runFixedRaw(const std::vector<ImuSample>& samples) {
    using S = FixedTypes;
    FilterParams params;
    params.gyrRateHz = params.accRateHz = params.magRateHz = kRateHz;
    OrientationFilter<S> filter(params);
    std::vector<std::int32_t> raw;
    raw.reserve(samples.size() * kValuesPerSample);
    for (const ImuSample& s : samples) {
        filter.updateGyr(fromDoubleVec<S::Gyr>(s.gyrRadS.x(), s.gyrRadS.y(), s.gyrRadS.z()));
        filter.updateAcc(fromDoubleVec<S::Acc>(s.accMps2.x(), s.accMps2.y(), s.accMps2.z()));
        filter.updateMag(fromDoubleVec<S::Mag>(s.magUt.x(), s.magUt.y(), s.magUt.z()));
        const Quat<S::Unit> q = filter.quat();
        const Vec3<S::Bias> b = filter.bias();
        for (std::int32_t v : {q.w.raw, q.x.raw, q.y.raw, q.z.raw, b.x.raw, b.y.raw, b.z.raw}) {
            raw.push_back(v);
        }
    }
    return raw;
}

void Fnv1a64::addInt32(std::int32_t v) {
    const auto u = static_cast<std::uint32_t>(v);
    for (int shift = 0; shift < 32; shift += 8) {
        addByte(static_cast<std::uint8_t>((u >> shift) & 0xffU));
    }
}

void Fnv1a64::addBytes(const std::string& s) {
    for (char c : s) {
        addByte(static_cast<std::uint8_t>(c));
    }
}

std::vector<Checkpoint> checkpoints(const std::vector<std::int32_t>& raw) {
    std::vector<Checkpoint> out;
    Fnv1a64 h;
    const std::size_t n = raw.size() / kValuesPerSample;
    for (std::size_t i = 0; i < n; ++i) {
        for (std::size_t k = 0; k < kValuesPerSample; ++k) {
            h.addInt32(raw[i * kValuesPerSample + k]);
        }
        if ((i + 1) % kCheckpointSamples == 0 || i + 1 == n) {
            out.push_back({i + 1, h.value()});
        }
    }
    return out;
}

std::string formatGolden(const std::vector<Checkpoint>& points, const std::string& comment) {
    std::ostringstream os;
    std::istringstream lines(comment);
    for (std::string l; std::getline(lines, l);) {
        os << "# " << l << '\n';
    }
    for (const Checkpoint& c : points) {
        char hex[17];
        for (int i = 0; i < 16; ++i) {
            hex[i] = "0123456789abcdef"[(c.hash >> (60 - 4 * i)) & 0xfU];
        }
        hex[16] = '\0';
        os << "hash " << c.samples << ' ' << hex << '\n';
    }
    return os.str();
}

Result<std::vector<Checkpoint>> readGolden(const std::string& path) {
    std::ifstream in(path);
    if (!in) {
        return errnoError(-(errno != 0 ? errno : ENOENT), "open '" + path + "'");
    }
    std::vector<Checkpoint> out;
    std::size_t line = 0;
    for (std::string row; std::getline(in, row);) {
        ++line;
        if (row.empty() || row[0] == '#') {
            continue;
        }
        std::istringstream fields(row);
        std::string key;
        std::string count;
        std::string hex;
        std::string extra;
        fields >> key >> count >> hex;
        const bool countOk = !count.empty() && count.size() <= 12 &&
                             count.find_first_not_of("0123456789") == std::string::npos;
        const bool hexOk =
            hex.size() == 16 && hex.find_first_not_of("0123456789abcdef") == std::string::npos;
        if (key != "hash" || !countOk || !hexOk || (fields >> extra)) {
            return lineError(path, line,
                             "expected 'hash SAMPLES HEX' with 16 lowercase hex digits");
        }
        Checkpoint c;
        c.samples = static_cast<std::size_t>(std::stoull(count));
        c.hash = std::stoull(hex, nullptr, 16);
        if (!out.empty() && c.samples <= out.back().samples) {
            return lineError(path, line, "expected sample counts in increasing order");
        }
        out.push_back(c);
    }
    if (out.empty()) {
        return lineError(path, line, "expected at least one 'hash' line");
    }
    return out;
}

}  // namespace caphub::fusion::golden
