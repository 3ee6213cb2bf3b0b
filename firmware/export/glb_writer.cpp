// Binary glTF 2.0 export through tinygltf's writer (docs/exports.md, "glTF").
#include <algorithm>
#include <cstring>
#include <limits>
#include <sstream>

#include <fmt/format.h>
#include <tiny_gltf.h>

#include "firmware/export/output_file.h"
#include "firmware/export/writers.h"
#include "render/skin.h"
#include "render/skin_fit.h"

namespace caphub::firmware::exporter {

namespace {

constexpr int kFloat = TINYGLTF_COMPONENT_TYPE_FLOAT;

// Builds the one binary buffer and its views and accessors.
struct Builder {
    tinygltf::Model& model;

    // Appends bytes as a new buffer view (4-byte aligned, as every accessor here needs).
    int view(const void* data, std::size_t bytes, int target) {
        auto& buf = model.buffers[0].data;
        buf.resize((buf.size() + 3) & ~std::size_t{3}, 0);
        tinygltf::BufferView v;
        v.buffer = 0;
        v.byteOffset = buf.size();
        v.byteLength = bytes;
        v.target = target;
        const auto* p = static_cast<const unsigned char*>(data);
        buf.insert(buf.end(), p, p + bytes);
        model.bufferViews.push_back(v);
        return static_cast<int>(model.bufferViews.size() - 1);
    }

    int accessor(int bufferView, int componentType, int type, std::size_t count,
                 std::vector<double> minValues = {}, std::vector<double> maxValues = {}) {
        tinygltf::Accessor a;
        a.bufferView = bufferView;
        a.componentType = componentType;
        a.type = type;
        a.count = count;
        a.minValues = std::move(minValues);
        a.maxValues = std::move(maxValues);
        model.accessors.push_back(a);
        return static_cast<int>(model.accessors.size() - 1);
    }

