// caphub-build-skin: builds caphub's default skin (render/data/caphub-default.mesh) from the CC0
// MakeHuman assets: the hm08 base mesh's body, the default rig's joints and weights mapped onto
// caphub's 21 segments, posed from MakeHuman's A-pose into caphub's T-pose (docs/render.md).
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "fusion/body/skeleton.h"
#include "render/skin.h"
#include "render/skinning.h"

namespace {

using caphub::Error;
using caphub::Quatd;
using caphub::Result;
using caphub::Vec3d;
using caphub::board::Segment;
using caphub::render::GroupMethod;
using caphub::render::Skin;
namespace fs = std::filesystem;

constexpr int kSegs = caphub::render::kSegmentCount;
constexpr double kMakeHumanUnitM = 0.1;  // hm08 is modelled in decimetres

int seg(Segment s) {
    return static_cast<int>(s);
}

struct Obj {
    std::vector<Vec3d> vertices;          // every vertex of the file (joints index them all)
    std::vector<std::vector<int>> faces;  // faces of the "body" group, 0-based
};

Result<Obj> readObj(const fs::path& path) {
    std::ifstream f(path);
    if (!f) {
        return Error{ENOENT, fmt::format("{}: cannot open", path.string())};
    }
    Obj obj;
    std::string line, group;
    int lineNo = 0;
    while (std::getline(f, line)) {
        ++lineNo;
        std::istringstream in(line);
        std::string tag;
        in >> tag;
        if (tag == "v") {
            Vec3d v;
            if (!(in >> v.x() >> v.y() >> v.z())) {
                return Error{EINVAL,
                             fmt::format("{}:{}: expected 'v x y z'", path.string(), lineNo)};
            }
            obj.vertices.push_back(v);
        } else if (tag == "g") {
            in >> group;
        } else if (tag == "f" && group == "body") {
            std::vector<int> face;
            std::string corner;
            while (in >> corner) {
                const int v = std::atoi(corner.c_str());
                if (v <= 0 || v > static_cast<int>(obj.vertices.size())) {
                    return Error{EINVAL,
                                 fmt::format("{}:{}: face vertex '{}': expected 1 to {}",
                                             path.string(), lineNo, corner, obj.vertices.size())};
                }
                face.push_back(v - 1);
            }
            if (face.size() < 3) {
                return Error{EINVAL, fmt::format("{}:{}: expected a face of at least 3 corners",
                                                 path.string(), lineNo)};
            }
            obj.faces.push_back(std::move(face));
        }
    }
    if (obj.faces.empty()) {
        return Error{EINVAL, fmt::format("{}: expected faces in a 'g body' group", path.string())};
    }
    return obj;
}

Result<nlohmann::json> readJson(const fs::path& path) {
    std::ifstream f(path);
    if (!f) {
        return Error{ENOENT, fmt::format("{}: cannot open", path.string())};
    }
    try {
        return nlohmann::json::parse(f);
    } catch (const nlohmann::json::exception& e) {
        return Error{EINVAL, fmt::format("{}: {}", path.string(), e.what())};
    }
}

// Which caphub segment each MakeHuman bone belongs to: the bone's own entry here, or its nearest
// ancestor's (facial bones follow "head", fingers "wrist", toes "toe*-1").
Segment segmentOfBone(const std::string& bone, const nlohmann::json& bones) {
    static const std::map<std::string, Segment> kMap = {
        {"root", Segment::Pelvis},
        {"pelvis.L", Segment::Pelvis},
        {"pelvis.R", Segment::Pelvis},
        {"spine05", Segment::Pelvis},
        {"spine04", Segment::L5},
        {"spine03", Segment::L5},
        {"spine02", Segment::T12},
        {"spine01", Segment::T12},
        {"neck01", Segment::C7},
        {"neck02", Segment::C7},
        {"neck03", Segment::C7},
        {"head", Segment::Skull},
        {"clavicle.L", Segment::LClavicle},
        {"shoulder01.L", Segment::LClavicle},
        {"upperarm01.L", Segment::LUpperarm},
        {"upperarm02.L", Segment::LUpperarm},
        {"lowerarm01.L", Segment::LForearm},
        {"lowerarm02.L", Segment::LForearm},
        {"wrist.L", Segment::LHand},
        {"clavicle.R", Segment::RClavicle},
        {"shoulder01.R", Segment::RClavicle},
        {"upperarm01.R", Segment::RUpperarm},
        {"upperarm02.R", Segment::RUpperarm},
        {"lowerarm01.R", Segment::RForearm},
        {"lowerarm02.R", Segment::RForearm},
        {"wrist.R", Segment::RHand},
        {"upperleg01.L", Segment::LThigh},
        {"upperleg02.L", Segment::LThigh},
        {"lowerleg01.L", Segment::LCalf},
        {"lowerleg02.L", Segment::LCalf},
        {"foot.L", Segment::LHindfoot},
        {"upperleg01.R", Segment::RThigh},
        {"upperleg02.R", Segment::RThigh},
        {"lowerleg01.R", Segment::RCalf},
        {"lowerleg02.R", Segment::RCalf},
        {"foot.R", Segment::RHindfoot},
    };
    std::string b = bone;
    for (int depth = 0; depth < 32; ++depth) {
        if (auto it = kMap.find(b); it != kMap.end()) {
            return it->second;
        }
        if (b.rfind("toe", 0) == 0) {
            return b.back() == 'L' ? Segment::LMiddistal : Segment::RMiddistal;
        }
        if (!bones.contains(b)) {
            break;
        }
        const auto& parent = bones[b]["parent"];
        if (parent.is_null()) {
            break;
        }
        b = parent.get<std::string>();
    }
    return Segment::Pelvis;
}

// The rotation taking unit direction `from` to `to` about their common normal.
Quatd align(const Vec3d& from, const Vec3d& to) {
    return Quatd::FromTwoVectors(from.normalized(), to.normalized());
}

// The rotation taking the frame (primary a, secondary b) onto (A, B): a -> A exactly, b -> B as
// nearly as the first allows.
Quatd alignFrame(const Vec3d& a, const Vec3d& b, const Vec3d& aTo, const Vec3d& bTo) {
    auto frame = [](const Vec3d& p, const Vec3d& s) {
        Eigen::Matrix3d m;
        const Vec3d x = p.normalized();
        const Vec3d z = x.cross(s).normalized();
        m.col(0) = x;
        m.col(1) = z.cross(x);
        m.col(2) = z;
        return m;
    };
    const Eigen::Matrix3d r = frame(aTo, bTo) * frame(a, b).transpose();
    return Quatd(r).normalized();
}

int run(const fs::path& assets, const fs::path& outPath) {
    auto obj = readObj(assets / "base_hm08.obj");
    auto skel = readJson(assets / "default.mhskel");
    auto weightsJson = readJson(assets / "default_weights.mhw");
    for (const Error* e : {obj ? nullptr : &obj.error(), skel ? nullptr : &skel.error(),
                           weightsJson ? nullptr : &weightsJson.error()}) {
        if (e) {
            std::fprintf(stderr, "caphub-build-skin: %s\n", e->message.c_str());
            return 1;
        }
    }
    const auto& bones = (*skel)["bones"];
    const auto& jointsJson = (*skel)["joints"];
    auto jointPos = [&](const std::string& bone) {
        const auto& list = jointsJson[bone + "____head"];
        Vec3d sum = Vec3d::Zero();
        for (int v : list) {
            sum += obj->vertices[static_cast<std::size_t>(v)];
        }
        return Vec3d(sum / static_cast<double>(list.size()));
    };

    // The body's vertices, renumbered densely.
    std::vector<int> newIndex(obj->vertices.size(), -1);
    std::vector<int> used;
    for (const auto& f : obj->faces) {
        for (int v : f) {
            if (newIndex[static_cast<std::size_t>(v)] < 0) {
                newIndex[static_cast<std::size_t>(v)] = static_cast<int>(used.size());
                used.push_back(v);
            }
        }
    }
    const std::size_t n = used.size();

    // Weights per caphub segment: the sum over the MakeHuman bones mapped to it.
    std::vector<std::array<float, kSegs>> segW(n, std::array<float, kSegs>{});
    for (const auto& [bone, list] : (*weightsJson)["weights"].items()) {
        const int s = seg(segmentOfBone(bone, bones));
        for (const auto& pair : list) {
            const int v = pair[0].get<int>();
            if (v < 0 || v >= static_cast<int>(newIndex.size()) ||
                newIndex[static_cast<std::size_t>(v)] < 0) {
                continue;  // helper geometry
            }
            segW[static_cast<std::size_t>(newIndex[static_cast<std::size_t>(v)])]
                [static_cast<std::size_t>(s)] += pair[1].get<float>();
        }
    }

    // caphub's segment origins in MakeHuman's rest pose.
    std::array<Vec3d, kSegs> origin;
    auto setO = [&](Segment s, Vec3d p) { origin[static_cast<std::size_t>(seg(s))] = p; };
    setO(Segment::Pelvis, 0.5 * (jointPos("upperleg01.L") + jointPos("upperleg01.R")));
    setO(Segment::L5, jointPos("spine04"));
    setO(Segment::T12, jointPos("spine02"));
    setO(Segment::C7, jointPos("neck01"));
    setO(Segment::Skull, jointPos("head"));
    for (const char* side : {"L", "R"}) {
        const bool left = side[0] == 'L';
        auto j = [&](const char* b) { return jointPos(fmt::format("{}.{}", b, side)); };
        setO(left ? Segment::LClavicle : Segment::RClavicle, j("clavicle"));
        setO(left ? Segment::LUpperarm : Segment::RUpperarm, j("upperarm01"));
        setO(left ? Segment::LForearm : Segment::RForearm, j("lowerarm01"));
        setO(left ? Segment::LHand : Segment::RHand, j("wrist"));
        setO(left ? Segment::LThigh : Segment::RThigh, j("upperleg01"));
        setO(left ? Segment::LCalf : Segment::RCalf, j("lowerleg01"));
        setO(left ? Segment::LHindfoot : Segment::RHindfoot, j("foot"));
        setO(left ? Segment::LMiddistal : Segment::RMiddistal, j("toe3-1"));
    }

    // The pose taking MakeHuman's A-pose to caphub's T-pose: arms straight out along +-X with
    // the palms down, legs straight down; the trunk, head and feet keep their rest orientation.
    caphub::render::SkinPose toTPose;
    for (const char* side : {"L", "R"}) {
        const bool left = side[0] == 'L';
        const double sx = left ? 1.0 : -1.0;
        auto j = [&](const char* b) { return jointPos(fmt::format("{}.{}", b, side)); };
        auto q = [&](Segment s) -> Quatd& {
            return toTPose.qWorld[static_cast<std::size_t>(seg(s))];
        };
        q(left ? Segment::LUpperarm : Segment::RUpperarm) =
            align(j("lowerarm01") - j("upperarm01"), Vec3d(sx, 0, 0));
        q(left ? Segment::LForearm : Segment::RForearm) =
            align(j("wrist") - j("lowerarm01"), Vec3d(sx, 0, 0));
        // Palm normal from the wrist and the index and little finger bases (points out of the
        // palm for the left hand with this order, into it for the right).
        const Vec3d palm = (j("finger2-1") - j("wrist")).cross(j("finger5-1") - j("wrist")) * sx;
        q(left ? Segment::LHand : Segment::RHand) =
            alignFrame(j("finger3-1") - j("wrist"), palm, Vec3d(sx, 0, 0), Vec3d(0, -1, 0));
        q(left ? Segment::LThigh : Segment::RThigh) =
            align(j("lowerleg01") - j("upperleg01"), Vec3d(0, -1, 0));
        q(left ? Segment::LCalf : Segment::RCalf) =
            align(j("foot") - j("lowerleg01"), Vec3d(0, -1, 0));
    }

    // Keep the four largest segment weights per vertex.
    Skin skin;
    skin.positions.resize(n);
    skin.normals.assign(n, {0, 1, 0});
    skin.joints.resize(n);
    skin.weights.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
        const Vec3d& p = obj->vertices[static_cast<std::size_t>(used[i])];
        skin.positions[i] = {static_cast<float>(p.x()), static_cast<float>(p.y()),
                             static_cast<float>(p.z())};
        std::array<int, kSegs> order{};
        for (int s = 0; s < kSegs; ++s) {
            order[static_cast<std::size_t>(s)] = s;
        }
        const auto& w = segW[i];
        std::partial_sort(order.begin(), order.begin() + 4, order.end(), [&](int a, int b) {
            return w[static_cast<std::size_t>(a)] > w[static_cast<std::size_t>(b)];
        });
        for (int k = 0; k < 4; ++k) {
            skin.joints[i][static_cast<std::size_t>(k)] =
                static_cast<std::uint8_t>(order[static_cast<std::size_t>(k)]);
            skin.weights[i][static_cast<std::size_t>(k)] =
                w[static_cast<std::size_t>(order[static_cast<std::size_t>(k)])];
        }
    }
    caphub::render::renormaliseWeights(skin, seg(Segment::Pelvis));
    for (int s = 0; s < kSegs; ++s) {
        const auto& o = origin[static_cast<std::size_t>(s)];
        skin.jointOriginsM[static_cast<std::size_t>(s)] = {
            static_cast<float>(o.x()), static_cast<float>(o.y()), static_cast<float>(o.z())};
    }

