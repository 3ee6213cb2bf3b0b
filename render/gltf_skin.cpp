#include "render/gltf_skin.h"

#include <algorithm>
#include <cctype>
#include <cstring>
#include <map>
#include <sstream>

#include <Eigen/Geometry>
#include <fmt/format.h>
#include <tiny_gltf.h>

#include "fusion/body/skeleton.h"

namespace caphub::render {

namespace {

using Mat4 = Eigen::Matrix4d;

Mat4 localTransform(const tinygltf::Node& n) {
    Mat4 m = Mat4::Identity();
    if (n.matrix.size() == 16) {
        for (int i = 0; i < 16; ++i) {
            m(i % 4, i / 4) = n.matrix[static_cast<std::size_t>(i)];  // column-major
        }
        return m;
    }
    Eigen::Affine3d a = Eigen::Affine3d::Identity();
    if (n.translation.size() == 3) {
        a.translate(Eigen::Vector3d(n.translation[0], n.translation[1], n.translation[2]));
    }
    if (n.rotation.size() == 4) {
        a.rotate(Eigen::Quaterniond(n.rotation[3], n.rotation[0], n.rotation[1], n.rotation[2])
                     .normalized());
    }
    if (n.scale.size() == 3) {
        a.scale(Eigen::Vector3d(n.scale[0], n.scale[1], n.scale[2]));
    }
    return a.matrix();
}

// Reads element i, component c of an accessor as a double (normalised integers scaled to 0-1).
class AccessorReader {
public:
    static Result<AccessorReader> make(const tinygltf::Model& model, int index, int components,
                                       const char* what) {
        if (index < 0 || index >= static_cast<int>(model.accessors.size())) {
            return Error{EINVAL, fmt::format("{}: accessor {} does not exist", what, index)};
        }
        const auto& acc = model.accessors[static_cast<std::size_t>(index)];
        if (tinygltf::GetNumComponentsInType(static_cast<std::uint32_t>(acc.type)) != components) {
            return Error{
                EINVAL,
                fmt::format("{}: accessor {} has {} components: expected {}", what, index,
                            tinygltf::GetNumComponentsInType(static_cast<std::uint32_t>(acc.type)),
                            components)};
        }
        if (acc.bufferView < 0 || acc.bufferView >= static_cast<int>(model.bufferViews.size())) {
            return Error{EINVAL, fmt::format("{}: accessor {} has no buffer view", what, index)};
        }
        const auto& view = model.bufferViews[static_cast<std::size_t>(acc.bufferView)];
        if (view.buffer < 0 || view.buffer >= static_cast<int>(model.buffers.size())) {
            return Error{EINVAL,
                         fmt::format("{}: buffer view {} has no buffer", what, acc.bufferView)};
        }
        const auto& buf = model.buffers[static_cast<std::size_t>(view.buffer)].data;
        AccessorReader r;
        r.componentType_ = acc.componentType;
        r.normalized_ = acc.normalized;
        r.count_ = acc.count;
        r.components_ = components;
        const int size =
            tinygltf::GetComponentSizeInBytes(static_cast<std::uint32_t>(acc.componentType));
        if (size <= 0) {
            return Error{EINVAL, fmt::format("{}: accessor {} component type {} is unknown", what,
                                             index, acc.componentType)};
        }
        r.size_ = static_cast<std::size_t>(size);
        r.stride_ =
            view.byteStride ? view.byteStride : r.size_ * static_cast<std::size_t>(components);
        const std::size_t start = view.byteOffset + acc.byteOffset;
        const std::size_t end =
            acc.count == 0 ? start : start + r.stride_ * (acc.count - 1) + r.size_ * components;
        if (end > buf.size() || end > view.byteOffset + view.byteLength) {
            return Error{EINVAL, fmt::format("{}: accessor {} reads past its buffer", what, index)};
        }
        r.data_ = buf.data() + start;
        return r;
    }
    std::size_t count() const { return count_; }
    double get(std::size_t i, int c) const {
        const std::uint8_t* p = data_ + i * stride_ + static_cast<std::size_t>(c) * size_;
        switch (componentType_) {
            case TINYGLTF_COMPONENT_TYPE_FLOAT: {
                float f;
                std::memcpy(&f, p, 4);
                return f;
            }
            case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
                return normalized_ ? p[0] / 255.0 : p[0];
            case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
                std::uint16_t v;
                std::memcpy(&v, p, 2);
                return normalized_ ? v / 65535.0 : v;
            }
            case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: {
                std::uint32_t v;
                std::memcpy(&v, p, 4);
                return v;
            }
            default:
                return 0;
        }
    }

private:
    const std::uint8_t* data_ = nullptr;
    std::size_t count_ = 0, stride_ = 0, size_ = 0;
    int components_ = 0, componentType_ = 0;
    bool normalized_ = false;
};

}  // namespace

