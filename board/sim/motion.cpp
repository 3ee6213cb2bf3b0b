#include "board/sim/motion.h"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

namespace caphub::board::sim {

using board::Segment;

namespace {

constexpr std::size_t sz(Segment s) {
    return static_cast<std::size_t>(s);
}

// Cumulative basis functions of the uniform cubic B-spline, B~1..B~3 (B~0 is 1), and their
// first and second derivatives with respect to u in [0, 1].
struct Basis {
    std::array<double, 3> b;
    std::array<double, 3> db;
    std::array<double, 3> ddb;
};

Basis cumulativeBasis(double u) {
    const double u2 = u * u;
    const double u3 = u2 * u;
    Basis k;
    k.b = {(u3 - 3 * u2 + 3 * u + 5) / 6, (-2 * u3 + 3 * u2 + 3 * u + 1) / 6, u3 / 6};
    k.db = {(u - 1) * (u - 1) / 2, (-2 * u2 + 2 * u + 1) / 2, u2 / 2};
    k.ddb = {u - 1, 1 - 2 * u, u};
    return k;
}

// The T-pose direction of each segment's bone in the world frame (subject facing +Z, left +X).
// The pelvis has none: its rest orientation is its T-pose orientation.
std::optional<Vec3d> tposeDirection(Segment s) {
    switch (s) {
        case Segment::Pelvis:
            return std::nullopt;
        case Segment::L5:
        case Segment::T12:
        case Segment::C7:
        case Segment::Skull:
            return Vec3d::UnitY();
        case Segment::LClavicle:
        case Segment::LUpperarm:
        case Segment::LForearm:
        case Segment::LHand:
            return Vec3d::UnitX();
        case Segment::RClavicle:
        case Segment::RUpperarm:
        case Segment::RForearm:
        case Segment::RHand:
            return -Vec3d::UnitX();
        case Segment::LThigh:
        case Segment::LCalf:
        case Segment::RThigh:
        case Segment::RCalf:
            return -Vec3d::UnitY();
        case Segment::LHindfoot:
        case Segment::LMiddistal:
        case Segment::RHindfoot:
        case Segment::RMiddistal:
            return Vec3d::UnitZ();
    }
    return std::nullopt;
}

// The segment that continues a segment's chain (whose origin is its distal end), if any.
std::optional<Segment> distalSegment(Segment s) {
    switch (s) {
        case Segment::L5:
            return Segment::T12;
        case Segment::T12:
            return Segment::C7;
        case Segment::C7:
            return Segment::Skull;
        case Segment::LClavicle:
            return Segment::LUpperarm;
        case Segment::LUpperarm:
            return Segment::LForearm;
        case Segment::LForearm:
            return Segment::LHand;
        case Segment::RClavicle:
            return Segment::RUpperarm;
        case Segment::RUpperarm:
            return Segment::RForearm;
        case Segment::RForearm:
            return Segment::RHand;
        case Segment::LThigh:
            return Segment::LCalf;
        case Segment::LCalf:
            return Segment::LHindfoot;
        case Segment::LHindfoot:
            return Segment::LMiddistal;
        case Segment::RThigh:
            return Segment::RCalf;
        case Segment::RCalf:
            return Segment::RHindfoot;
        case Segment::RHindfoot:
            return Segment::RMiddistal;
        default:
            return std::nullopt;
    }
}

// World rotations and positions (file units) of every joint at one frame.
void forwardKinematics(const BvhClip& clip, std::span<const double> values, std::vector<Quatd>& q,
                       std::vector<Vec3d>& p) {
    q.resize(clip.joints.size());
    p.resize(clip.joints.size());
    for (std::size_t j = 0; j < clip.joints.size(); ++j) {
        Vec3d t;
        Quatd r;
        clip.localPose(static_cast<int>(j), values, t, r);
        const int parent = clip.joints[j].parent;
        if (parent < 0) {
            q[j] = r;
            p[j] = t;
        } else {
            const auto pj = static_cast<std::size_t>(parent);
            q[j] = q[pj] * r;
            p[j] = p[pj] + q[pj] * t;
        }
    }
}

// The rest-pose world position of the point a segment's bone points at: the origin of the
// segment continuing its chain, else its orientation joint's End Site, else the first joint
// below it that sits away from it.
std::optional<Vec3d> restDistalPoint(const BvhClip& clip, const SegmentBinding& b, Segment s,
                                     const std::vector<Vec3d>& restP) {
    if (const auto d = distalSegment(s); d && b.mapped(*d)) {
        return restP[static_cast<std::size_t>(b.positionJoint[sz(*d)])];
    }
    const int oj = b.orientationJoint[sz(s)];
    const BvhJoint& joint = clip.joints[static_cast<std::size_t>(oj)];
    if (joint.endSite && joint.endSite->norm() > 0) {
        return restP[static_cast<std::size_t>(oj)] + *joint.endSite;
    }
    for (std::size_t k = static_cast<std::size_t>(oj) + 1; k < clip.joints.size(); ++k) {
        int a = clip.joints[k].parent;
        while (a >= 0 && a != oj) {
            a = clip.joints[static_cast<std::size_t>(a)].parent;
        }
        if (a == oj && (restP[k] - restP[static_cast<std::size_t>(oj)]).norm() > 0) {
            return restP[k];
        }
    }
    return std::nullopt;
}

// Solves the knot equations of a uniform cubic B-spline with natural ends, in place:
// x_0 = r_0, (x_{k-1} + 4 x_k + x_{k+1}) / 6 = r_k, x_{n-1} = r_{n-1} (Thomas algorithm; the
// matrix is diagonally dominant, so no pivoting is needed).
void solveKnotSystem(std::vector<Vec3d>& r, std::vector<double>& upper) {
    const std::size_t n = r.size();
    if (n < 3) {
        return;  // every row is an end row: x = r
    }
    upper.assign(n, 0.0);
    constexpr double kOff = 1.0 / 6.0;
    constexpr double kDiag = 4.0 / 6.0;
    for (std::size_t i = 1; i + 1 < n; ++i) {
        const double pivot = kDiag - kOff * upper[i - 1];
        upper[i] = kOff / pivot;
        r[i] = (r[i] - kOff * r[i - 1]) / pivot;
    }
    for (std::size_t i = n - 1; i-- > 0;) {
        r[i] -= upper[i] * r[i + 1];
    }
}

// Zero-phase Gaussian low-pass of the keys: rotations averaged in the tangent space at each
// key, positions directly; beyond the ends the keys are mirrored (odd extension), which keeps
// a steady motion steady up to the last frame.
void smoothKeys(std::vector<Quatd>& q, std::vector<Vec3d>& p, double sigmaFrames) {
    const auto n = static_cast<long>(q.size());
    if (!(sigmaFrames > 0) || n < 3) {
        return;
    }
    // Three sigmas hold all but 0.3 % of the kernel; more than the clip's length adds nothing.
    const long radius = std::max(
        1L, static_cast<long>(std::min(std::ceil(3 * sigmaFrames), static_cast<double>(n))));
    std::vector<double> w(static_cast<std::size_t>(2 * radius + 1));
    double sum = 0;
    for (long j = -radius; j <= radius; ++j) {
        const double x = static_cast<double>(j) / sigmaFrames;
        w[static_cast<std::size_t>(j + radius)] = std::exp(-0.5 * x * x);
        sum += w[static_cast<std::size_t>(j + radius)];
    }
    auto key = [&](long m, Quatd& qm, Vec3d& pm) {
        if (m < 0) {
            const long k = std::min(-m, n - 1);
            qm = q[0] * fromRotationVector<double>(-toRotationVector<double>(
                            q[0].conjugate() * q[static_cast<std::size_t>(k)]));
            pm = 2 * p[0] - p[static_cast<std::size_t>(k)];
        } else if (m >= n) {
            const long k = std::max(2 * (n - 1) - m, 0L);
            const auto last = static_cast<std::size_t>(n - 1);
            qm = q[last] * fromRotationVector<double>(-toRotationVector<double>(
                               q[last].conjugate() * q[static_cast<std::size_t>(k)]));
            pm = 2 * p[last] - p[static_cast<std::size_t>(k)];
        } else {
            qm = q[static_cast<std::size_t>(m)];
            pm = p[static_cast<std::size_t>(m)];
        }
    };
    std::vector<Quatd> qs(q.size());
    std::vector<Vec3d> ps(p.size());
    for (long k = 0; k < n; ++k) {
        const Quatd& base = q[static_cast<std::size_t>(k)];
        Vec3d v = Vec3d::Zero();
        Vec3d pos = Vec3d::Zero();
        for (long j = -radius; j <= radius; ++j) {
            Quatd qm;
            Vec3d pm;
            key(k + j, qm, pm);
            const double wj = w[static_cast<std::size_t>(j + radius)] / sum;
            v += wj * toRotationVector<double>(base.conjugate() * qm);
            pos += wj * pm;
        }
        qs[static_cast<std::size_t>(k)] = (base * fromRotationVector<double>(v)).normalized();
        ps[static_cast<std::size_t>(k)] = pos;
    }
    q.swap(qs);
    p.swap(ps);
}

}  // namespace

Result<Motion> Motion::fromClip(const BvhClip& clip, const JointMap& map,
                                const MotionOptions& options) {
    if (clip.frameCount < 1 ||
        clip.values.size() < static_cast<std::size_t>(clip.frameCount) *
                                 static_cast<std::size_t>(clip.channelCount)) {
        return Error{EINVAL, "the clip has no frames: motion needs at least one"};
    }
    // Mocap runs at 1 Hz to 100 kHz; outside that the frame time is a mistake, and the
    // nanosecond arithmetic of evaluate() would lose its meaning.
    constexpr double kMinFrameTimeS = 1e-5;
    constexpr double kMaxFrameTimeS = 1.0;
    if (!(clip.frameTimeS >= kMinFrameTimeS && clip.frameTimeS <= kMaxFrameTimeS)) {
        return Error{EINVAL, fmt::format("the clip's frame time {:g} s is outside {:g} to {:g} s",
                                         clip.frameTimeS, kMinFrameTimeS, kMaxFrameTimeS)};
    }
    const std::optional<double> unit = options.unitM ? options.unitM : map.unitM;
    if (!unit || !(*unit > 0) || !std::isfinite(*unit)) {
        return Error{EINVAL, fmt::format("no length unit for the clip: joint map '{}' gives none; "
                                         "set unit_m in the map or pass the unit option",
                                         map.name)};
    }
    // In metres, the clip must be a body somewhere on the ground: an OFFSET of 1e50 units (or
    // a unit of 1e300 m) made every figure of the evaluation nan or inf.
    constexpr double kMaxBoneM = 2.0;          // a longer bone is not a person's
    constexpr double kMaxPositionM = 10000.0;  // a capture 10 km from its origin is a mistake
    for (const BvhJoint& j : clip.joints) {
        for (const auto& [what, offset] :
             {std::pair{"OFFSET", j.offset},
              std::pair{"End Site OFFSET", j.endSite.value_or(Vec3d::Zero())}}) {
            const double m = offset.stableNorm() * *unit;  // 1e200 units: no overflow
            if (!(m <= kMaxBoneM) && !(j.parent < 0 && m <= kMaxPositionM)) {
                return Error{EINVAL,
                             fmt::format("line {}: joint '{}': its {} is {:g} m long at {:g} m "
                                         "per unit, more than a body's bone ({:g} m): not a "
                                         "body's skeleton, or the wrong unit (unit_m of map "
                                         "'{}')",
                                         j.line, j.name, what, m, *unit, kMaxBoneM, map.name)};
            }
        }
    }
    for (int f = 0; f < clip.frameCount; ++f) {
        const std::span<const double> values = clip.frame(f);
        for (const BvhJoint& j : clip.joints) {
            for (std::size_t c = 0; c < j.channels.size(); ++c) {
                const BvhChannel ch = j.channels[c];
                const bool position = ch == BvhChannel::Xposition || ch == BvhChannel::Yposition ||
                                      ch == BvhChannel::Zposition;
                const double v = values[static_cast<std::size_t>(j.firstChannel) + c];
                if (position && !(std::abs(v) * *unit <= kMaxPositionM)) {
                    return Error{EINVAL,
                                 fmt::format("frame {}: joint '{}': a position of {:g} m at {:g} "
                                             "m per unit, beyond {:g} m of the origin",
                                             f, j.name, v * *unit, *unit, kMaxPositionM)};
                }
            }
        }
    }
    const ReferencePose ref =
        options.reference ? *options.reference : map.reference.value_or(ReferencePose{});
    if (ref.kind == ReferencePose::Kind::Frame && (ref.frame < 0 || ref.frame >= clip.frameCount)) {
        return Error{EINVAL, fmt::format("reference frame {} is outside the clip (frames 0 to {})",
                                         ref.frame, clip.frameCount - 1)};
    }
    const int first = options.firstFrame ? *options.firstFrame : map.firstFrame.value_or(0);
    if (first < 0 || first >= clip.frameCount) {
        return Error{EINVAL, fmt::format("first frame of motion {} is outside the clip (frames 0 "
                                         "to {})",
                                         first, clip.frameCount - 1)};
    }
    auto binding = bindJointMap(map, clip);
    if (!binding) {
        return binding.error();
    }
    const SegmentBinding& b = *binding;

    Motion m;
    m.frameCount_ = clip.frameCount - first;
    m.firstFrame_ = first;
    m.frameTimeS_ = clip.frameTimeS;
    m.unitM_ = *unit;
    m.reference_ = ref;

    // The world rotation of each segment's orientation joint in the reference pose.
    std::array<Quatd, board::kSegmentCount> qRef;
    qRef.fill(Quatd::Identity());
    std::vector<Quatd> q;
    std::vector<Vec3d> p;
    if (ref.kind == ReferencePose::Kind::Frame) {
        forwardKinematics(clip, clip.frame(ref.frame), q, p);
        for (const auto& info : board::kSegments) {
            if (b.mapped(info.id)) {
                qRef[sz(info.id)] =
                    q[static_cast<std::size_t>(b.orientationJoint[sz(info.id)])].normalized();
            }
        }
    } else if (ref.kind == ReferencePose::Kind::TPose) {
        const std::vector<double> zeros(static_cast<std::size_t>(clip.channelCount), 0.0);
        forwardKinematics(clip, zeros, q, p);
        for (const auto& info : board::kSegments) {
            const auto target = tposeDirection(info.id);
            if (!b.mapped(info.id) || !target) {
                continue;
            }
            const auto distal = restDistalPoint(clip, b, info.id, p);
            if (!distal) {
                continue;
            }
            const Vec3d bone = *distal - p[static_cast<std::size_t>(b.positionJoint[sz(info.id)])];
            if (bone.norm() > 0) {
                qRef[sz(info.id)] = Quatd::FromTwoVectors(bone, *target);
            }
        }
    }

    const auto n = static_cast<std::size_t>(m.frameCount_);
    for (const auto& info : board::kSegments) {
        m.mapped_[sz(info.id)] = b.mapped(info.id);
        m.source_[sz(info.id)] = b.poseSource[sz(info.id)];
        if (b.mapped(info.id)) {
            m.tracks_[sz(info.id)].keyQ.resize(n);
            m.tracks_[sz(info.id)].keyP.resize(n);
        }
    }
    for (std::size_t f = 0; f < n; ++f) {
        forwardKinematics(clip, clip.frame(first + static_cast<int>(f)), q, p);
        for (const auto& info : board::kSegments) {
            if (!b.mapped(info.id)) {
                continue;
            }
            Track& tr = m.tracks_[sz(info.id)];
            const Quatd qs = (q[static_cast<std::size_t>(b.orientationJoint[sz(info.id)])] *
                              qRef[sz(info.id)].conjugate())
                                 .normalized();
            // Keep neighbouring keys in one hemisphere so differences stay small rotations.
            tr.keyQ[f] = (f > 0 && tr.keyQ[f - 1].dot(qs) < 0) ? Quatd(-qs.coeffs()) : qs;
            tr.keyP[f] = p[static_cast<std::size_t>(b.positionJoint[sz(info.id)])] * m.unitM_;
        }
    }

    if (options.smoothingHz > 0) {
        // A Gaussian of standard deviation sigma passes half the power at
        // f = sqrt(ln 2) / (2 pi sigma), about 0.1325 / sigma.
        const double sigmaFrames = 0.1325 / (options.smoothingHz * clip.frameTimeS);
        for (const auto& info : board::kSegments) {
            if (b.mapped(info.id)) {
                Track& tr = m.tracks_[sz(info.id)];
                smoothKeys(tr.keyQ, tr.keyP, sigmaFrames);
            }
        }
    }

    // Control points. With the phantom ends mirroring c_1 about c_0 (a natural end: no
    // curvature there) the spline's value at an end knot is the end control point, and at an
    // inner knot k it is (c_{k-1} + 4 c_k + c_{k+1}) / 6 in a vector space, its group analogue
    // for rotations. Interpolating means solving that tridiagonal system for the controls:
    // exactly for positions; for rotations by Newton steps, each the same system solved for the
    // tangent-space corrections of the knot residuals (converging in a few steps, since
    // neighbouring frames differ by small rotations). Not interpolating: the keys are the
    // controls, and the spline smooths them a little more.
    constexpr int kMaxNewtonSteps = 30;
    constexpr double kTolRad = 1e-12;
    std::vector<double> scratch;
    std::vector<Vec3d> delta(n);
    for (const auto& info : board::kSegments) {
        if (!b.mapped(info.id)) {
            continue;
        }
        Track& tr = m.tracks_[sz(info.id)];
        tr.q.assign(n + 2, Quatd::Identity());
        tr.p.assign(n + 2, Vec3d::Zero());
        for (std::size_t k = 0; k < n; ++k) {
            tr.q[k + 1] = tr.keyQ[k];
            delta[k] = tr.keyP[k];
        }
        if (options.interpolate) {
            solveKnotSystem(delta, scratch);
        }
        for (std::size_t k = 0; k < n; ++k) {
            tr.p[k + 1] = delta[k];
        }
        auto setPhantoms = [&] {
            if (n == 1) {
                tr.q[0] = tr.q[2] = tr.q[1];
                tr.p[0] = tr.p[2] = tr.p[1];
                return;
            }
            tr.q[0] = (tr.q[1] * fromRotationVector<double>(
                                     -toRotationVector<double>(tr.q[1].conjugate() * tr.q[2])))
                          .normalized();
            tr.q[n + 1] = (tr.q[n] * fromRotationVector<double>(toRotationVector<double>(
                                         tr.q[n - 1].conjugate() * tr.q[n])))
                              .normalized();
            tr.p[0] = 2 * tr.p[1] - tr.p[2];
            tr.p[n + 1] = 2 * tr.p[n] - tr.p[n - 1];
        };
        setPhantoms();
        for (int step = 0; options.interpolate && n > 2; ++step) {
            double worstRad = 0;
            for (std::size_t k = 0; k < n; ++k) {
                // Knot k: padded controls k, k+1, k+2 (c_{k-1}, c_k, c_{k+1}).
                const Vec3d l1 = toRotationVector<double>(tr.q[k].conjugate() * tr.q[k + 1]);
                const Vec3d l2 = toRotationVector<double>(tr.q[k + 1].conjugate() * tr.q[k + 2]);
                const Quatd knot = tr.q[k] * fromRotationVector<double>(l1 * (5.0 / 6.0)) *
                                   fromRotationVector<double>(l2 * (1.0 / 6.0));
                delta[k] = toRotationVector<double>(knot.conjugate() * tr.keyQ[k]);
                worstRad = std::max(worstRad, delta[k].norm());
            }
            if (worstRad < kTolRad || step == kMaxNewtonSteps) {
                m.fitResidualRad_ = std::max(m.fitResidualRad_, worstRad);
                break;
            }
            solveKnotSystem(delta, scratch);
            for (std::size_t k = 0; k < n; ++k) {
                tr.q[k + 1] = (tr.q[k + 1] * fromRotationVector<double>(delta[k])).normalized();
            }
            setPhantoms();
        }
        tr.logQ.assign(n + 2, Vec3d::Zero());
        tr.dP.assign(n + 2, Vec3d::Zero());
        for (std::size_t k = 1; k < n + 2; ++k) {
            tr.logQ[k] = toRotationVector<double>(tr.q[k - 1].conjugate() * tr.q[k]);
            tr.dP[k] = tr.p[k] - tr.p[k - 1];
        }
    }
    return m;
}

const Motion::Track& Motion::track(Segment s) const {
    return tracks_[sz(source_[sz(s)])];
}

bool Motion::mapped(Segment s) const {
    return mapped_[sz(s)];
}

std::int64_t Motion::durationNs() const {
    return static_cast<std::int64_t>(std::llround((frameCount_ - 1) * frameTimeS_ * 1e9));
}

Quatd Motion::keyOrientation(Segment s, int frame) const {
    return track(s).keyQ[static_cast<std::size_t>(frame)];
}

Vec3d Motion::keyPositionM(Segment s, int frame) const {
    return track(s).keyP[static_cast<std::size_t>(frame)];
}

void Motion::evaluate(Segment s, std::int64_t tNs, SegmentState& out) const {
    const Track& tr = track(s);
    const double x = static_cast<double>(tNs) * 1e-9 / frameTimeS_;
    const int last = frameCount_ - 1;
    if (frameCount_ == 1 || x < 0 || x > last) {
        // Outside the clip the pose is held. The spline's value at an end knot is the end key
        // itself (see the phantom control points), so the pose is continuous there.
        const std::size_t k = (frameCount_ == 1 || x < 0) ? 0 : static_cast<std::size_t>(last);
        out.qWorldSegment = tr.keyQ[k];
        out.positionM = tr.keyP[k];
        out.velocityMps.setZero();
        out.accelerationMps2.setZero();
        out.omegaRadS.setZero();
        out.alphaRadS2.setZero();
        return;
    }
    const int i = std::clamp(static_cast<int>(std::floor(x)), 0, last - 1);
    const double u = x - i;
    const Basis k = cumulativeBasis(u);
    const double invDt = 1.0 / frameTimeS_;
    const double invDt2 = invDt * invDt;

    // Controls i-1 .. i+2 are padded indices i .. i+3.
    const auto m0 = static_cast<std::size_t>(i);
    Quatd r = tr.q[m0];
    Vec3d omega = Vec3d::Zero();
    Vec3d alpha = Vec3d::Zero();
    Vec3d pos = tr.p[m0];
    Vec3d vel = Vec3d::Zero();
    Vec3d acc = Vec3d::Zero();
    for (std::size_t j = 0; j < 3; ++j) {
        const Vec3d& w = tr.logQ[m0 + j + 1];
        const Quatd a = fromRotationVector<double>(w * k.b[j]);
        const Quatd aInv = a.conjugate();
        const Vec3d rate = w * (k.db[j] * invDt);
        const Vec3d omegaPrev = aInv * omega;
        alpha = aInv * alpha + omegaPrev.cross(rate) + w * (k.ddb[j] * invDt2);
        omega = omegaPrev + rate;
        r = r * a;
        const Vec3d& d = tr.dP[m0 + j + 1];
        pos += d * k.b[j];
        vel += d * (k.db[j] * invDt);
        acc += d * (k.ddb[j] * invDt2);
    }
    out.qWorldSegment = r.normalized();
    out.positionM = pos;
    out.velocityMps = vel;
    out.accelerationMps2 = acc;
    out.omegaRadS = omega;
    out.alphaRadS2 = alpha;
}

void Motion::evaluateAll(std::int64_t tNs, SuitState& out) const {
    for (const auto& info : board::kSegments) {
        evaluate(info.id, tNs, out[sz(info.id)]);
    }
}

}  // namespace caphub::board::sim