    // Pose into the T-pose with dual quaternions (no collapse at the shoulders and elbows).
    skin.groups = {{"all", GroupMethod::Dqs, 0, 0, static_cast<std::uint32_t>(n)}};
    caphub::render::Skinner poser(skin);
    toTPose.pelvisM = origin[0];
    poser.setPose(toTPose);
    poser.skin();
    for (std::size_t i = 0; i < n; ++i) {
        const auto& p = poser.output()[i].position;
        skin.positions[i] = {p[0], p[1], p[2]};
    }
    for (int s = 0; s < kSegs; ++s) {
        const Vec3d& p = poser.jointPositionsM()[static_cast<std::size_t>(s)];
        skin.jointOriginsM[static_cast<std::size_t>(s)] = {
            static_cast<float>(p.x()), static_cast<float>(p.y()), static_cast<float>(p.z())};
    }

    // Metres, feet on the floor (y = 0), the pelvis origin above the world origin.
    float minY = 1e9f;
    for (const auto& p : skin.positions) {
        minY = std::min(minY, p[1]);
    }
    const auto pelvis = skin.jointOriginsM[0];
    auto toMetres = [&](std::array<float, 3>& p) {
        p = {(p[0] - pelvis[0]) * static_cast<float>(kMakeHumanUnitM),
             (p[1] - minY) * static_cast<float>(kMakeHumanUnitM),
             (p[2] - pelvis[2]) * static_cast<float>(kMakeHumanUnitM)};
    };
    for (auto& p : skin.positions) {
        toMetres(p);
    }
    for (auto& p : skin.jointOriginsM) {
        toMetres(p);
    }

