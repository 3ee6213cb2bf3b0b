// The four export formats (docs/exports.md): each writes a PoseTrack to a file, reporting
// progress as a fraction of the frames written. A failed write is an error naming the file.
#pragma once

#include <string>

#include "firmware/export/joint_names.h"
#include "firmware/export/pose_track.h"
#include "hal/core/error.h"

namespace caphub::firmware::exporter {

struct BvhOptions {
    double unitsPerM = 1;         // 1: metres, 100: centimetres (offsets and positions)
    bool referenceFrame = false;  // prepend the reference pose (T-pose) as frame 0
};

// BVH: the 21 joints with End Sites at the chain tips, offsets from the track's dimensions,
// root channels Xposition Yposition Zposition Zrotation Xrotation Yrotation, the others
// Zrotation Xrotation Yrotation (R = Rz Rx Ry), "Frame Time" with 9 decimals.
Result<void> writeBvh(const PoseTrack& track, const JointNames& names, const BvhOptions& options,
                      const std::string& path, const ProgressFn& progress = {});

// CSV: t, then per segment its world orientation (qw, qx, qy, qz) and the world position of
// its origin (px, py, pz, in units).
Result<void> writeCsv(const PoseTrack& track, const JointNames& names, double unitsPerM,
                      const std::string& path, const ProgressFn& progress = {});

// Whose orientations a .sto table holds.
enum class StoOrientations {
    Sensors,   // each sensor's (segment orientation x its mounting): what OpenSense expects
    Segments,  // each segment's
};

// The .sto columns: one per sensor of the recording's board (board order) or per segment
// (segment order), each "<segment name>_imu", leaving out the segments names.stoColumn leaves
// out. Errors: sensors asked for and the recording names none; no column at all.
struct StoColumn {
    std::string label;
    board::Segment segment = board::Segment::Pelvis;
};
Result<std::vector<StoColumn>> stoColumns(const PoseTrack& track, const JointNames& names,
                                          StoOrientations which);

// OpenSim OpenSense orientation table (.sto): DataRate, DataType=Quaternion, version=3,
// OpenSimVersion, endheader, then "time" and the columns, each cell an orientation in the
// skeleton world frame as "w,x,y,z".
Result<void> writeSto(const PoseTrack& track, const JointNames& names, StoOrientations which,
                      const std::string& path, const ProgressFn& progress = {});

// Binary glTF 2.0: the default skin's mesh bound to a 21-joint node tree, and one animation
// (a rotation channel per joint, the root's translation; LINEAR; seconds from the first frame).
Result<void> writeGlb(const PoseTrack& track, const JointNames& names, const std::string& path,
                      const ProgressFn& progress = {});

// The world orientation of every segment and the world position of its origin, per frame.
struct WorldPose {
    std::array<Quatd, body::kSegmentCount> q;
    std::array<Vec3d, body::kSegmentCount> positionM;
    // The orientation of the sensor on each segment: q * mountingAt(segment, t).
    std::array<Quatd, body::kSegmentCount> qSensor;
};
WorldPose worldPose(const PoseTrack& track, const PoseFrame& frame);

}  // namespace caphub::firmware::exporter
