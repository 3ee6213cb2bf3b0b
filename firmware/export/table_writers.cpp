// CSV and OpenSim .sto export (docs/exports.md).
#include <string>

#include <fmt/format.h>

#include "firmware/export/output_file.h"
#include "firmware/export/writers.h"
#include "fusion/body/kinematics.h"

namespace caphub::firmware::exporter {

WorldPose worldPose(const PoseTrack& track, const PoseFrame& frame) {
    body::Pose pose;
    pose.qLocal = frame.qLocal;
    body::worldFromLocal(pose);
    body::forwardKinematics(track.dimensions, frame.rootM, pose);
    WorldPose out{pose.qWorld, pose.positionM, {}};
    for (int s = 0; s < body::kSegmentCount; ++s) {
        const auto i = static_cast<std::size_t>(s);
        out.qSensor[i] =
            (out.q[i] * mountingAt(track, static_cast<board::Segment>(s), frame.tS)).normalized();
    }
    return out;
}

namespace {

// Keeps each segment's quaternion on the side of the previous frame's (q and -q are the same
// rotation), so that a column does not jump sign from one row to the next.
struct Continuity {
    std::array<Quatd, body::kSegmentCount> previous;
    std::array<Quatd, body::kSegmentCount> previousSensor;
    bool first = true;

    void apply(WorldPose& p) {
        keep(p.q, previous);
        keep(p.qSensor, previousSensor);
        first = false;
    }

    void keep(std::array<Quatd, body::kSegmentCount>& q,
              std::array<Quatd, body::kSegmentCount>& before) const {
        for (std::size_t s = 0; s < q.size(); ++s) {
            if (first) {
                q[s] = canonical(q[s]);
            } else if (q[s].coeffs().dot(before[s].coeffs()) < 0) {
                q[s].coeffs() *= -1;
            }
            before[s] = q[s];
        }
    }
};

template <typename Row>
Result<void> writeRows(const PoseTrack& track, const std::string& header, const std::string& path,
                       const ProgressFn& progress, Row row) {
    auto file = OutputFile::open(path);
    if (!file) {
        return file.error();
    }
    std::string out = header;
    Continuity continuity;
    for (std::size_t f = 0; f < track.frames.size(); ++f) {
        WorldPose p = worldPose(track, track.frames[f]);
        continuity.apply(p);
        row(out, track.frames[f], p);
        if (out.size() > (1u << 20)) {
            file->write(out);
            out.clear();
            if (progress) {
                progress(static_cast<double>(f + 1) / static_cast<double>(track.frames.size()));
            }
        }
    }
    file->write(out);
    if (progress) {
        progress(1.0);
    }
    return file->close();
}

}  // namespace

Result<void> writeCsv(const PoseTrack& track, const JointNames& names, double unitsPerM,
                      const std::string& path, const ProgressFn& progress) {
    std::string header = "t";
    for (const auto& n : names.segment) {
        for (const char* c : {"qw", "qx", "qy", "qz", "px", "py", "pz"}) {
            header += fmt::format(",{}_{}", n, c);
        }
    }
    header += ",not_measured\n";
    return writeRows(track, header, path, progress,
                     [unitsPerM, &names](std::string& out, const PoseFrame& f, const WorldPose& p) {
                         auto it = std::back_inserter(out);
                         fmt::format_to(it, "{:.6f}", f.tS);
                         for (std::size_t s = 0; s < p.q.size(); ++s) {
                             const Quatd& q = p.q[s];
                             const Vec3d x = p.positionM[s] * unitsPerM;
                             fmt::format_to(it, ",{:.7f},{:.7f},{:.7f},{:.7f},{:.6f},{:.6f},{:.6f}",
                                            q.w(), q.x(), q.y(), q.z(), x.x(), x.y(), x.z());
                         }
                         // The segments held (not measured) in this frame, space separated.
                         out += ',';
                         const char* separator = "";
                         for (std::size_t s = 0; s < names.segment.size(); ++s) {
                             if ((f.notMeasured >> s & 1u) != 0) {
                                 out += separator;
                                 out += names.segment[s];
                                 separator = " ";
                             }
                         }
                         out += '\n';
                     });
}

Result<std::vector<StoColumn>> stoColumns(const PoseTrack& track, const JointNames& names,
                                          StoOrientations which) {
    std::vector<StoColumn> columns;
    if (which == StoOrientations::Sensors) {
        if (track.sensors.empty()) {
            return Error{EINVAL,
                         "the recording carries no board file naming its sensors: export the "
                         "segments' orientations (--orientations segments)"};
        }
        for (const auto& s : track.sensors) {
            const auto i = static_cast<std::size_t>(s.segment);
            if (names.stoColumn[i]) {
                columns.push_back({names.segment[i] + "_imu", s.segment});
            }
        }
    } else {
        for (int s = 0; s < body::kSegmentCount; ++s) {
            const auto i = static_cast<std::size_t>(s);
            if (names.stoColumn[i]) {
                columns.push_back({names.segment[i] + "_imu", static_cast<board::Segment>(s)});
            }
        }
    }
    if (columns.empty()) {
        return Error{EINVAL,
                     fmt::format("no .sto column: no {} has a name in the '{}' set",
                                 which == StoOrientations::Sensors ? "sensor's segment" : "segment",
                                 names.setName)};
    }
    return columns;
}

Result<void> writeSto(const PoseTrack& track, const JointNames& names, StoOrientations which,
                      const std::string& path, const ProgressFn& progress) {
    auto columns = stoColumns(track, names, which);
    if (!columns) {
        return columns.error();
    }
    std::string header = fmt::format(
        "DataRate={:.6f}\nDataType=Quaternion\nversion=3\nOpenSimVersion=4.1\nendheader\ntime",
        track.rateHz);
    for (const auto& c : *columns) {
        header += "\t" + c.label;
    }
    header += '\n';
    const bool sensors = which == StoOrientations::Sensors;
    return writeRows(track, header, path, progress,
                     [&](std::string& out, const PoseFrame& f, const WorldPose& p) {
                         auto it = std::back_inserter(out);
                         fmt::format_to(it, "{:.6f}", f.tS);
                         for (const auto& c : *columns) {
                             const auto i = static_cast<std::size_t>(c.segment);
                             const Quatd& q = sensors ? p.qSensor[i] : p.q[i];
                             fmt::format_to(it, "\t{:.7f},{:.7f},{:.7f},{:.7f}", q.w(), q.x(),
                                            q.y(), q.z());
                         }
                         out += '\n';
                     });
}

}  // namespace caphub::firmware::exporter
