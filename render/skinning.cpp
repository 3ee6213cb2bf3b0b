#include "render/skinning.h"

#include <cmath>
#include <cstring>

#include <fmt/format.h>

#include "fusion/body/skeleton.h"

// The kernels are written with GCC/Clang vector extensions: 4- and 8-float vectors that the
// compiler maps to SSE/AVX on x86-64 and NEON on aarch64. On x86-64 each kernel is also compiled
// for Haswell (AVX2 + FMA) and the best version is picked at load time (ifunc).
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define CAPHUB_SKIN_KERNEL __attribute__((target_clones("arch=haswell", "default")))
#else
#define CAPHUB_SKIN_KERNEL
#endif

// The 8-float helpers below pass vectors by value between internal, inlined functions; GCC warns
// that their ABI differs with and without AVX, which matters only across translation units.
#pragma GCC diagnostic ignored "-Wpsabi"

namespace caphub::render {

namespace {

using v4 = float __attribute__((vector_size(16)));
using v8 = float __attribute__((vector_size(32)));

inline v8 load8(const float* p) {
    v8 v;
    std::memcpy(&v, p, sizeof v);
    return v;
}
inline v4 load4(const float* p) {
    v4 v;
    std::memcpy(&v, p, sizeof v);
    return v;
}
inline v8 splat8(float x) {
    return v8{x, x, x, x, x, x, x, x};
}

// out = [c0 c1] * (x x x x y y y y) + [c2 c3] * (z z z z w w w w), then the halves added:
// c0 x + c1 y + c2 z + c3 w, with w = 1 for a position (translation applies) and 0 for a normal.
inline v4 apply(v8 a, v8 b, v4 p) {
    const v8 xy = __builtin_shufflevector(p, p, 0, 0, 0, 0, 1, 1, 1, 1);
    const v8 zw = __builtin_shufflevector(p, p, 2, 2, 2, 2, 3, 3, 3, 3);
    const v8 s = a * xy + b * zw;
    return __builtin_shufflevector(s, s, 0, 1, 2, 3) + __builtin_shufflevector(s, s, 4, 5, 6, 7);
}

CAPHUB_SKIN_KERNEL
void skinRigid(const float* bind, float* out, std::uint32_t n, const float* m) {
    const v8 a = load8(m);
    const v8 b = load8(m + 8);
    for (std::uint32_t i = 0; i < n; ++i) {
        const v4 p = apply(a, b, load4(bind + 8 * i));
        const v4 nn = apply(a, b, load4(bind + 8 * i + 4));
        std::memcpy(out + 8 * i, &p, sizeof p);
        std::memcpy(out + 8 * i + 4, &nn, sizeof nn);
    }
}

// Paper eq. 14: v' = sum_k w_k M_k v, with M_k = T(bone k) B_k^-1 already composed; blending the
// matrices first and applying the blend once is the same sum with fewer operations.
CAPHUB_SKIN_KERNEL
void skinLbs(const float* bind, const std::uint8_t* joints, const float* weights, float* out,
             std::uint32_t n, const float* mats) {
    for (std::uint32_t i = 0; i < n; ++i) {
        const std::uint8_t* j = joints + 4 * i;
        const float* w = weights + 4 * i;
        const float* m0 = mats + 16 * j[0];
        const float* m1 = mats + 16 * j[1];
        const float* m2 = mats + 16 * j[2];
        const float* m3 = mats + 16 * j[3];
        const v8 w0 = splat8(w[0]), w1 = splat8(w[1]), w2 = splat8(w[2]), w3 = splat8(w[3]);
        const v8 a = w0 * load8(m0) + w1 * load8(m1) + w2 * load8(m2) + w3 * load8(m3);
        const v8 b =
            w0 * load8(m0 + 8) + w1 * load8(m1 + 8) + w2 * load8(m2 + 8) + w3 * load8(m3 + 8);
        const v4 p = apply(a, b, load4(bind + 8 * i));
        const v4 nn = apply(a, b, load4(bind + 8 * i + 4));
        std::memcpy(out + 8 * i, &p, sizeof p);
        std::memcpy(out + 8 * i + 4, &nn, sizeof nn);
    }
}

inline float dot4(v4 a, v4 b) {
    const v4 m = a * b;
    return m[0] + m[1] + m[2] + m[3];
}

// Dual-quaternion blending (Kavan et al. 2008): the weighted sum of the unit dual quaternions,
// each flipped into the hemisphere of the first so that q and -q do not cancel, normalised by
// the norm of its real part, then applied as a rotation and a translation.
CAPHUB_SKIN_KERNEL
void skinDqs(const float* bind, const std::uint8_t* joints, const float* weights, float* out,
             std::uint32_t n, const float* dqs) {
    for (std::uint32_t i = 0; i < n; ++i) {
        const std::uint8_t* j = joints + 4 * i;
        const float* w = weights + 4 * i;
        const v8 d0 = load8(dqs + 8 * j[0]);
        const v4 r0 = __builtin_shufflevector(d0, d0, 0, 1, 2, 3);
        v8 sum = splat8(w[0]) * d0;
        for (int k = 1; k < 4; ++k) {
            const v8 dk = load8(dqs + 8 * j[k]);
            const v4 rk = __builtin_shufflevector(dk, dk, 0, 1, 2, 3);
            const float s = dot4(r0, rk) < 0 ? -w[k] : w[k];
            sum += splat8(s) * dk;
        }
        const v4 r = __builtin_shufflevector(sum, sum, 0, 1, 2, 3);
        const v4 d = __builtin_shufflevector(sum, sum, 4, 5, 6, 7);
        const float inv = 1.0f / std::sqrt(dot4(r, r));
        const float x = r[0] * inv, y = r[1] * inv, z = r[2] * inv, ww = r[3] * inv;
        const float dx = d[0] * inv, dy = d[1] * inv, dz = d[2] * inv, dw = d[3] * inv;
        // Translation of a unit dual quaternion: 2 (w d_v - d_w r_v + r_v x d_v).
        const float tx = 2 * (ww * dx - dw * x + (y * dz - z * dy));
        const float ty = 2 * (ww * dy - dw * y + (z * dx - x * dz));
        const float tz = 2 * (ww * dz - dw * z + (x * dy - y * dx));
        const v8 a = {1 - 2 * (y * y + z * z), 2 * (x * y + ww * z),    2 * (x * z - ww * y), 0,
                      2 * (x * y - ww * z),    1 - 2 * (x * x + z * z), 2 * (y * z + ww * x), 0};
        const v8 b = {
            2 * (x * z + ww * y), 2 * (y * z - ww * x), 1 - 2 * (x * x + y * y), 0, tx, ty, tz, 1};
        const v4 p = apply(a, b, load4(bind + 8 * i));
        const v4 nn = apply(a, b, load4(bind + 8 * i + 4));
        std::memcpy(out + 8 * i, &p, sizeof p);
        std::memcpy(out + 8 * i + 4, &nn, sizeof nn);
    }
}

}  // namespace

Skinner::Skinner(const Skin& skin) {
    const std::size_t n = skin.vertexCount();
    bind_.resize(n);
    out_.resize(n);
    joints_ = skin.joints;
    weights_ = skin.weights;
    for (std::size_t i = 0; i < n; ++i) {
        const auto& p = skin.positions[i];
        const auto& nn = skin.normals[i];
        bind_[i] = BindVertex{{p[0], p[1], p[2], 1.0f}, {nn[0], nn[1], nn[2], 0.0f}};
    }
    for (const auto& g : skin.groups) {
        bool rigidCapable = true;
        for (std::uint32_t v = g.firstVertex; v < g.firstVertex + g.vertexCount; ++v) {
            if (skin.joints[v][0] != g.segment || skin.weights[v][0] != 1.0f) {
                rigidCapable = false;
                break;
            }
        }
        groups_.push_back(Group{g.method, rigidCapable, g.segment, g.firstVertex, g.vertexCount});
    }
    for (int s = 0; s < kSegmentCount; ++s) {
        const auto& o = skin.jointOriginsM[static_cast<std::size_t>(s)];
        originsM_[static_cast<std::size_t>(s)] = Vec3d(o[0], o[1], o[2]);
    }
    setPose(SkinPose{});
}

Result<void> Skinner::setGroupMethod(int group, GroupMethod method) {
    if (group < 0 || group >= static_cast<int>(groups_.size())) {
        return Error{EINVAL,
                     fmt::format("group {}: the skin has {} groups", group, groups_.size())};
    }
    auto& g = groups_[static_cast<std::size_t>(group)];
    if (method == GroupMethod::Rigid && !g.rigidCapable) {
        return Error{EINVAL, fmt::format("group {}: its vertices are not all weighted to one "
                                         "segment, so it cannot be rigid",
                                         group)};
    }
    g.method = method;
    return {};
}

void Skinner::setRigidGroupsBlended(bool blended) {
    rigidBlended_ = blended;
}

void Skinner::setPose(const SkinPose& pose) {
    for (const auto& info : body::joints()) {
        const int s = body::idx(info.segment);
        const auto si = static_cast<std::size_t>(s);
        if (info.parent < 0) {
            jointPositionsM_[si] = pose.pelvisM;
        } else {
            const auto pi = static_cast<std::size_t>(info.parent);
            jointPositionsM_[si] = jointPositionsM_[pi] +
                                   pose.qWorld[pi].normalized() * (originsM_[si] - originsM_[pi]);
        }
        const Quatd q = pose.qWorld[si].normalized();
        // M_s v = P_s + R_s (v - O_s): the bind point O_s goes to the joint's position P_s.
        const Eigen::Matrix3d r = q.toRotationMatrix();
        const Vec3d t = jointPositionsM_[si] - r * originsM_[si];
        auto& m = matrices_[si];
        for (int c = 0; c < 3; ++c) {
            for (int k = 0; k < 3; ++k) {
                m.c[4 * c + k] = static_cast<float>(r(k, c));
            }
            m.c[4 * c + 3] = 0;
        }
        for (int k = 0; k < 3; ++k) {
            m.c[12 + k] = static_cast<float>(t[k]);
        }
        m.c[15] = 1;
        // Dual part = 1/2 (0, t) q.
        const Quatd dual = Quatd(0, 0.5 * t.x(), 0.5 * t.y(), 0.5 * t.z()) * q;
        auto& d = dualQuats_[si];
        d.q[0] = static_cast<float>(q.x());
        d.q[1] = static_cast<float>(q.y());
        d.q[2] = static_cast<float>(q.z());
        d.q[3] = static_cast<float>(q.w());
        d.q[4] = static_cast<float>(dual.x());
        d.q[5] = static_cast<float>(dual.y());
        d.q[6] = static_cast<float>(dual.z());
        d.q[7] = static_cast<float>(dual.w());
    }
}

void Skinner::skin() {
    const auto* bind = reinterpret_cast<const float*>(bind_.data());
    auto* out = reinterpret_cast<float*>(out_.data());
    const auto* joints = reinterpret_cast<const std::uint8_t*>(joints_.data());
    const auto* weights = reinterpret_cast<const float*>(weights_.data());
    const auto* mats = reinterpret_cast<const float*>(matrices_.data());
    const auto* dqs = reinterpret_cast<const float*>(dualQuats_.data());
    for (const auto& g : groups_) {
        GroupMethod m = g.method;
        if (m == GroupMethod::Rigid && rigidBlended_) {
            m = GroupMethod::Lbs;
        }
        const std::size_t f = g.first;
        switch (m) {
            case GroupMethod::Rigid:
                skinRigid(bind + 8 * f, out + 8 * f, g.count, mats + 16 * g.segment);
                break;
            case GroupMethod::Lbs:
                skinLbs(bind + 8 * f, joints + 4 * f, weights + 4 * f, out + 8 * f, g.count, mats);
                break;
            case GroupMethod::Dqs:
                skinDqs(bind + 8 * f, joints + 4 * f, weights + 4 * f, out + 8 * f, g.count, dqs);
                break;
        }
    }
}

}  // namespace caphub::render