Result<GltfJointMap> parseGltfJointMap(std::string_view text, std::string_view sourceName) {
    GltfJointMap map;
    std::istringstream in{std::string(text)};
    std::string line;
    int lineNo = 0;
    while (std::getline(in, line)) {
        ++lineNo;
        // '#' starts a comment, except "#N" (a node index).
        for (std::size_t hash = line.find('#'); hash != std::string::npos;
             hash = line.find('#', hash + 1)) {
            if (hash + 1 >= line.size() ||
                !std::isdigit(static_cast<unsigned char>(line[hash + 1]))) {
                line.resize(hash);
                break;
            }
        }
        auto trim = [](std::string s) {
            const auto b = s.find_first_not_of(" \t\r");
            const auto e = s.find_last_not_of(" \t\r");
            return b == std::string::npos ? std::string() : s.substr(b, e - b + 1);
        };
        line = trim(line);
        if (line.empty()) {
            continue;
        }
        const auto eq = line.find('=');
        if (eq == std::string::npos) {
            return Error{EINVAL,
                         fmt::format("{}:{}: expected 'joint name = segment'", sourceName, lineNo)};
        }
        const std::string name = trim(line.substr(0, eq));
        const std::string segName = trim(line.substr(eq + 1));
        const auto seg = board::findSegment(segName);
        if (name.empty() || !seg) {
            return Error{EINVAL, fmt::format("{}:{}: '{}': expected a joint name and one of "
                                             "caphub's segment names (pelvis, l5, ..., "
                                             "r_middistal)",
                                             sourceName, lineNo, line)};
        }
        map.joints.emplace_back(name, *seg);
    }
    return map;
}