    // Floats, n components per element, with their per-component min and max when asked.
    int floats(const std::vector<float>& v, int n, int type, int target, bool bounds) {
        std::vector<double> lo;
        std::vector<double> hi;
        if (bounds) {
            lo.assign(static_cast<std::size_t>(n), std::numeric_limits<double>::infinity());
            hi.assign(static_cast<std::size_t>(n), -std::numeric_limits<double>::infinity());
            for (std::size_t i = 0; i < v.size(); ++i) {
                const auto c = i % static_cast<std::size_t>(n);
                lo[c] = std::min(lo[c], static_cast<double>(v[i]));
                hi[c] = std::max(hi[c], static_cast<double>(v[i]));
            }
        }
        const int bv = view(v.data(), v.size() * sizeof(float), target);
        return accessor(bv, kFloat, type, v.size() / static_cast<std::size_t>(n), std::move(lo),
                        std::move(hi));
    }
};

Vec3d origin(const render::Skin& skin, int segment) {
    const auto& o = skin.jointOriginsM[static_cast<std::size_t>(segment)];
    return {o[0], o[1], o[2]};
}

// Weights that sum to 1 in single precision as closely as float allows: the validator checks
// the sum, and the mesh file stores them quantised to 1/255.
std::array<float, 4> exactWeights(const std::array<float, render::kMaxInfluences>& w) {
    double sum = 0;
    for (float x : w) {
        sum += std::max(0.0f, x);
    }
    std::array<float, 4> out{};
    std::size_t largest = 0;
    float rest = 1.0f;
    for (std::size_t i = 0; i < 4; ++i) {
        out[i] = sum > 0 ? static_cast<float>(std::max(0.0f, w[i]) / sum) : (i == 0 ? 1.0f : 0.0f);
        if (out[i] > out[largest]) {
            largest = i;
        }
    }
    for (std::size_t i = 0; i < 4; ++i) {
        if (i != largest) {
            rest -= out[i];
        }
    }
    out[largest] = rest;
    return out;
}

}  // namespace

Result<void> writeGlb(const PoseTrack& track, const JointNames& names, const std::string& path,
                      const ProgressFn& progress) {
    auto loaded = render::loadDefaultSkin();
    if (!loaded) {
        return Error{loaded.error().code, "the default mesh: " + loaded.error().message};
    }
    // Fitted to the recording's subject, so that the mesh's joints are the skeleton's (those of
    // the BVH export too).
    auto fitted = render::fitSkinToSubject(*loaded, track.subject);
    if (!fitted) {
        return Error{fitted.error().code, "the default mesh: " + fitted.error().message};
    }
    const render::Skin& skin = *fitted;
    const std::size_t nv = skin.vertexCount();

    tinygltf::Model model;
    model.asset.version = "2.0";
    model.asset.generator = "caphub export";
    model.buffers.resize(1);
    Builder b{model};

    // The mesh, in the reference pose (metres, skeleton world frame = glTF's frame).
    std::vector<float> positions;
    std::vector<float> normals;
    std::vector<float> weights;
    std::vector<std::uint8_t> jointIds;
    positions.reserve(nv * 3);
    normals.reserve(nv * 3);
    weights.reserve(nv * 4);
    jointIds.reserve(nv * 4);
    for (std::size_t i = 0; i < nv; ++i) {
        positions.insert(positions.end(), skin.positions[i].begin(), skin.positions[i].end());
        // The file's normals are quantised: made unit length again (the validator checks).
        Eigen::Vector3d n(skin.normals[i][0], skin.normals[i][1], skin.normals[i][2]);
        n = n.norm() > 0 ? n.normalized() : Eigen::Vector3d::UnitY();
        normals.insert(normals.end(), {static_cast<float>(n.x()), static_cast<float>(n.y()),
                                       static_cast<float>(n.z())});
        const auto w = exactWeights(skin.weights[i]);
        for (std::size_t k = 0; k < 4; ++k) {
            weights.push_back(w[k]);
            // An unused influence points at joint 0, as glTF recommends.
            jointIds.push_back(w[k] > 0 ? skin.joints[i][k] : std::uint8_t{0});
        }
    }
    std::vector<std::uint32_t> indices;
    indices.reserve(skin.triangles.size() * 3);
    for (const auto& t : skin.triangles) {
        indices.insert(indices.end(), t.begin(), t.end());
    }
    tinygltf::Primitive prim;
    prim.mode = TINYGLTF_MODE_TRIANGLES;
    prim.attributes["POSITION"] =
        b.floats(positions, 3, TINYGLTF_TYPE_VEC3, TINYGLTF_TARGET_ARRAY_BUFFER, true);
    prim.attributes["NORMAL"] =
        b.floats(normals, 3, TINYGLTF_TYPE_VEC3, TINYGLTF_TARGET_ARRAY_BUFFER, false);
    prim.attributes["JOINTS_0"] =
        b.accessor(b.view(jointIds.data(), jointIds.size(), TINYGLTF_TARGET_ARRAY_BUFFER),
                   TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE, TINYGLTF_TYPE_VEC4, nv);
    prim.attributes["WEIGHTS_0"] =
        b.floats(weights, 4, TINYGLTF_TYPE_VEC4, TINYGLTF_TARGET_ARRAY_BUFFER, false);
    prim.indices =
        b.accessor(b.view(indices.data(), indices.size() * sizeof(std::uint32_t),
                          TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER),
                   TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT, TINYGLTF_TYPE_SCALAR, indices.size());
    tinygltf::Mesh mesh;
    mesh.name = "caphub-default";
    mesh.primitives.push_back(prim);
    model.meshes.push_back(mesh);

    // Nodes 0-20: the joints, node i = segment i, rest translations from the mesh's joint
    // origins (so that the bind pose is exactly the mesh's reference pose); node 21: the mesh.
    constexpr int kJoints = body::kSegmentCount;
    std::vector<float> inverseBind;
    for (int s = 0; s < kJoints; ++s) {
        tinygltf::Node node;
        node.name = names.joint[static_cast<std::size_t>(s)];
        const int parent = body::parentOf(s);
        const Vec3d t = parent < 0 ? origin(skin, s) : origin(skin, s) - origin(skin, parent);
        node.translation = {t.x(), t.y(), t.z()};
        for (int c = s + 1; c < kJoints; ++c) {
            if (body::parentOf(c) == s) {
                node.children.push_back(c);
            }
        }
        model.nodes.push_back(node);
        // The bind pose is a pure translation to the joint's origin: its inverse moves back.
        const Vec3d o = origin(skin, s);
        const std::array<float, 16> m = {1,
                                         0,
                                         0,
                                         0,
                                         0,
                                         1,
                                         0,
                                         0,
                                         0,
                                         0,
                                         1,
                                         0,  // column-major
                                         static_cast<float>(-o.x()),
                                         static_cast<float>(-o.y()),
                                         static_cast<float>(-o.z()),
                                         1};
        inverseBind.insert(inverseBind.end(), m.begin(), m.end());
    }
    tinygltf::Skin gskin;
    gskin.name = "caphub-skeleton";
    gskin.skeleton = 0;
    for (int s = 0; s < kJoints; ++s) {
        gskin.joints.push_back(s);
    }
    gskin.inverseBindMatrices = b.floats(inverseBind, 16, TINYGLTF_TYPE_MAT4, 0, false);
    model.skins.push_back(gskin);
    tinygltf::Node meshNode;
    meshNode.name = "caphub-default";
    meshNode.mesh = 0;
    meshNode.skin = 0;
    model.nodes.push_back(meshNode);

    // The animation: seconds from the first exported frame.
    const std::size_t nf = track.frames.size();
    const double t0 = nf > 0 ? track.frames.front().tS : 0.0;
    std::vector<float> times(nf);
    std::vector<float> root(nf * 3);
    std::vector<std::vector<float>> rotations(kJoints, std::vector<float>(nf * 4));
    for (std::size_t f = 0; f < nf; ++f) {
        const PoseFrame& frame = track.frames[f];
        times[f] = static_cast<float>(frame.tS - t0);
        for (int c = 0; c < 3; ++c) {
            root[f * 3 + static_cast<std::size_t>(c)] = static_cast<float>(frame.rootM[c]);
        }
        for (std::size_t s = 0; s < static_cast<std::size_t>(kJoints); ++s) {
            const Quatd q = frame.qLocal[s].normalized();
            float* out = &rotations[s][f * 4];
            out[0] = static_cast<float>(q.x());  // glTF stores x, y, z, w
            out[1] = static_cast<float>(q.y());
            out[2] = static_cast<float>(q.z());
            out[3] = static_cast<float>(q.w());
        }
        if (progress && f % 4096 == 0) {
            progress(0.5 * static_cast<double>(f) / static_cast<double>(nf));
        }
    }
    tinygltf::Animation anim;
    anim.name = "caphub-recording";
    const int input = b.floats(times, 1, TINYGLTF_TYPE_SCALAR, 0, true);
    auto channel = [&](int node, const char* pathName, int output) {
        tinygltf::AnimationSampler sampler;
        sampler.input = input;
        sampler.output = output;
        sampler.interpolation = "LINEAR";
        anim.samplers.push_back(sampler);
        tinygltf::AnimationChannel ch;
        ch.sampler = static_cast<int>(anim.samplers.size() - 1);
        ch.target_node = node;
        ch.target_path = pathName;
        anim.channels.push_back(ch);
    };
    channel(0, "translation", b.floats(root, 3, TINYGLTF_TYPE_VEC3, 0, false));
    for (int s = 0; s < kJoints; ++s) {
        channel(s, "rotation",
                b.floats(rotations[static_cast<std::size_t>(s)], 4, TINYGLTF_TYPE_VEC4, 0, false));
    }
    // The joints whose segment was not measured (its sensor out) and is held at its last
    // measured rotation, by span in the animation's seconds: a reader can show or cut them.
    if (const auto spans = notMeasuredSpans(track); !spans.empty()) {
        tinygltf::Value::Array list;
        for (const auto& span : spans) {
            tinygltf::Value::Object o;
            o["joint"] = tinygltf::Value(names.joint[static_cast<std::size_t>(span.segment)]);
            o["from_s"] = tinygltf::Value(span.fromS - t0);
            o["to_s"] = tinygltf::Value(span.toS - t0);
            list.emplace_back(std::move(o));
        }
        tinygltf::Value::Object extras;
        extras["caphub_not_measured"] = tinygltf::Value(std::move(list));
        anim.extras = tinygltf::Value(std::move(extras));
    }
    model.animations.push_back(anim);

    tinygltf::Scene scene;
    scene.name = "caphub";
    scene.nodes = {0, kJoints};
    model.scenes.push_back(scene);
    model.defaultScene = 0;

    // Serialised in memory, then written through OutputFile: the same checks on what the file is
    // and the same errors (a full disk) as the other formats.
    tinygltf::TinyGLTF writer;
    std::ostringstream glb;
    if (!writer.WriteGltfSceneToStream(&model, glb, false, true)) {
        return Error{EIO, fmt::format("write '{}': the glTF writer failed", path)};
    }
    auto file = OutputFile::open(path);
    if (!file) {
        return file.error();
    }
    file->write(glb.view());
    if (auto closed = file->close(); !closed) {
        return closed;
    }
    if (progress) {
        progress(1.0);
    }
    return {};
}

}  // namespace caphub::firmware::exporter
