// BVH export (docs/exports.md, "BVH").
#include <string>
#include <vector>

#include <fmt/format.h>

#include "firmware/export/euler.h"
#include "firmware/export/output_file.h"
#include "firmware/export/writers.h"

namespace caphub::firmware::exporter {

namespace {

using board::Segment;
using body::idx;

// The End Site of a segment at the tip of a chain, from its origin; none for the others.
std::optional<Vec3d> endSiteOf(const body::Dimensions& d, int segment) {
    using body::EndEffector;
    auto site = [&](EndEffector e) { return d.endSiteM[static_cast<std::size_t>(e)]; };
    switch (static_cast<Segment>(segment)) {
        case Segment::Skull:
            return site(EndEffector::Head);
        case Segment::LHand:
            return site(EndEffector::LHand);
        case Segment::RHand:
            return site(EndEffector::RHand);
        // The toe tips are given from the hindfoot; the toe segment starts at the ball.
        case Segment::LMiddistal:
            return d.leftFootPointM[2] -
                   d.offsetM[static_cast<std::size_t>(idx(Segment::LMiddistal))];
        case Segment::RMiddistal:
            return d.rightFootPointM[2] -
                   d.offsetM[static_cast<std::size_t>(idx(Segment::RMiddistal))];
        default:
            return std::nullopt;
    }
}

struct Writer {
    const PoseTrack& track;
    const JointNames& names;
    double k;  // units per metre
    std::string out;
    std::vector<int> order;  // segments in the order their channels appear

    void indent(int depth) { out.append(static_cast<std::size_t>(depth), '\t'); }

    void offset(int depth, const Vec3d& m) {
        indent(depth);
        fmt::format_to(std::back_inserter(out), "OFFSET {:.6f} {:.6f} {:.6f}\n", m.x() * k,
                       m.y() * k, m.z() * k);
    }

    void joint(int segment, int depth) {
        const auto i = static_cast<std::size_t>(segment);
        order.push_back(segment);
        indent(depth);
        fmt::format_to(std::back_inserter(out), "{} {}\n", segment == 0 ? "ROOT" : "JOINT",
                       names.joint[i]);
        indent(depth);
        out += "{\n";
        offset(depth + 1, track.dimensions.offsetM[i]);
        indent(depth + 1);
        out += segment == 0 ? "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation "
                              "Yrotation\n"
                            : "CHANNELS 3 Zrotation Xrotation Yrotation\n";
        for (int child = segment + 1; child < body::kSegmentCount; ++child) {
            if (body::parentOf(child) == segment) {
                joint(child, depth + 1);
            }
        }
        if (auto site = endSiteOf(track.dimensions, segment)) {
            indent(depth + 1);
            out += "End Site\n";
            indent(depth + 1);
            out += "{\n";
            offset(depth + 2, *site);
            indent(depth + 1);
            out += "}\n";
        }
        indent(depth);
        out += "}\n";
    }

    void frame(const Vec3d& rootM, const std::array<Quatd, body::kSegmentCount>& qLocal) {
        fmt::format_to(std::back_inserter(out), "{:.6f} {:.6f} {:.6f}", rootM.x() * k,
                       rootM.y() * k, rootM.z() * k);
        for (int s : order) {
            const EulerZxyDeg e = eulerZxyDeg(qLocal[static_cast<std::size_t>(s)]);
            fmt::format_to(std::back_inserter(out), " {:.6f} {:.6f} {:.6f}", e.z, e.x, e.y);
        }
        out += '\n';
    }
};

}  // namespace

Result<void> writeBvh(const PoseTrack& track, const JointNames& names, const BvhOptions& options,
                      const std::string& path, const ProgressFn& progress) {
    auto file = OutputFile::open(path);
    if (!file) {
        return file.error();
    }
    Writer w{track, names, options.unitsPerM, {}, {}};
    w.out += "HIERARCHY\n";
    w.joint(0, 0);
    const std::size_t frames = track.frames.size() + (options.referenceFrame ? 1 : 0);
    fmt::format_to(std::back_inserter(w.out), "MOTION\nFrames: {}\nFrame Time: {:.9f}\n", frames,
                   1.0 / track.rateHz);
    if (options.referenceFrame) {
        std::array<Quatd, body::kSegmentCount> identity;
        identity.fill(Quatd::Identity());
        w.frame(track.dimensions.offsetM[0], identity);
    }
    for (std::size_t f = 0; f < track.frames.size(); ++f) {
        w.frame(track.frames[f].rootM, track.frames[f].qLocal);
        if (w.out.size() > (1u << 20)) {
            file->write(w.out);
            w.out.clear();
            if (progress) {
                progress(static_cast<double>(f + 1) / static_cast<double>(track.frames.size()));
            }
        }
    }
    file->write(w.out);
    if (progress) {
        progress(1.0);
    }
    return file->close();
}

}  // namespace caphub::firmware::exporter
