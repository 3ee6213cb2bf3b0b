#include "fusion/body/body_calibration.h"

#include <charconv>
#include <cmath>
#include <numbers>

#include <fmt/format.h>

namespace caphub::body {

namespace {

using S = Segment;

Quatd yaw(double rad) {
    return Quatd(Eigen::AngleAxisd(rad, Vec3d::UnitY()));
}

// A turn about ENU up (+z).
Quatd yawEnu(double rad) {
    return Quatd(Eigen::AngleAxisd(rad, Vec3d::UnitZ()));
}

bool isArm(Segment s) {
    switch (s) {
        case S::LUpperarm:
        case S::LForearm:
        case S::LHand:
        case S::RUpperarm:
        case S::RForearm:
        case S::RHand:
            return true;
        default:
            return false;
    }
}

Result<void> checkFrame(const SensorFrame& f, std::string_view what) {
    if ((f.mask & ((SegmentMask{1} << kSegmentCount) - 1)) == 0) {
        return Error{EINVAL,
                     fmt::format("{}: no sensor orientations: expected at least one", what)};
    }
    for (int i = 0; i < kSegmentCount; ++i) {
        if (!has(f.mask, i)) {
            continue;
        }
        const auto& q = f.qEnuSensor[static_cast<std::size_t>(i)];
        const double n = q.coeffs().norm();
        if (!q.coeffs().allFinite() || std::abs(n - 1.0) > 1e-3) {
            return Error{EINVAL, fmt::format("{}: orientation of the {} sensor (w {} x {} y {} z "
                                             "{}): expected a finite unit quaternion",
                                             what, board::segmentName(static_cast<Segment>(i)),
                                             q.w(), q.x(), q.y(), q.z())};
        }
    }
    return {};
}

// The subject's heading: circular mean over the sensors of the heading of their segment,
// estimated through the nominal mountings.
double estimateHeading(ReferencePoseKind pose, const SensorFrame& f, const CalibrationOptions& o) {
    const Quatd qWorldEnu = enuFromSkeletonWorld().conjugate();
    const SegmentMask from = (f.mask & o.headingFrom) != 0 ? f.mask & o.headingFrom : f.mask;
    double s = 0;
    double c = 0;
    for (int i = 0; i < kSegmentCount; ++i) {
        if (!has(from, i)) {
            continue;
        }
        const auto u = static_cast<std::size_t>(i);
        const Quatd seg = qWorldEnu * f.qEnuSensor[u] * o.nominalMounting[u].conjugate();
        const Quatd turn = seg * referenceOrientation(pose, static_cast<Segment>(i)).conjugate();
        const Vec3d z = turn * Vec3d::UnitZ();
        const double h = std::hypot(z.x(), z.z());
        if (h < 0.1) {
            continue;  // this sensor's forward axis is near vertical: no heading from it
        }
        s += z.x() / h;
        c += z.z() / h;
    }
    return std::atan2(s, c);
}

Quatd average(const Quatd& a, const Quatd& b) {
    Eigen::Vector4d sum = a.coeffs() + (a.coeffs().dot(b.coeffs()) < 0 ? -b.coeffs() : b.coeffs());
    return Quatd(sum.normalized());
}

// Rotation taking the sensor-frame pair (s1 primary, s2) onto the segment-frame pair (g1, g2).
Quatd triad(const Vec3d& s1, const Vec3d& s2, const Vec3d& g1, const Vec3d& g2) {
    auto basis = [](const Vec3d& a, const Vec3d& b) {
        Eigen::Matrix3d m;
        const Vec3d t1 = a.normalized();
        const Vec3d t2 = a.cross(b).normalized();
        m.col(0) = t1;
        m.col(1) = t2;
        m.col(2) = t1.cross(t2);
        return m;
    };
    const Eigen::Matrix3d r = basis(g1, g2) * basis(s1, s2).transpose();
    return Quatd(r).normalized();
}

}  // namespace

std::string_view toString(CalibrationMethod m) {
    switch (m) {
        case CalibrationMethod::None:
            return "none";
        case CalibrationMethod::TPose:
            return "tpose";
        case CalibrationMethod::NPose:
            return "npose";
        case CalibrationMethod::TPlusN:
            return "tpose+npose";
    }
    return "none";
}

Quatd enuFromSkeletonWorld() {
    Eigen::Matrix3d r;
    r << -1, 0, 0, 0, 0, 1, 0, 1, 0;
    return Quatd(r);
}

Quatd BodyCalibration::qEnuWorld() const {
    return enuFromSkeletonWorld() * yaw(headingRad);
}

Quatd referenceOrientation(ReferencePoseKind pose, Segment s) {
    if (pose == ReferencePoseKind::T || !isArm(s)) {
        return Quatd::Identity();
    }
    // N-pose: the arms hang, palms towards the thighs: a quarter turn about the forward axis,
    // down on either side (+X, the left arm, turns to -Y).
    const bool left = s == S::LUpperarm || s == S::LForearm || s == S::LHand;
    return Quatd(
        Eigen::AngleAxisd(left ? -std::numbers::pi / 2 : std::numbers::pi / 2, Vec3d::UnitZ()));
}

std::array<Quatd, kSegmentCount> referencePose(ReferencePoseKind pose) {
    std::array<Quatd, kSegmentCount> q;
    for (int i = 0; i < kSegmentCount; ++i) {
        q[static_cast<std::size_t>(i)] = referenceOrientation(pose, static_cast<Segment>(i));
    }
    return q;
}

Result<BodyCalibration> calibrateOnePose(ReferencePoseKind pose, const SensorFrame& frame,
                                         const CalibrationOptions& options, std::int64_t tNs) {
    if (auto ok = checkFrame(frame, pose == ReferencePoseKind::T ? "T-pose" : "N-pose"); !ok) {
        return ok.error();
    }
    BodyCalibration cal;
    cal.method = pose == ReferencePoseKind::T ? CalibrationMethod::TPose : CalibrationMethod::NPose;
    cal.tNs = tNs;
    cal.mask = frame.mask;
    cal.headingRad =
        options.headingRad ? *options.headingRad : estimateHeading(pose, frame, options);
    const Quatd qWorldEnu = cal.qEnuWorld().conjugate();
    for (int i = 0; i < kSegmentCount; ++i) {
        if (!has(frame.mask, i)) {
            continue;
        }
        const auto u = static_cast<std::size_t>(i);
        const Quatd left =
            referenceOrientation(pose, static_cast<Segment>(i)).conjugate() * qWorldEnu;
        const bool free = has(options.freeHeading, i);
        if (free || has(options.checkHeading, i)) {
            // The sensor's heading is unknown (or unchecked), its mounting nearly known: the turn
            // about up that brings the mounting closest to the nominal one. An unchecked heading
            // that a strap could explain is taken as right, the mounting measured.
            const double turn =
                closestHeadingTurn(left, frame.qEnuSensor[u], options.nominalMounting[u]);
            if (!free && std::abs(turn) <= options.plausibleTurnRad) {
                cal.mounting[u] = (left * frame.qEnuSensor[u]).normalized();
                continue;
            }
            cal.mounting[u] = (left * yawEnu(turn) * frame.qEnuSensor[u]).normalized();
            cal.freeHeading |= SegmentMask{1} << i;
            cal.nominalHeading |= SegmentMask{1} << i;
            cal.headingTurnRad[u] = turn;
            continue;
        }
        cal.mounting[u] = (left * frame.qEnuSensor[u]).normalized();
    }
    return cal;
}

double closestHeadingTurn(const Quatd& left, const Quatd& qEnuSensor, const Quatd& target) {
    // With h = turn / 2, Rz(turn) = cos h + sin h k (k the pure quaternion of ENU +z), and the
    // scalar part of target^-1 * left * Rz(turn) * q is a cos h + b sin h: its magnitude (the
    // cosine of half the angle between the rotations) is largest, sqrt(a^2 + b^2), at
    // h = atan2(b, a).
    const Quatd c = target.conjugate() * left;
    const Quatd k(0, 0, 0, 1);
    const double a = (c * qEnuSensor).w();
    const double b = (c * k * qEnuSensor).w();
    return std::remainder(2 * std::atan2(b, a), 2 * std::numbers::pi);
}

Result<BodyCalibration> calibrateTwoPose(const SensorFrame& tPose, const SensorFrame& nPose,
                                         const CalibrationOptions& options, std::int64_t tNs) {
    if (tPose.mask != nPose.mask) {
        return Error{EINVAL,
                     "T+N calibration: the two poses have different sensors: expected "
                     "the same set"};
    }
    auto t = calibrateOnePose(ReferencePoseKind::T, tPose, options, tNs);
    if (!t) {
        return t.error();
    }
    // The unchecked headings are checked in the T-pose; the N-pose takes them as it found them.
    CalibrationOptions nOptions = options;
    nOptions.freeHeading |= t->freeHeading & options.checkHeading;
    nOptions.checkHeading = 0;
    auto n = calibrateOnePose(ReferencePoseKind::N, nPose, nOptions, tNs);
    if (!n) {
        return n.error();
    }
    BodyCalibration cal = *t;
    cal.method = CalibrationMethod::TPlusN;
    const Vec3d upEnu = Vec3d::UnitZ();
    for (int i = 0; i < kSegmentCount; ++i) {
        if (!has(cal.mask, i)) {
            continue;
        }
        const auto u = static_cast<std::size_t>(i);
        const auto s = static_cast<Segment>(i);
        if (!isArm(s)) {
            cal.mounting[u] = average(t->mounting[u], n->mounting[u]);
            continue;
        }
        // Up as each pose's sensor sees it (gravity; no heading involved) and as the segment
        // frame has it in that pose.
        const Vec3d upT = tPose.qEnuSensor[u].conjugate() * upEnu;
        const Vec3d upN = nPose.qEnuSensor[u].conjugate() * upEnu;
        const Vec3d segUpT =
            referenceOrientation(ReferencePoseKind::T, s).conjugate() * Vec3d::UnitY();
        const Vec3d segUpN =
            referenceOrientation(ReferencePoseKind::N, s).conjugate() * Vec3d::UnitY();
        if (upT.cross(upN).norm() < std::sin(30.0 * std::numbers::pi / 180)) {
            return Error{EINVAL,
                         fmt::format("T+N calibration: the {} sensor turned by less than 30 deg "
                                     "between the poses: expected the arms to go from "
                                     "horizontal to hanging",
                                     board::segmentName(s))};
        }
        cal.mounting[u] = triad(upN, upT, segUpN, segUpT);
        if (has(nOptions.freeHeading, i)) {
            // Measured whole from the two gravity directions: the free heading's turn is the one
            // that brings the T-pose's orientation onto it, not a nominal heading.
            cal.nominalHeading &= ~(SegmentMask{1} << i);
            cal.headingTurnRad[u] = closestHeadingTurn(cal.qEnuWorld().conjugate(),
                                                       tPose.qEnuSensor[u], cal.mounting[u]);
        }
    }
    return cal;
}

void headingReset(BodyCalibration& cal, const Pose& current) {
    const Vec3d z = current.qWorld[0] * Vec3d::UnitZ();
    if (std::hypot(z.x(), z.z()) < 1e-6) {
        return;  // pelvis forward axis vertical (lying on the back): heading undefined
    }
    cal.headingRad += std::atan2(z.x(), z.z());
    cal.headingRad = std::remainder(cal.headingRad, 2 * std::numbers::pi);
}

std::string toText(const BodyCalibration& cal) {
    std::string out = fmt::format("method {}\ntime_ns {}\nheading_rad {:.17g}\n",
                                  toString(cal.method), cal.tNs, cal.headingRad);
    for (int i = 0; i < kSegmentCount; ++i) {
        if (!has(cal.mask, i)) {
            continue;
        }
        const Quatd& q = cal.mounting[static_cast<std::size_t>(i)];
        out += fmt::format("mounting {} {:.17g} {:.17g} {:.17g} {:.17g}\n",
                           board::segmentName(static_cast<Segment>(i)), q.w(), q.x(), q.y(), q.z());
    }
    // Only when a heading was free: a calibration without one reads as it always did.
    for (int i = 0; i < kSegmentCount; ++i) {
        if (!has(cal.freeHeading & cal.mask, i)) {
            continue;
        }
        out +=
            fmt::format("heading_free {} {:.17g} {}\n", board::segmentName(static_cast<Segment>(i)),
                        cal.headingTurnRad[static_cast<std::size_t>(i)],
                        has(cal.nominalHeading, i) ? "nominal-heading" : "measured");
    }
    return out;
}

Result<BodyCalibration> parseBodyCalibration(std::string_view text, std::string_view sourceName) {
    BodyCalibration cal;
    int lineNo = 0;
    bool haveMethod = false;
    std::array<int, kSegmentCount> freeLine{};  // where each heading_free line was
    auto fail = [&](std::string_view what) {
        return Error{EINVAL, fmt::format("{}:{}: {}", sourceName, lineNo, what)};
    };
    while (!text.empty()) {
        ++lineNo;
        const auto nl = text.find('\n');
        std::string_view line = text.substr(0, nl);
        text = nl == std::string_view::npos ? std::string_view{} : text.substr(nl + 1);
        if (!line.empty() && line.back() == '\r') {
            line.remove_suffix(1);
        }
        std::array<std::string_view, 6> tok{};
        int n = 0;
        for (std::size_t p = 0; p < line.size();) {
            while (p < line.size() && line[p] == ' ') {
                ++p;
            }
            const std::size_t b = p;
            while (p < line.size() && line[p] != ' ') {
                ++p;
            }
            if (p > b) {
                if (n == 6) {
                    return fail("too many fields: expected at most 6");
                }
                tok[static_cast<std::size_t>(n++)] = line.substr(b, p - b);
            }
        }
        if (n == 0 || tok[0].front() == '#') {
            continue;
        }
        auto number = [&](std::string_view t, double& v) {
            const auto r = std::from_chars(t.data(), t.data() + t.size(), v);
            return r.ec == std::errc() && r.ptr == t.data() + t.size() && std::isfinite(v);
        };
        auto unknownSegment = [&](std::string_view key) {
            return fail(
                fmt::format("{}: unknown segment '{}': expected an H-Anim segment name "
                            "such as l_upperarm",
                            key, tok[1]));
        };
        if (tok[0] == "method") {
            bool found = false;
            for (auto m : {CalibrationMethod::None, CalibrationMethod::TPose,
                           CalibrationMethod::NPose, CalibrationMethod::TPlusN}) {
                if (n == 2 && tok[1] == toString(m)) {
                    cal.method = m;
                    found = true;
                }
            }
            if (!found) {
                return fail("method: expected one of none, tpose, npose, tpose+npose");
            }
            haveMethod = true;
        } else if (tok[0] == "time_ns") {
            std::int64_t v = 0;
            const auto r = n == 2 ? std::from_chars(tok[1].data(), tok[1].data() + tok[1].size(), v)
                                  : std::from_chars_result{nullptr, std::errc::invalid_argument};
            if (r.ec != std::errc() || r.ptr != tok[1].data() + tok[1].size()) {
                return fail("time_ns: expected an integer");
            }
            cal.tNs = v;
        } else if (tok[0] == "heading_rad") {
            if (n != 2 || !number(tok[1], cal.headingRad)) {
                return fail("heading_rad: expected a number");
            }
        } else if (tok[0] == "mounting") {
            if (n != 6) {
                return fail("mounting: expected '<segment> w x y z'");
            }
            const auto seg = board::findSegment(tok[1]);
            if (!seg) {
                return unknownSegment("mounting");
            }
            std::array<double, 4> q{};
            for (std::size_t k = 0; k < 4; ++k) {
                if (!number(tok[k + 2], q[k])) {
                    return fail("mounting: expected four numbers w x y z");
                }
            }
            const Quatd qq = fromWxyz(q);
            if (std::abs(qq.norm() - 1.0) > 1e-6) {
                return fail("mounting: expected a unit quaternion");
            }
            cal.mounting[static_cast<std::size_t>(idx(*seg))] = qq;
            cal.mask |= bit(*seg);
        } else if (tok[0] == "heading_free") {
            if (n != 4) {
                return fail(
                    "heading_free: expected '<segment> <turn_rad> nominal-heading|measured'");
            }
            const auto seg = board::findSegment(tok[1]);
            if (!seg) {
                return unknownSegment("heading_free");
            }
            double turn = 0;
            if (!number(tok[2], turn)) {
                return fail("heading_free: expected a number of radians after the segment");
            }
            if (tok[3] != "nominal-heading" && tok[3] != "measured") {
                return fail("heading_free: expected nominal-heading or measured last");
            }
            const auto u = static_cast<std::size_t>(idx(*seg));
            cal.headingTurnRad[u] = turn;
            cal.freeHeading |= bit(*seg);
            if (tok[3] == "nominal-heading") {
                cal.nominalHeading |= bit(*seg);
            } else {
                cal.nominalHeading &= ~bit(*seg);
            }
            freeLine[u] = lineNo;
        } else {
            return fail(
                fmt::format("unknown key '{}': expected method, time_ns, heading_rad, "
                            "mounting or heading_free",
                            tok[0]));
        }
    }
    if (!haveMethod) {
        return Error{EINVAL, fmt::format("{}: no 'method' line: expected one", sourceName)};
    }
    for (int i = 0; i < kSegmentCount; ++i) {
        if (has(cal.freeHeading, i) && !has(cal.mask, i)) {
            return Error{EINVAL, fmt::format("{}:{}: heading_free {}: expected a mounting line "
                                             "for the segment too",
                                             sourceName, freeLine[static_cast<std::size_t>(i)],
                                             board::segmentName(static_cast<Segment>(i)))};
        }
    }
    return cal;
}

}  // namespace caphub::body