    // Triangles (quads split on their first diagonal) and area-weighted vertex normals.
    std::vector<Vec3d> normals(n, Vec3d::Zero());
    auto pos = [&](std::uint32_t v) {
        const auto& p = skin.positions[v];
        return Vec3d(p[0], p[1], p[2]);
    };
    for (const auto& f : obj->faces) {
        for (std::size_t k = 1; k + 1 < f.size(); ++k) {
            std::array<std::uint32_t, 3> t = {
                static_cast<std::uint32_t>(newIndex[static_cast<std::size_t>(f[0])]),
                static_cast<std::uint32_t>(newIndex[static_cast<std::size_t>(f[k])]),
                static_cast<std::uint32_t>(newIndex[static_cast<std::size_t>(f[k + 1])])};
            const Vec3d nrm = (pos(t[1]) - pos(t[0])).cross(pos(t[2]) - pos(t[0]));
            for (auto v : t) {
                normals[v] += nrm;
            }
            skin.triangles.push_back(t);
        }
    }
    for (std::size_t i = 0; i < n; ++i) {
        const Vec3d nn = normals[i].norm() > 0 ? normals[i].normalized() : Vec3d::UnitY();
        skin.normals[i] = {static_cast<float>(nn.x()), static_cast<float>(nn.y()),
                           static_cast<float>(nn.z())};
    }

