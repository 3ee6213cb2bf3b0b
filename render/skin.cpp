#include "render/skin.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <fstream>

#include <fmt/format.h>
#include <zlib.h>

namespace caphub::render {

namespace {

constexpr char kMagic[8] = {'C', 'A', 'P', 'H', 'U', 'B', 'S', 'K'};
constexpr std::uint32_t kFormatVersion = 1;
// Far above any skin a hub can draw; stops a corrupt count from asking for gigabytes.
constexpr std::uint32_t kMaxVertices = 4'000'000;
constexpr std::uint32_t kMaxTriangles = 8'000'000;
constexpr std::uint32_t kMaxPayloadBytes = 256u << 20;

static_assert(std::endian::native == std::endian::little,
              "the .mesh codec writes host floats; add byte swapping for big-endian hosts");

class Writer {
public:
    template <typename T>
    void put(T v) {
        const auto* p = reinterpret_cast<const std::uint8_t*>(&v);
        bytes_.insert(bytes_.end(), p, p + sizeof(T));
    }
    void putString(std::string_view s) {
        put(static_cast<std::uint16_t>(s.size()));
        bytes_.insert(bytes_.end(), s.begin(), s.end());
    }
    std::vector<std::uint8_t>& bytes() { return bytes_; }

private:
    std::vector<std::uint8_t> bytes_;
};

// Bounds-checked reading: the first failure is kept with the offset and what was being read.
class Reader {
public:
    explicit Reader(std::span<const std::uint8_t> b) : b_(b) {}
    template <typename T>
    bool get(T& v, const char* what) {
        if (!need(sizeof(T), what)) {
            return false;
        }
        std::memcpy(&v, b_.data() + pos_, sizeof(T));
        pos_ += sizeof(T);
        return true;
    }
    bool getString(std::string& s, const char* what) {
        std::uint16_t n = 0;
        if (!get(n, what) || !need(n, what)) {
            return false;
        }
        s.assign(reinterpret_cast<const char*>(b_.data() + pos_), n);
        pos_ += n;
        return true;
    }
    bool need(std::size_t n, const char* what) {
        if (b_.size() - pos_ < n) {
            if (error_.empty()) {
                error_ = fmt::format("payload offset {}: truncated while reading {}", pos_, what);
            }
            return false;
        }
        return true;
    }
    std::size_t offset() const { return pos_; }
    const std::string& error() const { return error_; }

private:
    std::span<const std::uint8_t> b_;
    std::size_t pos_ = 0;
    std::string error_;
};

std::int16_t toSnorm16(float v) {
    return static_cast<std::int16_t>(std::lround(std::clamp(v, -1.0f, 1.0f) * 32767.0f));
}

// Quantises four weights to bytes summing to exactly 255: the largest takes the rounding.
std::array<std::uint8_t, 4> quantiseWeights(const std::array<float, 4>& w) {
    std::array<std::uint8_t, 4> q{};
    int sum = 0;
    int largest = 0;
    for (int i = 0; i < 4; ++i) {
        const long v = std::lround(std::clamp(w[i], 0.0f, 1.0f) * 255.0f);
        q[i] = static_cast<std::uint8_t>(v);
        sum += q[i];
        if (w[i] > w[largest]) {
            largest = i;
        }
    }
    q[largest] = static_cast<std::uint8_t>(std::clamp(q[largest] + 255 - sum, 0, 255));
    return q;
}

}  // namespace

std::string_view toString(GroupMethod m) {
    switch (m) {
        case GroupMethod::Rigid:
            return "rigid";
        case GroupMethod::Lbs:
            return "lbs";
        case GroupMethod::Dqs:
            return "dqs";
    }
    return "?";
}

int Skin::findGroup(std::string_view name) const {
    for (std::size_t i = 0; i < groups.size(); ++i) {
        if (groups[i].name == name) {
            return static_cast<int>(i);
        }
    }
    return -1;
}

Result<void> validate(const Skin& skin) {
    const std::size_t n = skin.positions.size();
    if (skin.normals.size() != n || skin.joints.size() != n || skin.weights.size() != n) {
        return Error{EINVAL,
                     fmt::format("skin: {} positions but {} normals, {} joint sets, {} "
                                 "weight sets: expected one of each per vertex",
                                 n, skin.normals.size(), skin.joints.size(), skin.weights.size())};
    }
    for (std::size_t t = 0; t < skin.triangles.size(); ++t) {
        for (auto v : skin.triangles[t]) {
            if (v >= n) {
                return Error{EINVAL, fmt::format("skin: triangle {} uses vertex {}: expected an "
                                                 "index below {}",
                                                 t, v, n)};
            }
        }
    }
    for (std::size_t v = 0; v < n; ++v) {
        float sum = 0;
        for (int k = 0; k < kMaxInfluences; ++k) {
            const float w = skin.weights[v][k];
            if (!std::isfinite(w) || w < 0) {
                return Error{EINVAL, fmt::format("skin: vertex {} weight {} is {}: expected a "
                                                 "finite value >= 0",
                                                 v, k, w)};
            }
            if (skin.joints[v][k] >= kSegmentCount) {
                return Error{EINVAL, fmt::format("skin: vertex {} joint {} is {}: expected a "
                                                 "segment index below {}",
                                                 v, k, skin.joints[v][k], kSegmentCount)};
            }
            sum += w;
        }
        // 1e-3: the file stores weights in 1/255 steps but renormalises them on load.
        if (std::fabs(sum - 1.0f) > 1e-3f) {
            return Error{EINVAL,
                         fmt::format("skin: vertex {} weights sum to {}: expected 1", v, sum)};
        }
        for (float c : skin.positions[v]) {
            if (!std::isfinite(c)) {
                return Error{EINVAL, fmt::format("skin: vertex {} position is not finite", v)};
            }
        }
    }
    std::uint32_t next = 0;
    for (const auto& g : skin.groups) {
        if (g.firstVertex != next) {
            return Error{EINVAL, fmt::format("skin: group '{}' starts at vertex {}: expected {} "
                                             "(groups cover the vertices in order)",
                                             g.name, g.firstVertex, next)};
        }
        if (g.segment < 0 || g.segment >= kSegmentCount) {
            return Error{EINVAL, fmt::format("skin: group '{}' segment {}: expected 0 to {}",
                                             g.name, g.segment, kSegmentCount - 1)};
        }
        next = g.firstVertex + g.vertexCount;
        if (next > n) {
            return Error{EINVAL, fmt::format("skin: group '{}' ends at vertex {}: the skin has {}",
                                             g.name, next, n)};
        }
        if (g.method == GroupMethod::Rigid) {
            for (std::uint32_t v = g.firstVertex; v < next; ++v) {
                if (skin.joints[v][0] != g.segment || skin.weights[v][0] != 1.0f) {
                    return Error{EINVAL,
                                 fmt::format("skin: vertex {} of rigid group '{}': expected "
                                             "weight 1 on segment {}",
                                             v, g.name, board::kSegments[g.segment].name)};
                }
            }
        }
    }
    if (next != n) {
        return Error{EINVAL, fmt::format("skin: groups cover {} of {} vertices", next, n)};
    }
    return {};
}

void renormaliseWeights(Skin& skin, int fallbackSegment) {
    for (std::size_t v = 0; v < skin.weights.size(); ++v) {
        auto& w = skin.weights[v];
        float sum = 0;
        for (float& x : w) {
            if (!std::isfinite(x) || x < 0) {
                x = 0;
            }
            sum += x;
        }
        if (sum > 0) {
            for (float& x : w) {
                x /= sum;
            }
        } else {
            w = {1, 0, 0, 0};
            skin.joints[v] = {static_cast<std::uint8_t>(fallbackSegment), 0, 0, 0};
        }
    }
}

std::vector<std::uint8_t> encodeSkin(const Skin& skin) {
    Writer p;
    const auto nv = static_cast<std::uint32_t>(skin.positions.size());
    const auto nt = static_cast<std::uint32_t>(skin.triangles.size());
    p.put(nv);
    p.put(nt);
    p.put(static_cast<std::uint16_t>(skin.groups.size()));
    p.put(static_cast<std::uint16_t>(kSegmentCount));
    p.putString(skin.provenance);
    for (const auto& o : skin.jointOriginsM) {
        for (float c : o) {
            p.put(c);
        }
    }
    for (const auto& g : skin.groups) {
        p.put(static_cast<std::uint8_t>(g.method));
        p.put(static_cast<std::uint8_t>(g.segment));
        p.putString(g.name);
        p.put(g.firstVertex);
        p.put(g.vertexCount);
    }
    for (const auto& v : skin.positions) {
        for (float c : v) {
            p.put(c);
        }
    }
    for (const auto& nrm : skin.normals) {
        for (float c : nrm) {
            p.put(toSnorm16(c));
        }
    }
    for (const auto& j : skin.joints) {
        for (auto c : j) {
            p.put(c);
        }
    }
    for (const auto& w : skin.weights) {
        for (auto c : quantiseWeights(w)) {
            p.put(c);
        }
    }
    const bool small = nv <= 65535;
    for (const auto& t : skin.triangles) {
        for (auto v : t) {
            if (small) {
                p.put(static_cast<std::uint16_t>(v));
            } else {
                p.put(v);
            }
        }
    }

    const auto& payload = p.bytes();
    uLongf packedSize = compressBound(static_cast<uLong>(payload.size()));
    std::vector<std::uint8_t> packed(packedSize);
    compress2(packed.data(), &packedSize, payload.data(), static_cast<uLong>(payload.size()),
              Z_BEST_COMPRESSION);
    packed.resize(packedSize);

    Writer out;
    for (char c : kMagic) {
        out.put(c);
    }
    out.put(kFormatVersion);
    out.put(static_cast<std::uint32_t>(payload.size()));
    out.put(static_cast<std::uint32_t>(packed.size()));
    out.bytes().insert(out.bytes().end(), packed.begin(), packed.end());
    return std::move(out.bytes());
}

Result<Skin> decodeSkin(std::span<const std::uint8_t> bytes, std::string_view sourceName) {
    auto fail = [&](const std::string& what) {
        return Error{EINVAL, fmt::format("{}: {}", sourceName, what)};
    };
    constexpr std::size_t kHeader = 8 + 4 + 4 + 4;
    if (bytes.size() < kHeader || std::memcmp(bytes.data(), kMagic, 8) != 0) {
        return fail("not a caphub mesh: expected the 'CAPHUBSK' header");
    }
    std::uint32_t version = 0, payloadSize = 0, packedSize = 0;
    std::memcpy(&version, bytes.data() + 8, 4);
    std::memcpy(&payloadSize, bytes.data() + 12, 4);
    std::memcpy(&packedSize, bytes.data() + 16, 4);
    if (version != kFormatVersion) {
        return fail(fmt::format("format version {}: expected {}", version, kFormatVersion));
    }
    if (payloadSize > kMaxPayloadBytes || packedSize != bytes.size() - kHeader) {
        return fail(
            fmt::format("payload of {} bytes packed in {} (file holds {}): expected at "
                        "most {} bytes, packed in the rest of the file",
                        payloadSize, packedSize, bytes.size() - kHeader, kMaxPayloadBytes));
    }
    std::vector<std::uint8_t> payload(payloadSize);
    uLongf outSize = payloadSize;
    if (uncompress(payload.data(), &outSize, bytes.data() + kHeader, packedSize) != Z_OK ||
        outSize != payloadSize) {
        return fail("corrupt compressed payload");
    }

    Reader r(payload);
    Skin s;
    std::uint32_t nv = 0, nt = 0;
    std::uint16_t ng = 0, nseg = 0;
    if (!r.get(nv, "vertex count") || !r.get(nt, "triangle count") || !r.get(ng, "group count") ||
        !r.get(nseg, "segment count")) {
        return fail(r.error());
    }
    if (nv > kMaxVertices || nt > kMaxTriangles || nseg != kSegmentCount) {
        return fail(
            fmt::format("{} vertices, {} triangles, {} segments: expected at most {}, "
                        "at most {}, exactly {}",
                        nv, nt, nseg, kMaxVertices, kMaxTriangles, kSegmentCount));
    }
    if (!r.getString(s.provenance, "provenance")) {
        return fail(r.error());
    }
    for (auto& o : s.jointOriginsM) {
        for (float& c : o) {
            if (!r.get(c, "joint origins")) {
                return fail(r.error());
            }
        }
    }
    s.groups.resize(ng);
    for (auto& g : s.groups) {
        std::uint8_t method = 0, segment = 0;
        if (!r.get(method, "group method") || !r.get(segment, "group segment") ||
            !r.getString(g.name, "group name") || !r.get(g.firstVertex, "group first vertex") ||
            !r.get(g.vertexCount, "group vertex count")) {
            return fail(r.error());
        }
        if (method > static_cast<std::uint8_t>(GroupMethod::Dqs)) {
            return fail(fmt::format("group '{}' method {}: expected 0 (rigid), 1 (lbs) or 2 (dqs)",
                                    g.name, method));
        }
        g.method = static_cast<GroupMethod>(method);
        g.segment = segment;
    }
    const bool small = nv <= 65535;
    const std::size_t need =
        std::size_t{nv} * (12 + 6 + 4 + 4) + std::size_t{nt} * 3 * (small ? 2 : 4);
    if (!r.need(need, "vertex and triangle arrays")) {
        return fail(r.error());
    }
    s.positions.resize(nv);
    s.normals.resize(nv);
    s.joints.resize(nv);
    s.weights.resize(nv);
    s.triangles.resize(nt);
    for (auto& v : s.positions) {
        for (float& c : v) {
            (void)r.get(c, "positions");
        }
    }
    for (auto& n : s.normals) {
        for (float& c : n) {
            std::int16_t q = 0;
            (void)r.get(q, "normals");
            c = static_cast<float>(q) / 32767.0f;
        }
    }
    for (auto& j : s.joints) {
        for (auto& c : j) {
            (void)r.get(c, "joints");
        }
    }
    for (auto& w : s.weights) {
        for (float& c : w) {
            std::uint8_t q = 0;
            (void)r.get(q, "weights");
            c = static_cast<float>(q) / 255.0f;
        }
    }
    for (auto& t : s.triangles) {
        for (auto& v : t) {
            if (small) {
                std::uint16_t q = 0;
                (void)r.get(q, "triangles");
                v = q;
            } else {
                (void)r.get(v, "triangles");
            }
        }
    }
    if (r.offset() != payload.size()) {
        return fail(fmt::format("{} bytes after the triangles: expected the payload to end",
                                payload.size() - r.offset()));
    }
    // 1/255 steps do not sum to exactly 1 in float.
    renormaliseWeights(s, 0);
    if (auto ok = validate(s); !ok) {
        return fail(ok.error().message);
    }
    return s;
}

Result<void> saveSkin(const Skin& skin, const std::filesystem::path& path) {
    const auto bytes = encodeSkin(skin);
    std::ofstream f(path, std::ios::binary);
    if (!f || !f.write(reinterpret_cast<const char*>(bytes.data()),
                       static_cast<std::streamsize>(bytes.size()))) {
        return errnoError(-errno, fmt::format("write '{}'", path.string()));
    }
    return {};
}

Result<Skin> loadSkin(const std::filesystem::path& path) {
    std::ifstream f(path, std::ios::binary);
    if (!f) {
        return errnoError(-errno, fmt::format("open '{}'", path.string()));
    }
    std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(f)),
                                    std::istreambuf_iterator<char>());
    return decodeSkin(bytes, path.string());
}