Result<Skin> loadGltfSkin(const std::filesystem::path& path, const GltfJointMap& map) {
    const std::string file = path.string();
    tinygltf::Model model;
    tinygltf::TinyGLTF loader;
    std::string err, warn;
    const bool binary = path.extension() == ".glb";
    const bool ok = binary ? loader.LoadBinaryFromFile(&model, &err, &warn, file)
                           : loader.LoadASCIIFromFile(&model, &err, &warn, file);
    if (!ok) {
        return Error{EINVAL, fmt::format("{}: {}", file, err.empty() ? "not a glTF file" : err)};
    }
    auto fail = [&](const std::string& what) {
        return Error{EINVAL, fmt::format("{}: {}", file, what)};
    };

    // Node parents and rest-pose global transforms.
    const std::size_t nodeCount = model.nodes.size();
    std::vector<int> parent(nodeCount, -1);
    for (std::size_t i = 0; i < nodeCount; ++i) {
        for (int c : model.nodes[i].children) {
            if (c < 0 || static_cast<std::size_t>(c) >= nodeCount ||
                parent[static_cast<std::size_t>(c)] >= 0) {
                return fail(fmt::format("node {} child {}: expected a node with one parent", i, c));
            }
            parent[static_cast<std::size_t>(c)] = static_cast<int>(i);
        }
    }
    std::vector<Mat4> global(nodeCount);
    std::vector<int> state(nodeCount, 0);
    for (std::size_t i = 0; i < nodeCount; ++i) {
        std::vector<int> chain;
        for (int k = static_cast<int>(i); k >= 0 && state[static_cast<std::size_t>(k)] == 0;
             k = parent[static_cast<std::size_t>(k)]) {
            chain.push_back(k);
            if (chain.size() > nodeCount) {
                return fail("the node hierarchy has a cycle");
            }
        }
        for (auto it = chain.rbegin(); it != chain.rend(); ++it) {
            const auto k = static_cast<std::size_t>(*it);
            const int p = parent[k];
            global[k] = (p >= 0 ? global[static_cast<std::size_t>(p)] : Mat4::Identity()) *
                        localTransform(model.nodes[k]);
            state[k] = 1;
        }
    }

    // The first node with both a mesh and a skin.
    const tinygltf::Node* meshNode = nullptr;
    for (const auto& n : model.nodes) {
        if (n.mesh >= 0 && n.skin >= 0 && n.mesh < static_cast<int>(model.meshes.size()) &&
            n.skin < static_cast<int>(model.skins.size())) {
            meshNode = &n;
            break;
        }
    }
    if (!meshNode) {
        return fail("expected a node with a skinned mesh");
    }
    const auto& gskin = model.skins[static_cast<std::size_t>(meshNode->skin)];
    const std::size_t jointCount = gskin.joints.size();
    if (jointCount == 0) {
        return fail(fmt::format("skin {} has no joints", meshNode->skin));
    }

    // Each glTF joint's segment: its own name in the map, else its nearest mapped ancestor's.
    std::map<std::string, board::Segment> byName(map.joints.begin(), map.joints.end());
    std::vector<int> jointSegment(jointCount, -1);
    std::vector<int> nodeSegment(nodeCount, -1);
    for (std::size_t i = 0; i < nodeCount; ++i) {
        auto it = byName.find(model.nodes[i].name);
        if (it == byName.end()) {
            it = byName.find(fmt::format("#{}", i));  // unnamed nodes, by index
        }
        if (it != byName.end()) {
            nodeSegment[i] = static_cast<int>(it->second);
        }
    }
    bool anyMapped = false;
    for (std::size_t j = 0; j < jointCount; ++j) {
        int k = gskin.joints[j];
        if (k < 0 || static_cast<std::size_t>(k) >= nodeCount) {
            return fail(fmt::format("skin joint {} is node {}: no such node", j, k));
        }
        while (k >= 0 && nodeSegment[static_cast<std::size_t>(k)] < 0) {
            k = parent[static_cast<std::size_t>(k)];
        }
        jointSegment[j] = k >= 0 ? nodeSegment[static_cast<std::size_t>(k)] : 0;
        anyMapped = anyMapped || k >= 0;
    }
    if (!anyMapped) {
        return fail("none of the skin's joints is named in the joint map");
    }

    // Joint matrices of the rest pose: global(joint) * inverseBind.
    std::vector<Mat4> jointMatrix(jointCount, Mat4::Identity());
    if (gskin.inverseBindMatrices >= 0) {
        auto ibm =
            AccessorReader::make(model, gskin.inverseBindMatrices, 16, "inverseBindMatrices");
        if (!ibm) {
            return fail(ibm.error().message);
        }
        if (ibm->count() < jointCount) {
            return fail("inverseBindMatrices: fewer matrices than joints");
        }
        for (std::size_t j = 0; j < jointCount; ++j) {
            Mat4 m;
            for (int e = 0; e < 16; ++e) {
                m(e % 4, e / 4) = ibm->get(j, e);
            }
            jointMatrix[j] = global[static_cast<std::size_t>(gskin.joints[j])] * m;
        }
    } else {
        for (std::size_t j = 0; j < jointCount; ++j) {
            jointMatrix[j] = global[static_cast<std::size_t>(gskin.joints[j])];
        }
    }

    // Segment origins: the most proximal joint mapped to each segment; absent segments sit at
    // their parent's origin.
    std::array<int, kSegmentCount> originDepth;
    originDepth.fill(1 << 30);
    std::array<Eigen::Vector3d, kSegmentCount> origin;
    origin.fill(Eigen::Vector3d::Zero());
    for (std::size_t i = 0; i < nodeCount; ++i) {
        const int s = nodeSegment[i];
        if (s < 0) {
            continue;
        }
        int depth = 0;
        for (int k = parent[i]; k >= 0; k = parent[static_cast<std::size_t>(k)]) {
            ++depth;
        }
        if (depth < originDepth[static_cast<std::size_t>(s)]) {
            originDepth[static_cast<std::size_t>(s)] = depth;
            origin[static_cast<std::size_t>(s)] = global[i].block<3, 1>(0, 3);
        }
    }
    for (const auto& info : body::joints()) {
        const auto s = static_cast<std::size_t>(body::idx(info.segment));
        if (originDepth[s] == (1 << 30) && info.parent >= 0) {
            origin[s] = origin[static_cast<std::size_t>(info.parent)];
        }
    }

    Skin skin;
    const auto& mesh = model.meshes[static_cast<std::size_t>(meshNode->mesh)];
    for (std::size_t pi = 0; pi < mesh.primitives.size(); ++pi) {
        const auto& prim = mesh.primitives[pi];
        if (prim.mode != TINYGLTF_MODE_TRIANGLES && prim.mode != -1) {
            continue;  // points and lines are not skin
        }
        auto attr = [&](const char* name) {
            auto it = prim.attributes.find(name);
            return it == prim.attributes.end() ? -1 : it->second;
        };
        const std::string where = fmt::format("mesh '{}' primitive {}", mesh.name, pi);
        auto pos = AccessorReader::make(model, attr("POSITION"), 3, "POSITION");
        auto jts = AccessorReader::make(model, attr("JOINTS_0"), 4, "JOINTS_0");
        auto wts = AccessorReader::make(model, attr("WEIGHTS_0"), 4, "WEIGHTS_0");
        for (const Error* e : {pos ? nullptr : &pos.error(), jts ? nullptr : &jts.error(),
                               wts ? nullptr : &wts.error()}) {
            if (e) {
                return fail(fmt::format("{}: {}", where, e->message));
            }
        }
        const std::size_t n = pos->count();
        if (jts->count() != n || wts->count() != n) {
            return fail(
                fmt::format("{}: {} positions, {} joint sets, {} weight sets: expected "
                            "one of each per vertex",
                            where, n, jts->count(), wts->count()));
        }
        const auto base = static_cast<std::uint32_t>(skin.positions.size());
        for (std::size_t i = 0; i < n; ++i) {
            std::array<float, kSegmentCount> segW{};
            Mat4 blend = Mat4::Zero();
            double sum = 0;
            for (int k = 0; k < 4; ++k) {
                const double w = wts->get(i, k);
                const auto j = static_cast<std::size_t>(jts->get(i, k));
                if (!(w > 0)) {
                    continue;
                }
                if (j >= jointCount) {
                    return fail(fmt::format("{}: vertex {} uses joint {}: the skin has {}", where,
                                            i, j, jointCount));
                }
                segW[static_cast<std::size_t>(jointSegment[j])] += static_cast<float>(w);
                blend += w * jointMatrix[j];
                sum += w;
            }
            if (sum > 0) {
                blend /= sum;
            } else {
                blend = Mat4::Identity();
            }
            const Eigen::Vector4d p =
                blend * Eigen::Vector4d(pos->get(i, 0), pos->get(i, 1), pos->get(i, 2), 1.0);
            skin.positions.push_back(
                {static_cast<float>(p.x()), static_cast<float>(p.y()), static_cast<float>(p.z())});
            std::array<int, kSegmentCount> order{};
            for (int s = 0; s < kSegmentCount; ++s) {
                order[static_cast<std::size_t>(s)] = s;
            }
            std::partial_sort(order.begin(), order.begin() + 4, order.end(), [&](int a, int b) {
                return segW[static_cast<std::size_t>(a)] > segW[static_cast<std::size_t>(b)];
            });
            std::array<std::uint8_t, 4> jj{};
            std::array<float, 4> ww{};
            for (std::size_t k = 0; k < 4; ++k) {
                jj[k] = static_cast<std::uint8_t>(order[k]);
                ww[k] = segW[static_cast<std::size_t>(order[k])];
            }
            skin.joints.push_back(jj);
            skin.weights.push_back(ww);
        }
        if (prim.indices >= 0) {
            auto idx = AccessorReader::make(model, prim.indices, 1, "indices");
            if (!idx) {
                return fail(fmt::format("{}: {}", where, idx.error().message));
            }
            for (std::size_t t = 0; t + 2 < idx->count(); t += 3) {
                std::array<std::uint32_t, 3> tri{};
                for (int c = 0; c < 3; ++c) {
                    const double v = idx->get(t + static_cast<std::size_t>(c), 0);
                    if (v >= static_cast<double>(n)) {
                        return fail(
                            fmt::format("{}: index {} is {}: the primitive has {} "
                                        "vertices",
                                        where, t + static_cast<std::size_t>(c), v, n));
                    }
                    tri[static_cast<std::size_t>(c)] = base + static_cast<std::uint32_t>(v);
                }
                skin.triangles.push_back(tri);
            }
        } else {
            for (std::uint32_t t = 0; t + 2 < n; t += 3) {
                skin.triangles.push_back({base + t, base + t + 1, base + t + 2});
            }
        }
    }
    if (skin.positions.empty() || skin.triangles.empty()) {
        return fail("the skinned mesh has no triangles");
    }
    renormaliseWeights(skin, 0);

    // Normals from the rest-pose triangles (area weighted).
    std::vector<Eigen::Vector3d> normals(skin.positions.size(), Eigen::Vector3d::Zero());
    auto P = [&](std::uint32_t v) {
        const auto& p = skin.positions[v];
        return Eigen::Vector3d(p[0], p[1], p[2]);
    };
    for (const auto& t : skin.triangles) {
        const Eigen::Vector3d nrm = (P(t[1]) - P(t[0])).cross(P(t[2]) - P(t[0]));
        for (auto v : t) {
            normals[v] += nrm;
        }
    }
    for (const auto& nrm : normals) {
        const Eigen::Vector3d u = nrm.norm() > 0 ? nrm.normalized() : Eigen::Vector3d::UnitY();
        skin.normals.push_back(
            {static_cast<float>(u.x()), static_cast<float>(u.y()), static_cast<float>(u.z())});
    }
    for (int s = 0; s < kSegmentCount; ++s) {
        const auto& o = origin[static_cast<std::size_t>(s)];
        skin.jointOriginsM[static_cast<std::size_t>(s)] = {
            static_cast<float>(o.x()), static_cast<float>(o.y()), static_cast<float>(o.z())};
    }
    skin.provenance = fmt::format("glTF {}", path.filename().string());
    Skin grouped = groupBySegment(skin, 0.97f);
    if (auto valid = validate(grouped); !valid) {
        return fail(valid.error().message);
    }
    return grouped;
}

}  // namespace caphub::render