    // Polygon groups (docs/render.md): 0.97 keeps the wrists, ankles and neck blended while
    // the hands, feet and head proper move rigidly.
    Skin sorted = caphub::render::groupBySegment(skin, 0.97f);
    sorted.provenance =
        "MakeHuman hm08 base mesh (body), default rig and weights, CC0; caphub-build-skin";

    if (auto ok = caphub::render::validate(sorted); !ok) {
        std::fprintf(stderr, "caphub-build-skin: %s\n", ok.error().message.c_str());
        return 1;
    }
    if (auto ok = caphub::render::saveSkin(sorted, outPath); !ok) {
        std::fprintf(stderr, "caphub-build-skin: %s\n", ok.error().message.c_str());
        return 1;
    }
    float maxY = 0;
    for (const auto& p : sorted.positions) {
        maxY = std::max(maxY, p[1]);
    }
    std::printf("%s: %zu vertices, %zu triangles, height %.3f m, %ju bytes\n",
                outPath.string().c_str(), n, sorted.triangles.size(), static_cast<double>(maxY),
                static_cast<std::uintmax_t>(fs::file_size(outPath)));
    for (const auto& g : sorted.groups) {
        std::printf("  group %-11s %-5s %5u vertices\n", g.name.c_str(),
                    std::string(caphub::render::toString(g.method)).c_str(), g.vertexCount);
    }
    return 0;
}

}  // namespace

int main(int argc, char** argv) {
    CLI::App app{"Build caphub's default skin from the MakeHuman assets"};
    std::string assets = "../shared/data/meshes/makehuman";
    std::string out = "render/data/caphub-default.mesh";
    app.add_option("--assets", assets,
                   "folder with base_hm08.obj, default.mhskel, "
                   "default_weights.mhw")
        ->capture_default_str();
    app.add_option("-o,--output", out, "the .mesh file to write")->capture_default_str();
    CLI11_PARSE(app, argc, argv);
    return run(assets, out);
}