std::filesystem::path defaultSkinPath() {
    const std::filesystem::path installed =
        std::filesystem::path(CAPHUB_INSTALL_DATA_DIR) / "mesh" / "caphub-default.mesh";
    const std::filesystem::path source =
        std::filesystem::path(CAPHUB_SOURCE_DATA_DIR) / "render" / "data" / "caphub-default.mesh";
    std::error_code ec;
    return std::filesystem::exists(source, ec) ? source : installed;
}

Result<Skin> loadDefaultSkin() {
    return loadSkin(defaultSkinPath());
}

Skin groupBySegment(const Skin& skin, float rigidWeight) {
    using S = board::Segment;
    struct GroupDef {
        const char* name;
        GroupMethod method;
        S segment;
    };
    static constexpr std::array<GroupDef, 14> kDefs = {{
        {"head", GroupMethod::Rigid, S::Skull},
        {"l_hand", GroupMethod::Rigid, S::LHand},
        {"r_hand", GroupMethod::Rigid, S::RHand},
        {"l_foot", GroupMethod::Rigid, S::LHindfoot},
        {"r_foot", GroupMethod::Rigid, S::RHindfoot},
        {"l_toes", GroupMethod::Rigid, S::LMiddistal},
        {"r_toes", GroupMethod::Rigid, S::RMiddistal},
        {"torso", GroupMethod::Lbs, S::T12},
        {"l_upperarm", GroupMethod::Lbs, S::LUpperarm},
        {"r_upperarm", GroupMethod::Lbs, S::RUpperarm},
        {"l_forearm", GroupMethod::Dqs, S::LForearm},
        {"r_forearm", GroupMethod::Dqs, S::RForearm},
        {"l_leg", GroupMethod::Lbs, S::LThigh},
        {"r_leg", GroupMethod::Lbs, S::RThigh},
    }};
    constexpr std::size_t kRigidCount = 7;
    const std::size_t n = skin.vertexCount();
    auto dominant = [&](std::size_t v) {
        int best = 0;
        for (int k = 1; k < kMaxInfluences; ++k) {
            if (skin.weights[v][k] > skin.weights[v][best]) {
                best = k;
            }
        }
        return best;
    };
    auto groupOf = [&](std::size_t v) -> std::size_t {
        const int k = dominant(v);
        const auto s = static_cast<S>(skin.joints[v][k]);
        if (skin.weights[v][k] >= rigidWeight) {
            for (std::size_t g = 0; g < kRigidCount; ++g) {
                if (kDefs[g].segment == s) {
                    return g;
                }
            }
        }
        switch (s) {
            case S::LUpperarm:
                return 8;
            case S::RUpperarm:
                return 9;
            case S::LForearm:
            case S::LHand:
                return 10;
            case S::RForearm:
            case S::RHand:
                return 11;
            case S::LThigh:
            case S::LCalf:
            case S::LHindfoot:
            case S::LMiddistal:
                return 12;
            case S::RThigh:
            case S::RCalf:
            case S::RHindfoot:
            case S::RMiddistal:
                return 13;
            default:
                return 7;
        }
    };
    std::vector<std::size_t> group(n);
    std::vector<std::uint32_t> order(n);
    for (std::size_t i = 0; i < n; ++i) {
        group[i] = groupOf(i);
        order[i] = static_cast<std::uint32_t>(i);
    }
    std::stable_sort(order.begin(), order.end(),
                     [&](std::uint32_t a, std::uint32_t b) { return group[a] < group[b]; });
    Skin out;
    out.jointOriginsM = skin.jointOriginsM;
    out.provenance = skin.provenance;
    std::vector<std::uint32_t> where(n);
    for (std::size_t k = 0; k < n; ++k) {
        const auto i = order[k];
        where[i] = static_cast<std::uint32_t>(k);
        out.positions.push_back(skin.positions[i]);
        out.normals.push_back(skin.normals[i]);
        if (group[i] < kRigidCount) {
            out.joints.push_back({skin.joints[i][static_cast<std::size_t>(dominant(i))], 0, 0, 0});
            out.weights.push_back({1, 0, 0, 0});
        } else {
            out.joints.push_back(skin.joints[i]);
            out.weights.push_back(skin.weights[i]);
        }
    }
    for (const auto& t : skin.triangles) {
        out.triangles.push_back({where[t[0]], where[t[1]], where[t[2]]});
    }
    std::uint32_t first = 0;
    for (std::size_t g = 0; g < kDefs.size(); ++g) {
        const auto count = static_cast<std::uint32_t>(std::count(group.begin(), group.end(), g));
        out.groups.push_back(PolygonGroup{kDefs[g].name, kDefs[g].method,
                                          static_cast<int>(kDefs[g].segment), first, count});
        first += count;
    }
    return out;
}

std::array<std::vector<int>, kSegmentCount> trianglesBySegment(const Skin& skin) {
    std::array<std::vector<int>, kSegmentCount> out;
    for (std::size_t t = 0; t < skin.triangles.size(); ++t) {
        const auto v = skin.triangles[t][0];
        int best = 0;
        for (int k = 1; k < kMaxInfluences; ++k) {
            if (skin.weights[v][k] > skin.weights[v][best]) {
                best = k;
            }
        }
        out[skin.joints[v][best]].push_back(static_cast<int>(t));
    }
    return out;
}

}  // namespace caphub::render
