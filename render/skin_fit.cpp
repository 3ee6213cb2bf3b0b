#include "render/skin_fit.h"

#include <algorithm>
#include <cmath>
#include <string>

#include <Eigen/Dense>
#include <fmt/format.h>

#include "fusion/body/kinematics.h"

namespace caphub::render {

namespace {

using Mat3d = Eigen::Matrix3d;

// Below this fraction of a segment's largest spread of child joints, a direction is left to the
// girth scale: joints that nearly line up (the clavicles either side of the neck) say little
// about how to stretch across them, and inverting that would magnify millimetres into shear.
constexpr double kMinSpreadFraction = 0.2;

// The linear part of a deformable segment's map: M D = D' for the bone vectors D (columns: skin
// origin to each child's origin) and their targets D', M u = g u across them. Solved with D's
// pseudo-inverse, ill-conditioned directions dropped (kMinSpreadFraction).
Mat3d boneMap(const std::vector<Vec3d>& bones, const std::vector<Vec3d>& targets, double g) {
    const Mat3d iso = g * Mat3d::Identity();
    if (bones.empty()) {
        return iso;
    }
    Eigen::Matrix<double, 3, Eigen::Dynamic> d(3, bones.size());
    Eigen::Matrix<double, 3, Eigen::Dynamic> t(3, bones.size());
    for (std::size_t i = 0; i < bones.size(); ++i) {
        d.col(static_cast<Eigen::Index>(i)) = bones[i];
        t.col(static_cast<Eigen::Index>(i)) = targets[i];
    }
    Eigen::JacobiSVD<Eigen::MatrixXd> svd(d, Eigen::ComputeThinU | Eigen::ComputeThinV);
    const Eigen::VectorXd& s = svd.singularValues();
    if (s.size() == 0 || s(0) < 1e-6) {
        return iso;  // children at the origin: nothing to stretch
    }
    Eigen::MatrixXd sInv = Eigen::MatrixXd::Zero(s.size(), s.size());
    for (Eigen::Index i = 0; i < s.size(); ++i) {
        if (s(i) >= kMinSpreadFraction * s(0)) {
            sInv(i, i) = 1.0 / s(i);
        }
    }
    const Eigen::MatrixXd pinv = svd.matrixV() * sInv * svd.matrixU().transpose();  // n x 3
    return iso + (t - g * d) * pinv;
}

}  // namespace

std::array<Vec3d, kSegmentCount> referenceOriginsM(const body::Dimensions& dims) {
    // The reference pose: every segment aligned with the world, the root at its height.
    body::Pose pose;
    body::forwardKinematics(dims, dims.offsetM[0], pose);  // offsetM[0]: the root's height
    return pose.positionM;
}

Result<Skin> fitSkin(const Skin& skin, const std::array<Vec3d, kSegmentCount>& targetOriginsM,
                     double targetHeightM) {
    if (auto ok = validate(skin); !ok) {
        return Error{ok.error().code, "fitting the skin: " + ok.error().message};
    }
    if (!(targetHeightM >= 0.5 && targetHeightM <= 2.5)) {
        return Error{EINVAL,
                     fmt::format("fitting the skin to a height of {} m: expected 0.5 to 2.5 m",
                                 targetHeightM)};
    }
    if (skin.vertexCount() == 0) {
        return skin;
    }
    float lowY = skin.positions[0][1];
    float highY = lowY;
    for (const auto& p : skin.positions) {
        lowY = std::min(lowY, p[1]);
        highY = std::max(highY, p[1]);
    }
    const double skinHeightM = static_cast<double>(highY) - lowY;
    if (!(skinHeightM > 0.01)) {
        return Error{EINVAL, fmt::format("fitting the skin: the skin is {} m high: expected a body",
                                         skinHeightM)};
    }
    const double g = targetHeightM / skinHeightM;

    std::array<bool, kSegmentCount> rigid{};
    for (const auto& group : skin.groups) {
        if (group.method == GroupMethod::Rigid && group.vertexCount > 0) {
            rigid[static_cast<std::size_t>(group.segment)] = true;
        }
    }
    auto origin = [&](int s) {
        const auto& o = skin.jointOriginsM[static_cast<std::size_t>(s)];
        return Vec3d(o[0], o[1], o[2]);
    };
    std::array<Mat3d, kSegmentCount> linear{};
    for (int s = 0; s < kSegmentCount; ++s) {
        std::vector<Vec3d> bones, targets;
        if (!rigid[static_cast<std::size_t>(s)]) {
            for (int c = 0; c < kSegmentCount; ++c) {
                if (body::parentOf(c) == s) {
                    bones.push_back(origin(c) - origin(s));
                    targets.push_back(targetOriginsM[static_cast<std::size_t>(c)] -
                                      targetOriginsM[static_cast<std::size_t>(s)]);
                }
            }
        }
        linear[static_cast<std::size_t>(s)] = boneMap(bones, targets, g);
    }

    Skin out = skin;
    for (std::size_t v = 0; v < skin.vertexCount(); ++v) {
        const auto& p = skin.positions[v];
        const Vec3d pos(p[0], p[1], p[2]);
        Vec3d moved = Vec3d::Zero();
        Mat3d blend = Mat3d::Zero();
        for (int k = 0; k < kMaxInfluences; ++k) {
            const double w = skin.weights[v][static_cast<std::size_t>(k)];
            if (w == 0) {
                continue;
            }
            const int s = skin.joints[v][static_cast<std::size_t>(k)];
            const auto si = static_cast<std::size_t>(s);
            moved += w * (targetOriginsM[si] + linear[si] * (pos - origin(s)));
            blend += w * linear[si];
        }
        const auto& n = skin.normals[v];
        Vec3d normal = blend.inverse().transpose() * Vec3d(n[0], n[1], n[2]);
        // A blend of maps that all preserve orientation keeps a positive determinant; guard anyway.
        if (!(normal.norm() > 1e-12) || !normal.allFinite()) {
            normal = Vec3d(n[0], n[1], n[2]);
        }
        normal.normalize();
        out.positions[v] = {static_cast<float>(moved.x()), static_cast<float>(moved.y()),
                            static_cast<float>(moved.z())};
        out.normals[v] = {static_cast<float>(normal.x()), static_cast<float>(normal.y()),
                          static_cast<float>(normal.z())};
    }
    for (int s = 0; s < kSegmentCount; ++s) {
        const Vec3d& t = targetOriginsM[static_cast<std::size_t>(s)];
        out.jointOriginsM[static_cast<std::size_t>(s)] = {
            static_cast<float>(t.x()), static_cast<float>(t.y()), static_cast<float>(t.z())};
    }
    out.provenance = skin.provenance + fmt::format("; fitted to a {:.3f} m subject", targetHeightM);
    return out;
}

Result<Skin> fitSkinToSubject(const Skin& skin, const board::SubjectConfig& subject) {
    auto dims = body::dimensionsFromSubject(subject);
    if (!dims) {
        return Error{dims.error().code, "fitting the skin: " + dims.error().message};
    }
    return fitSkin(skin, referenceOriginsM(*dims), subject.heightM);
}

}  // namespace caphub::render
