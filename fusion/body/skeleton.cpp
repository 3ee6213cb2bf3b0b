#include "fusion/body/skeleton.h"

#include <cmath>

#include <fmt/format.h>

namespace caphub::body {

namespace {

using S = Segment;

JointLimits lim(double x0, double x1, double y0, double y1, double z0, double z1) {
    return {Vec3d(x0, y0, z0), Vec3d(x1, y1, z1)};
}

// A right-side joint is the mirror image of the left one in the body's midplane (x -> -x): a
// rotation vector (an axial vector) maps to (x, -y, -z), so the Y and Z ranges swap and flip.
JointLimits mirror(const JointLimits& l) {
    return {Vec3d(l.minDeg.x(), -l.maxDeg.y(), -l.maxDeg.z()),
            Vec3d(l.maxDeg.x(), -l.minDeg.y(), -l.minDeg.z())};
}

// Left-side limits, degrees (docs/skeleton.md gives the sign conventions and the source: normal
// ranges of motion after AAOS, widened a little because the limits are soft).
const JointLimits kSpine = lim(-20, 45, -25, 25, -25, 25);  // per spine joint (half a region)
const JointLimits kNeck = lim(-40, 40, -45, 45, -25, 25);
const JointLimits kClavicle = lim(-30, 30, -25, 25, -10, 40);
const JointLimits kShoulder = lim(-100, 100, -135, 50, -100, 95);
const JointLimits kElbow = lim(-95, 95, -160, 10, -15, 15);
const JointLimits kWrist = lim(-20, 20, -35, 25, -85, 75);
const JointLimits kHip = lim(-130, 30, -45, 45, -30, 50);
const JointLimits kKnee = lim(-5, 150, -30, 30, -10, 10);
const JointLimits kAnkle = lim(-25, 55, -30, 30, -25, 35);
const JointLimits kToes = lim(-80, 40, -10, 10, -10, 10);
const JointLimits kFree{};

}  // namespace

namespace detail {
const std::array<JointInfo, kSegmentCount> kJointTable = {{
    {S::Pelvis, "humanoid_root", -1, JointKind::Root, 6, kFree},
    {S::L5, "vl5", idx(S::Pelvis), JointKind::Derived, 3, kSpine},
    {S::T12, "vt12", idx(S::L5), JointKind::Driven, 3, kSpine},
    {S::C7, "vc7", idx(S::T12), JointKind::Derived, 3, kNeck},
    {S::Skull, "skullbase", idx(S::C7), JointKind::Driven, 3, kNeck},
    {S::LClavicle, "l_sternoclavicular", idx(S::T12), JointKind::Driven, 2, kClavicle},
    {S::LUpperarm, "l_shoulder", idx(S::LClavicle), JointKind::Driven, 3, kShoulder},
    {S::LForearm, "l_elbow", idx(S::LUpperarm), JointKind::Driven, 2, kElbow},
    {S::LHand, "l_radiocarpal", idx(S::LForearm), JointKind::Driven, 2, kWrist},
    {S::RClavicle, "r_sternoclavicular", idx(S::T12), JointKind::Driven, 2, mirror(kClavicle)},
    {S::RUpperarm, "r_shoulder", idx(S::RClavicle), JointKind::Driven, 3, mirror(kShoulder)},
    {S::RForearm, "r_elbow", idx(S::RUpperarm), JointKind::Driven, 2, mirror(kElbow)},
    {S::RHand, "r_radiocarpal", idx(S::RForearm), JointKind::Driven, 2, mirror(kWrist)},
    {S::LThigh, "l_hip", idx(S::Pelvis), JointKind::Driven, 3, kHip},
    {S::LCalf, "l_knee", idx(S::LThigh), JointKind::Driven, 1, kKnee},
    {S::LHindfoot, "l_talocrural", idx(S::LCalf), JointKind::Driven, 2, kAnkle},
    {S::LMiddistal, "l_metatarsophalangeal", idx(S::LHindfoot), JointKind::Fixed, 1, kToes},
    {S::RThigh, "r_hip", idx(S::Pelvis), JointKind::Driven, 3, mirror(kHip)},
    {S::RCalf, "r_knee", idx(S::RThigh), JointKind::Driven, 1, mirror(kKnee)},
    {S::RHindfoot, "r_talocrural", idx(S::RCalf), JointKind::Driven, 2, mirror(kAnkle)},
    {S::RMiddistal, "r_metatarsophalangeal", idx(S::RHindfoot), JointKind::Fixed, 1, mirror(kToes)},
}};
}  // namespace detail

using detail::kJointTable;

namespace {

// Drillis & Contini (1966) as drawn in Winter, "Biomechanics and Motor Control of Human
// Movement", fig. 4.1: lengths as fractions of the standing height H.
constexpr double kHipHeight = 0.530;  // greater trochanter
constexpr double kShoulderHeight = 0.818;
constexpr double kChinHeight = 0.870;
constexpr double kHeadHeight = 0.130;  // chin to vertex
constexpr double kShoulderWidth = 0.259;
constexpr double kHipWidth = 0.191;
constexpr double kUpperarm = 0.186;
constexpr double kForearm = 0.146;
constexpr double kHand = 0.108;
constexpr double kThigh = 0.245;
constexpr double kShank = 0.246;
constexpr double kAnkleHeight = 0.039;
constexpr double kFootLength = 0.152;

// Where the table is silent (docs/skeleton.md, "Assumptions"): the trunk from hip to shoulder
// level is split pelvis/abdomen/thorax as 0.06/0.09/0.138 H at the L4-L5 and T12-L1 levels;
// the sternoclavicular joints sit 0.015 H either side of the midline, 0.010 H below the
// shoulders; the hip joint centres are a quarter of the hip width either side of the midline;
// the ankle is 0.2 foot lengths in front of the heel and the ball 0.55 in front of the ankle.
constexpr double kPelvisToL5 = 0.060;
constexpr double kL5ToT12 = 0.090;
constexpr double kSternoclavicularX = 0.015;
constexpr double kSternoclavicularBelowShoulder = 0.010;
constexpr double kHeelBehindAnkle = 0.20;  // of the foot length
constexpr double kBallBeforeAnkle = 0.55;
constexpr double kToeBeforeAnkle = 0.80;
constexpr double kBallAboveGround = 0.012;  // H, the metatarsophalangeal joint centre

// Dempster via Winter, table 4.1: mass fractions and centres of mass from the proximal end.
struct MassRow {
    Segment s;
    double fraction;
};
constexpr std::array<MassRow, 15> kMass = {{
    {S::Pelvis, 0.142},
    {S::L5, 0.139},     // abdomen
    {S::T12, 0.216},    // thorax (the clavicles are inside it)
    {S::Skull, 0.081},  // head and neck (c7 carries none of its own)
    {S::LUpperarm, 0.028},
    {S::LForearm, 0.016},
    {S::LHand, 0.006},
    {S::RUpperarm, 0.028},
    {S::RForearm, 0.016},
    {S::RHand, 0.006},
    {S::LThigh, 0.100},
    {S::LCalf, 0.0465},
    {S::LHindfoot, 0.0145},  // foot including the toes
    {S::RThigh, 0.100},
    {S::RCalf, 0.0465},
}};
constexpr double kRightFootMass = 0.0145;

}  // namespace

const std::array<JointInfo, kSegmentCount>& joints() {
    return kJointTable;
}

const std::array<IndependentJoint, kIndependentJointCount>& independentJoints() {
    static const std::array<IndependentJoint, kIndependentJointCount> kIndependent = [] {
        std::array<IndependentJoint, kIndependentJointCount> out{};
        std::size_t n = 0;
        for (const JointInfo& j : kJointTable) {
            const int seg = idx(j.segment);
            if (j.segment == S::T12) {
                out[n++] = {"vl5+vt12", idx(S::Pelvis), seg, idx(S::L5)};
            } else if (j.segment == S::Skull) {
                out[n++] = {"vc7+skullbase", idx(S::T12), seg, idx(S::C7)};
            } else if (j.kind == JointKind::Root || j.kind == JointKind::Driven) {
                out[n++] = {j.name, j.parent, seg, seg};
            }
        }
        return out;
    }();
    return kIndependent;
}

const JointInfo& jointInfo(Segment s) {
    return kJointTable[static_cast<std::size_t>(idx(s))];
}

std::string_view endEffectorName(EndEffector e) {
    static constexpr std::array<std::string_view, kEndEffectorCount> kNames = {
        "head", "l_hand", "r_hand", "l_foot", "r_foot"};
    return kNames[static_cast<std::size_t>(e)];
}

Segment endEffectorSegment(EndEffector e) {
    static constexpr std::array<Segment, kEndEffectorCount> kSeg = {S::Skull, S::LHand, S::RHand,
                                                                    S::LHindfoot, S::RHindfoot};
    return kSeg[static_cast<std::size_t>(e)];
}

void setCentresOfMass(Dimensions& d) {
    auto com = [&](Segment s, const Vec3d& v) {
        d.centreOfMassM[static_cast<std::size_t>(idx(s))] = v;
    };
    auto at = [&](Segment child) { return d.offsetM[static_cast<std::size_t>(idx(child))]; };
    com(S::Pelvis, 0.895 * at(S::L5));  // 0.105 from L4-L5 towards the trochanters
    com(S::L5, 0.56 * at(S::T12));      // 0.44 from T12-L1
    com(S::T12, 0.18 * at(S::C7));      // 0.82 from C7-T1
    com(S::Skull, Vec3d::Zero());       // head and neck: at the ear canal (the skullbase)
    com(S::LUpperarm, 0.436 * at(S::LForearm));
    com(S::RUpperarm, 0.436 * at(S::RForearm));
    com(S::LForearm, 0.430 * at(S::LHand));
    com(S::RForearm, 0.430 * at(S::RHand));
    com(S::LHand, 0.506 * d.endSiteM[static_cast<std::size_t>(EndEffector::LHand)]);
    com(S::RHand, 0.506 * d.endSiteM[static_cast<std::size_t>(EndEffector::RHand)]);
    com(S::LThigh, 0.433 * at(S::LCalf));
    com(S::RThigh, 0.433 * at(S::RCalf));
    com(S::LCalf, 0.433 * at(S::LHindfoot));
    com(S::RCalf, 0.433 * at(S::RHindfoot));
    com(S::LHindfoot, 0.5 * at(S::LMiddistal));
    com(S::RHindfoot, 0.5 * at(S::RMiddistal));
}

Result<Dimensions> dimensionsFromSubject(const board::SubjectConfig& subject) {
    const double h = subject.heightM;
    if (!(h >= 0.5 && h <= 2.5)) {
        return Error{EINVAL, fmt::format("subject height {} m: expected 0.5 to 2.5 m", h)};
    }
    if (subject.massKg && !(*subject.massKg >= 10 && *subject.massKg <= 400)) {
        return Error{EINVAL,
                     fmt::format("subject mass {} kg: expected 10 to 400 kg", *subject.massKg)};
    }
    Dimensions d;
    auto off = [&](Segment s, double x, double y, double z) {
        d.offsetM[static_cast<std::size_t>(idx(s))] = Vec3d(x, y, z) * h;
    };
    const double thoraxH = kShoulderHeight - kHipHeight - kPelvisToL5 - kL5ToT12;
    const double shoulderX = kShoulderWidth / 2;
    const double hipX = kHipWidth / 4;
    off(S::Pelvis, 0, kHipHeight, 0);
    off(S::L5, 0, kPelvisToL5, 0);
    off(S::T12, 0, kL5ToT12, 0);
    off(S::C7, 0, thoraxH, 0);
    off(S::Skull, 0, kChinHeight - kShoulderHeight, 0);
    for (int side = 0; side < 2; ++side) {
        const double sx = side == 0 ? 1.0 : -1.0;  // +X is the subject's left
        const Segment cl = side == 0 ? S::LClavicle : S::RClavicle;
        off(cl, sx * kSternoclavicularX, thoraxH - kSternoclavicularBelowShoulder, 0);
        off(side == 0 ? S::LUpperarm : S::RUpperarm, sx * (shoulderX - kSternoclavicularX),
            kSternoclavicularBelowShoulder, 0);
        off(side == 0 ? S::LForearm : S::RForearm, sx * kUpperarm, 0, 0);
        off(side == 0 ? S::LHand : S::RHand, sx * kForearm, 0, 0);
        off(side == 0 ? S::LThigh : S::RThigh, sx * hipX, 0, 0);
        off(side == 0 ? S::LCalf : S::RCalf, 0, -kThigh, 0);
        off(side == 0 ? S::LHindfoot : S::RHindfoot, 0, -kShank, 0);
        off(side == 0 ? S::LMiddistal : S::RMiddistal, 0, -(kAnkleHeight - kBallAboveGround),
            kBallBeforeAnkle * kFootLength);
        auto& fp = side == 0 ? d.leftFootPointM : d.rightFootPointM;
        fp[0] = Vec3d(0, -kAnkleHeight, -kHeelBehindAnkle * kFootLength) * h;
        fp[1] = Vec3d(0, -kAnkleHeight, kBallBeforeAnkle * kFootLength) * h;
        fp[2] = Vec3d(0, -kAnkleHeight, kToeBeforeAnkle * kFootLength) * h;
        d.endSiteM[static_cast<std::size_t>(side == 0 ? EndEffector::LHand : EndEffector::RHand)] =
            Vec3d(sx * kHand, 0, 0) * h;
        d.endSiteM[static_cast<std::size_t>(side == 0 ? EndEffector::LFoot : EndEffector::RFoot)] =
            fp[2];
    }
    d.endSiteM[static_cast<std::size_t>(EndEffector::Head)] = Vec3d(0, kHeadHeight, 0) * h;

    // Measured lengths replace the derived ones: the segment's bone (to its main child or end
    // site) keeps its direction and takes the measured length.
    for (const auto& [seg, lengthM] : subject.segmentLengthsM) {
        if (!(lengthM >= 0.01 && lengthM <= 1.5)) {
            return Error{EINVAL, fmt::format("measured length of {}: {} m: expected 0.01 to 1.5 m",
                                             board::segmentName(seg), lengthM)};
        }
        const double current = segmentLengthM(d, seg);
        if (!(current > 0)) {
            return Error{EINVAL, fmt::format("measured length of {}: the segment has no bone",
                                             board::segmentName(seg))};
        }
        const double k = lengthM / current;
        auto scaleChild = [&](Segment child) {
            d.offsetM[static_cast<std::size_t>(idx(child))] *= k;
        };
        switch (seg) {
            case S::Pelvis:
                d.offsetM[static_cast<std::size_t>(idx(S::Pelvis))] *= k;
                break;
            case S::L5:
                scaleChild(S::T12);
                break;
            case S::T12:
                scaleChild(S::C7);
                break;
            case S::C7:
                scaleChild(S::Skull);
                break;
            case S::Skull:
                d.endSiteM[static_cast<std::size_t>(EndEffector::Head)] *= k;
                break;
            case S::LClavicle:
                scaleChild(S::LUpperarm);
                break;
            case S::RClavicle:
                scaleChild(S::RUpperarm);
                break;
            case S::LUpperarm:
                scaleChild(S::LForearm);
                break;
            case S::RUpperarm:
                scaleChild(S::RForearm);
                break;
            case S::LForearm:
                scaleChild(S::LHand);
                break;
            case S::RForearm:
                scaleChild(S::RHand);
                break;
            case S::LHand:
                d.endSiteM[static_cast<std::size_t>(EndEffector::LHand)] *= k;
                break;
            case S::RHand:
                d.endSiteM[static_cast<std::size_t>(EndEffector::RHand)] *= k;
                break;
            case S::LThigh:
                scaleChild(S::LCalf);
                break;
            case S::RThigh:
                scaleChild(S::RCalf);
                break;
            case S::LCalf:
                scaleChild(S::LHindfoot);
                break;
            case S::RCalf:
                scaleChild(S::RHindfoot);
                break;
            case S::LHindfoot:
                scaleChild(S::LMiddistal);
                for (auto& p : d.leftFootPointM) {
                    p *= k;
                }
                break;
            case S::RHindfoot:
                scaleChild(S::RMiddistal);
                for (auto& p : d.rightFootPointM) {
                    p *= k;
                }
                break;
            case S::LMiddistal:
            case S::RMiddistal:
                break;  // the toes' length does not move any joint
        }
    }

    for (const MassRow& r : kMass) {
        d.massFraction[static_cast<std::size_t>(idx(r.s))] = r.fraction;
    }
    d.massFraction[static_cast<std::size_t>(idx(S::RHindfoot))] = kRightFootMass;
    if (subject.massKg) {
        for (std::size_t i = 0; i < d.massKg.size(); ++i) {
            d.massKg[i] = d.massFraction[i] * *subject.massKg;
        }
    }
    setCentresOfMass(d);
    return d;
}

double segmentLengthM(const Dimensions& d, Segment s) {
    auto at = [&](Segment child) { return d.offsetM[static_cast<std::size_t>(idx(child))].norm(); };
    auto end = [&](EndEffector e) { return d.endSiteM[static_cast<std::size_t>(e)].norm(); };
    switch (s) {
        case S::Pelvis:
            return at(S::Pelvis);  // the root's height above the floor
        case S::L5:
            return at(S::T12);
        case S::T12:
            return at(S::C7);
        case S::C7:
            return at(S::Skull);
        case S::Skull:
            return end(EndEffector::Head);
        case S::LClavicle:
            return at(S::LUpperarm);
        case S::RClavicle:
            return at(S::RUpperarm);
        case S::LUpperarm:
            return at(S::LForearm);
        case S::RUpperarm:
            return at(S::RForearm);
        case S::LForearm:
            return at(S::LHand);
        case S::RForearm:
            return at(S::RHand);
        case S::LHand:
            return end(EndEffector::LHand);
        case S::RHand:
            return end(EndEffector::RHand);
        case S::LThigh:
            return at(S::LCalf);
        case S::RThigh:
            return at(S::RCalf);
        case S::LCalf:
            return at(S::LHindfoot);
        case S::RCalf:
            return at(S::RHindfoot);
        case S::LHindfoot:
            return at(S::LMiddistal);
        case S::RHindfoot:
            return at(S::RMiddistal);
        case S::LMiddistal:
            return (d.leftFootPointM[2] - d.offsetM[static_cast<std::size_t>(idx(S::LMiddistal))])
                .norm();
        case S::RMiddistal:
            return (d.rightFootPointM[2] - d.offsetM[static_cast<std::size_t>(idx(S::RMiddistal))])
                .norm();
    }
    return 0;
}

Skeleton::Skeleton(const Dimensions& d) : dims_(d) {
    for (int i = 0; i < kSegmentCount; ++i) {
        const JointInfo& j = kJointTable[static_cast<std::size_t>(i)];
        Bone& b = bones_[static_cast<std::size_t>(i)];
        b.id = i;
        b.name = board::segmentName(j.segment);
        b.jointName = j.name;
        b.lengthM = segmentLengthM(d, j.segment);
        b.massKg = d.massKg[static_cast<std::size_t>(i)];
        b.centreOfMassM = d.centreOfMassM[static_cast<std::size_t>(i)];
        b.dof = j.dof;
        b.limits = j.limits;
        b.parent = j.parent;
        b.baseTranslationM = d.offsetM[static_cast<std::size_t>(i)];
        b.currentTranslationM = b.baseTranslationM;
        if (j.parent >= 0) {
            Bone& p = bones_[static_cast<std::size_t>(j.parent)];
            if (p.childCount < static_cast<int>(p.children.size())) {
                p.children[static_cast<std::size_t>(p.childCount++)] = i;
            }
        }
    }
}

int Skeleton::chain(EndEffector e, std::array<int, 8>& out) const {
    std::array<int, 8> rev{};
    int n = 0;
    for (int s = idx(endEffectorSegment(e)); s >= 0 && n < 8; s = parentOf(s)) {
        rev[static_cast<std::size_t>(n++)] = s;
    }
    for (int i = 0; i < n; ++i) {
        out[static_cast<std::size_t>(i)] = rev[static_cast<std::size_t>(n - 1 - i)];
    }
    return n;
}

}  // namespace caphub::body
