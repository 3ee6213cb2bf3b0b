// Skinning: rigid groups, linear blending (paper eqs. 14-16) and dual quaternions.
#include "render/skinning.h"

#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "render/skin.h"

namespace caphub::render {
namespace {

using board::Segment;
constexpr int kForearm = static_cast<int>(Segment::LForearm);
constexpr int kHand = static_cast<int>(Segment::LHand);

Vec3d pos(const SkinnedVertex& v) {
    return Vec3d(v.position[0], v.position[1], v.position[2]);
}

// A pose with every segment turned by a random rotation of up to ~70 degrees.
SkinPose randomPose(unsigned seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> u(-0.6, 0.6);
    SkinPose p;
    for (auto& q : p.qWorld) {
        q = Quatd(1.0, u(rng), u(rng), u(rng)).normalized();
    }
    p.pelvisM = Vec3d(0.3, 0.95, -0.2);
    return p;
}

// Signed volume of a closed triangle mesh (divergence theorem).
double volume(std::span<const SkinnedVertex> v,
              const std::vector<std::array<std::uint32_t, 3>>& t) {
    double sum = 0;
    for (const auto& tri : t) {
        sum += pos(v[tri[0]]).dot(pos(v[tri[1]]).cross(pos(v[tri[2]])));
    }
    return sum / 6;
}

// A closed tube along +X, 35 cm long, radius 3 cm: forearm up to 20 cm, then a 10 cm blend
// into the hand (the wrist), then 5 cm of hand. The hand joint sits at 25 cm.
Skin forearmTube(GroupMethod method) {
    Skin s;
    constexpr int kRings = 36, kAround = 32;
    constexpr double kLength = 0.35, kRadius = 0.03;
    for (int r = 0; r < kRings; ++r) {
        const double x = kLength * r / (kRings - 1);
        const float wf = static_cast<float>(std::clamp((0.3 - x) / 0.1, 0.0, 1.0));
        for (int a = 0; a < kAround; ++a) {
            const double phi = 2 * M_PI * a / kAround;
            s.positions.push_back({static_cast<float>(x),
                                   static_cast<float>(1.4 + kRadius * std::cos(phi)),
                                   static_cast<float>(kRadius * std::sin(phi))});
            s.normals.push_back(
                {0, static_cast<float>(std::cos(phi)), static_cast<float>(std::sin(phi))});
            s.joints.push_back({kForearm, kHand, 0, 0});
            s.weights.push_back({wf, 1 - wf, 0, 0});
        }
    }
    const auto capA = static_cast<std::uint32_t>(s.positions.size());
    s.positions.push_back({0, 1.4f, 0});
    s.positions.push_back({static_cast<float>(kLength), 1.4f, 0});
    s.normals.push_back({-1, 0, 0});
    s.normals.push_back({1, 0, 0});
    s.joints.push_back({kForearm, kHand, 0, 0});
    s.joints.push_back({kForearm, kHand, 0, 0});
    s.weights.push_back({1, 0, 0, 0});
    s.weights.push_back({0, 1, 0, 0});
    auto at = [](int r, int a) { return static_cast<std::uint32_t>(r * kAround + (a % kAround)); };
    for (int r = 0; r + 1 < kRings; ++r) {
        for (int a = 0; a < kAround; ++a) {
            s.triangles.push_back({at(r, a), at(r, a + 1), at(r + 1, a + 1)});
            s.triangles.push_back({at(r, a), at(r + 1, a + 1), at(r + 1, a)});
        }
    }
    for (int a = 0; a < kAround; ++a) {
        s.triangles.push_back({capA, at(0, a + 1), at(0, a)});
        s.triangles.push_back({capA + 1, at(kRings - 1, a), at(kRings - 1, a + 1)});
    }
    s.groups = {{"forearm", method, kForearm, 0, static_cast<std::uint32_t>(s.positions.size())}};
    s.jointOriginsM[kForearm] = {0, 1.4f, 0};
    s.jointOriginsM[kHand] = {0.25f, 1.4f, 0};
    return s;
}

double twistedVolumeRatio(GroupMethod method) {
    const Skin s = forearmTube(method);
    EXPECT_TRUE(validate(s));
    Skinner sk(s);
    SkinPose rest;  // pelvis at the skin's origin, every segment unrotated
    sk.setPose(rest);
    sk.skin();
    const double v0 = volume(sk.output(), s.triangles);
    SkinPose twisted = rest;
    twisted.qWorld[kHand] = Quatd(Eigen::AngleAxisd(M_PI / 2, Vec3d::UnitX()));
    sk.setPose(twisted);
    sk.skin();
    return volume(sk.output(), s.triangles) / v0;
}

TEST(Skinning, ReferencePoseReproducesTheBindMesh) {
    auto skin = loadDefaultSkin();
    ASSERT_TRUE(skin) << skin.error().message;
    Skinner sk(*skin);
    SkinPose p;
    const auto& o = skin->jointOriginsM[0];
    p.pelvisM = Vec3d(o[0], o[1], o[2]);
    sk.setPose(p);
    sk.skin();
    for (std::size_t i = 0; i < skin->vertexCount(); ++i) {
        for (int k = 0; k < 3; ++k) {
            // float arithmetic on coordinates below 2 m: a few ulps of 1e-7.
            ASSERT_NEAR(sk.output()[i].position[k], skin->positions[i][k], 2e-6) << i;
        }
    }
}

TEST(Skinning, LinearBlendMatchesEquation14InDoublePrecision) {
    auto skin = loadDefaultSkin();
    ASSERT_TRUE(skin) << skin.error().message;
    Skinner sk(*skin);
    for (std::size_t g = 0; g < skin->groups.size(); ++g) {
        ASSERT_TRUE(sk.setGroupMethod(static_cast<int>(g), GroupMethod::Lbs));
    }
    const SkinPose p = randomPose(7);
    sk.setPose(p);
    sk.skin();
    const auto& J = sk.jointPositionsM();
    for (std::size_t i = 0; i < skin->vertexCount(); i += 7) {
        const Vec3d v(skin->positions[i][0], skin->positions[i][1], skin->positions[i][2]);
        Vec3d expected = Vec3d::Zero();
        for (int k = 0; k < 4; ++k) {
            const int j = skin->joints[i][k];
            const auto& o = skin->jointOriginsM[j];
            expected += skin->weights[i][k] *
                        (J[j] + p.qWorld[j].normalized() * (v - Vec3d(o[0], o[1], o[2])));
        }
        // float matrices and weights against double: 1e-5 m is 50 float ulps at 2 m.
        ASSERT_NEAR((pos(sk.output()[i]) - expected).norm(), 0.0, 1e-5) << i;
    }
}

TEST(Skinning, RigidGroupsKeepTheirShapeExactly) {
    auto skin = loadDefaultSkin();
    ASSERT_TRUE(skin) << skin.error().message;
    Skinner sk(*skin);
    sk.setPose(randomPose(3));
    sk.skin();
    for (const auto& g : skin->groups) {
        if (g.method != GroupMethod::Rigid) {
            continue;
        }
        // Every vertex against the group's first few: distances unchanged.
        for (std::uint32_t a = g.firstVertex; a < g.firstVertex + 5; ++a) {
            for (std::uint32_t b = g.firstVertex; b < g.firstVertex + g.vertexCount; ++b) {
                const auto& pa = skin->positions[a];
                const auto& pb = skin->positions[b];
                const double before =
                    (Vec3d(pa[0], pa[1], pa[2]) - Vec3d(pb[0], pb[1], pb[2])).norm();
                const double after = (pos(sk.output()[a]) - pos(sk.output()[b])).norm();
                // One float rotation of coordinates up to 2 m: 1e-6 m.
                ASSERT_NEAR(after, before, 1e-6) << g.name << " " << a << " " << b;
            }
        }
    }
}

TEST(Skinning, RigidGroupsBlendedGiveTheSameMesh) {
    auto skin = loadDefaultSkin();
    ASSERT_TRUE(skin) << skin.error().message;
    Skinner rigid(*skin), blended(*skin);
    blended.setRigidGroupsBlended(true);
    const SkinPose p = randomPose(11);
    rigid.setPose(p);
    blended.setPose(p);
    rigid.skin();
    blended.skin();
    for (std::size_t i = 0; i < skin->vertexCount(); ++i) {
        ASSERT_NEAR((pos(rigid.output()[i]) - pos(blended.output()[i])).norm(), 0.0, 1e-6) << i;
    }
}

TEST(Skinning, RigidIsRefusedForABlendedGroup) {
    auto skin = loadDefaultSkin();
    ASSERT_TRUE(skin) << skin.error().message;
    Skinner sk(*skin);
    EXPECT_FALSE(sk.setGroupMethod(skin->findGroup("torso"), GroupMethod::Rigid));
    EXPECT_FALSE(sk.setGroupMethod(99, GroupMethod::Lbs));
}

TEST(Skinning, NinetyDegreeForearmTwistLosesVolumeUnderLinearBlending) {
    const double ratio = twistedVolumeRatio(GroupMethod::Lbs);
    RecordProperty("lbs_volume_ratio", std::to_string(ratio));
    std::printf("LBS: twisted/rest volume = %.4f\n", ratio);
    // Analytically the wrist's cross-sections shrink to 1 - 2 w (1 - w) of their area: 2/3 on
    // average over the 10 cm blend, 1/3 of 10/35 of the tube lost: ratio ~0.905.
    EXPECT_LT(ratio, 0.95);
}

TEST(Skinning, NinetyDegreeForearmTwistKeepsVolumeUnderDualQuaternions) {
    const double ratio = twistedVolumeRatio(GroupMethod::Dqs);
    RecordProperty("dqs_volume_ratio", std::to_string(ratio));
    std::printf("DQS: twisted/rest volume = %.4f\n", ratio);
    // DQS turns each ring rigidly; only the flat triangles between twisted rings change the
    // polyhedron's volume, by well under 1 %.
    EXPECT_NEAR(ratio, 1.0, 0.01);
}

TEST(Skinning, DualQuaternionOfOneInfluenceIsTheRigidTransform) {
    const Skin s = forearmTube(GroupMethod::Dqs);
    Skinner dqs(s);
    Skin lbsSkin = s;
    lbsSkin.groups[0].method = GroupMethod::Lbs;
    Skinner lbs(lbsSkin);
    SkinPose p = randomPose(5);
    dqs.setPose(p);
    lbs.setPose(p);
    dqs.skin();
    lbs.skin();
    for (std::size_t i = 0; i < s.vertexCount(); ++i) {
        if (s.weights[i][0] == 1.0f || s.weights[i][1] == 1.0f) {
            // Two float paths (matrix vs dual quaternion) to the same transform: 2e-6 m.
            ASSERT_NEAR((pos(dqs.output()[i]) - pos(lbs.output()[i])).norm(), 0.0, 2e-6) << i;
        }
    }
}

}  // namespace
}  // namespace caphub::render
