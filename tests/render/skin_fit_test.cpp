// Fitting the default skin to subjects of other heights: joints, extent, rigid groups.
#include "render/skin_fit.h"

#include <algorithm>
#include <cmath>

#include <gtest/gtest.h>

#include "render/skinning.h"

namespace caphub::render {
namespace {

using board::Segment;

Vec3d at(const std::array<float, 3>& p) {
    return Vec3d(p[0], p[1], p[2]);
}

const Skin& defaultSkin() {
    static const Skin skin = [] {
        auto s = loadDefaultSkin();
        EXPECT_TRUE(s) << s.error().message;
        return s ? *s : Skin{};
    }();
    return skin;
}

struct Fitted {
    Skin skin;
    body::Dimensions dims;
    std::array<Vec3d, kSegmentCount> originsM;
};

Fitted fitTo(double heightM) {
    board::SubjectConfig subject;
    subject.heightM = heightM;
    auto dims = body::dimensionsFromSubject(subject);
    EXPECT_TRUE(dims);
    auto fitted = fitSkinToSubject(defaultSkin(), subject);
    EXPECT_TRUE(fitted) << fitted.error().message;
    return {fitted ? *fitted : Skin{}, *dims, referenceOriginsM(*dims)};
}

struct Box {
    Vec3d lo = Vec3d::Constant(1e9);
    Vec3d hi = Vec3d::Constant(-1e9);
};

Box extent(const Skin& s) {
    Box b;
    for (const auto& p : s.positions) {
        b.lo = b.lo.cwiseMin(at(p));
        b.hi = b.hi.cwiseMax(at(p));
    }
    return b;
}

// The limb joints: shoulders, elbows, wrists, hips, knees, ankles (segment origins).
constexpr Segment kLimbJoints[] = {
    Segment::LUpperarm, Segment::RUpperarm, Segment::LForearm,  Segment::RForearm,
    Segment::LHand,     Segment::RHand,     Segment::LThigh,    Segment::RThigh,
    Segment::LCalf,     Segment::RCalf,     Segment::LHindfoot, Segment::RHindfoot,
};

TEST(SkinFit, ReferenceOriginsSumTheOffsetsDownTheTree) {
    board::SubjectConfig subject;
    subject.heightM = 1.80;
    auto dims = body::dimensionsFromSubject(subject);
    ASSERT_TRUE(dims);
    const auto o = referenceOriginsM(*dims);
    const auto i = [](Segment s) { return static_cast<std::size_t>(s); };
    EXPECT_TRUE(o[i(Segment::Pelvis)].isApprox(dims->offsetM[i(Segment::Pelvis)]));
    const Vec3d knee = dims->offsetM[i(Segment::Pelvis)] + dims->offsetM[i(Segment::LThigh)] +
                       dims->offsetM[i(Segment::LCalf)];
    EXPECT_LT((o[i(Segment::LCalf)] - knee).norm(), 1e-12);
}

constexpr double kShortM = 1.50;
constexpr double kTallM = 1.95;

double skinHeightM(const Skin& s) {
    const Box b = extent(s);
    return b.hi.y() - b.lo.y();
}

// Each limb joint's neighbourhood (the default skin's vertices within 8 cm of the joint) comes
// along: its centroid's offset from the joint is the old one scaled by g = H / skin height.
// Tolerance 1 cm: along the bone the neighbourhood is stretched by the bone's own ratio, not g
// (the skeleton's upper arm, 0.186 H, is 1.37 x MakeHuman's), which moves a centroid lying up to
// ~2 cm along the bone from its joint by up to 0.4 x that; the joints themselves move 1.8 to
// 37 cm between these subjects and the default skin, so a skin left in place fails.
TEST(SkinFit, VerticesAroundEachLimbJointFollowTheSkeletonsJoint) {
    const Skin& s0 = defaultSkin();
    for (double h : {kShortM, kTallM}) {
        const Fitted f = fitTo(h);
        const double g = h / skinHeightM(s0);
        for (Segment j : kLimbJoints) {
            const auto ji = static_cast<std::size_t>(j);
            const Vec3d o0 = at(s0.jointOriginsM[ji]);
            Vec3d c0 = Vec3d::Zero(), c1 = Vec3d::Zero();
            int n = 0;
            for (std::size_t v = 0; v < s0.vertexCount(); ++v) {
                if ((at(s0.positions[v]) - o0).norm() < 0.08) {
                    c0 += at(s0.positions[v]);
                    c1 += at(f.skin.positions[v]);
                    ++n;
                }
            }
            ASSERT_GT(n, 10) << board::segmentName(j);
            const Vec3d before = c0 / n - o0;
            const Vec3d after = c1 / n - f.originsM[ji];
            EXPECT_LT((after - g * before).norm(), 0.01)
                << board::segmentName(j) << " of a " << h << " m subject";
        }
    }
}

// The skinned reference pose of the fitted skin, pelvis where the skeleton has it, is the fitted
// mesh, and the skin's joints are the skeleton's: the preview's overlay and mesh agree with the
// body. Tolerance 1e-5 m: float positions of ~2 m carry ~2e-7 m, a few operations add a few ulps.
TEST(SkinFit, SkinnedReferencePoseHasTheSkeletonsJoints) {
    for (double h : {kShortM, kTallM}) {
        const Fitted f = fitTo(h);
        ASSERT_TRUE(validate(f.skin)) << validate(f.skin).error().message;
        Skinner skinner(f.skin);
        SkinPose pose;
        pose.pelvisM = f.originsM[static_cast<std::size_t>(Segment::Pelvis)];
        skinner.setPose(pose);
        skinner.skin();
        for (int s = 0; s < kSegmentCount; ++s) {
            EXPECT_LT((skinner.jointPositionsM()[static_cast<std::size_t>(s)] -
                       f.originsM[static_cast<std::size_t>(s)])
                          .norm(),
                      1e-5)
                << board::segmentName(static_cast<Segment>(s));
        }
        double worst = 0;
        for (std::size_t v = 0; v < f.skin.vertexCount(); ++v) {
            const auto& o = skinner.output()[v].position;
            worst = std::max(worst, (Vec3d(o[0], o[1], o[2]) - at(f.skin.positions[v])).norm());
        }
        EXPECT_LT(worst, 1e-5);
    }
}

// The mesh's extent follows the skeleton. Arm span: the fingertips within 1 cm of the skeleton's
// hand end sites (the hands are scaled by g, their length is MakeHuman's, 0.108 H in the
// skeleton: measured 4-6 mm apart). Soles within 1 cm of the floor (the skin's ankle height
// scaled by g against the skeleton's 0.039 H: measured 5-7 mm below). Height: the same fraction of
// H for both subjects (0.5 %), at 0.95-1.0 H: the skeleton puts the skullbase at chin height
// (0.870 H), MakeHuman's skull joint sits 6.6 cm higher in the head, so with the joints matched
// the crown is ~4 % of H below the skeleton's head end site.
TEST(SkinFit, ExtentFollowsTheSkeleton) {
    double heightFraction[2] = {0, 0};
    int i = 0;
    for (double h : {kShortM, kTallM}) {
        const Fitted f = fitTo(h);
        const Box b = extent(f.skin);
        const auto hand = [&](Segment s, body::EndEffector e) {
            return f.originsM[static_cast<std::size_t>(s)] +
                   f.dims.endSiteM[static_cast<std::size_t>(e)];
        };
        EXPECT_NEAR(b.hi.x(), hand(Segment::LHand, body::EndEffector::LHand).x(), 0.01) << h;
        EXPECT_NEAR(b.lo.x(), hand(Segment::RHand, body::EndEffector::RHand).x(), 0.01) << h;
        EXPECT_NEAR(b.lo.y(), 0.0, 0.01) << h;
        heightFraction[i] = (b.hi.y() - b.lo.y()) / h;
        EXPECT_GT(heightFraction[i], 0.95) << h;
        EXPECT_LE(heightFraction[i], 1.0) << h;
        ++i;
    }
    EXPECT_NEAR(heightFraction[0], heightFraction[1], 0.005);
}

// Rigid groups (head, hands, feet, toes) are moved as one: every distance within a group is its
// old one times g, and the skin's own height gives g = 1, i.e. distances kept. Tolerance: 1e-6 m
// plus 1e-5 relative, float rounding of the positions.
TEST(SkinFit, RigidGroupsKeepTheirShape) {
    const Skin& s0 = defaultSkin();
    for (double h : {kShortM, kTallM, skinHeightM(s0)}) {
        const Fitted f = fitTo(h);
        const double g = h / skinHeightM(s0);
        int groups = 0;
        for (const auto& group : s0.groups) {
            if (group.method != GroupMethod::Rigid || group.vertexCount < 2) {
                continue;
            }
            ++groups;
            double worst = 0;
            const std::uint32_t a = group.firstVertex;
            const std::uint32_t step = std::max(1u, group.vertexCount / 200);
            for (std::uint32_t v = a + 1; v < a + group.vertexCount; v += step) {
                for (std::uint32_t u : {a, v - 1}) {
                    const double d0 = (at(s0.positions[v]) - at(s0.positions[u])).norm();
                    const double d1 = (at(f.skin.positions[v]) - at(f.skin.positions[u])).norm();
                    worst = std::max(worst, std::abs(d1 - g * d0) - 1e-5 * d0);
                }
            }
            EXPECT_LT(worst, 1e-6) << group.name << " of a " << h << " m subject";
        }
        EXPECT_EQ(groups, 7);
    }
}

// Deformable groups do change shape: the arms of the tall subject are longer than g times the
// default's (the skeleton's arms are longer in proportion than MakeHuman's), measured along X.
TEST(SkinFit, DeformableGroupsStretchWithTheirBones) {
    const Skin& s0 = defaultSkin();
    const Fitted f = fitTo(kTallM);
    const double g = kTallM / skinHeightM(s0);
    const int arm = s0.findGroup("l_upperarm");
    ASSERT_GE(arm, 0);
    const auto& group = s0.groups[static_cast<std::size_t>(arm)];
    double lo0 = 1e9, hi0 = -1e9, lo1 = 1e9, hi1 = -1e9;
    for (std::uint32_t v = group.firstVertex; v < group.firstVertex + group.vertexCount; ++v) {
        lo0 = std::min<double>(lo0, s0.positions[v][0]);
        hi0 = std::max<double>(hi0, s0.positions[v][0]);
        lo1 = std::min<double>(lo1, f.skin.positions[v][0]);
        hi1 = std::max<double>(hi1, f.skin.positions[v][0]);
    }
    const auto i = [](Segment s) { return static_cast<std::size_t>(s); };
    const double boneRatio =
        (f.originsM[i(Segment::LForearm)] - f.originsM[i(Segment::LUpperarm)]).norm() /
        (at(s0.jointOriginsM[i(Segment::LForearm)]) - at(s0.jointOriginsM[i(Segment::LUpperarm)]))
            .norm();
    // The group's length along the bone grows by about the bone's ratio (10 %: the group reaches
    // past the joints into the blends with the shoulder and the elbow), well above g.
    EXPECT_GT(boneRatio, g * 1.2);
    EXPECT_NEAR((hi1 - lo1) / (hi0 - lo0), boneRatio, 0.1 * boneRatio);
}

TEST(SkinFit, HeightOutsideTheBodysRangeIsAnError) {
    board::SubjectConfig subject;
    subject.heightM = 3.1;
    auto fitted = fitSkinToSubject(defaultSkin(), subject);
    ASSERT_FALSE(fitted);
    EXPECT_NE(fitted.error().message.find("3.1"), std::string::npos) << fitted.error().message;
    EXPECT_NE(fitted.error().message.find("fitting the skin"), std::string::npos);
}

TEST(SkinFit, InvalidSkinIsAnError) {
    Skin broken = defaultSkin();
    broken.weights.pop_back();
    board::SubjectConfig subject;
    auto fitted = fitSkinToSubject(broken, subject);
    ASSERT_FALSE(fitted);
    EXPECT_NE(fitted.error().message.find("fitting the skin"), std::string::npos);
}

}  // namespace
}  // namespace caphub::render
