#include "firmware/stream/encoders.h"

#include <array>
#include <cstring>
#include <string>

#include <lo/lo.h>

#include "firmware/stream/unity_frame.h"
#include "fusion/body/skeleton.h"

namespace caphub::firmware {

namespace {

using body::idx;
using body::Segment;

constexpr std::array<std::string_view, body::kSegmentCount> kVmcBones = {
    "Hips",          "Spine",         "Chest",         "Neck",          "Head",
    "LeftShoulder",  "LeftUpperArm",  "LeftLowerArm",  "LeftHand",      "RightShoulder",
    "RightUpperArm", "RightLowerArm", "RightHand",     "LeftUpperLeg",  "LeftLowerLeg",
    "LeftFoot",      "LeftToes",      "RightUpperLeg", "RightLowerLeg", "RightFoot",
    "RightToes",
};

constexpr std::array<Segment, kVrChatTrackers> kVrChatSegments = {
    Segment::Pelvis, Segment::T12,   Segment::LHindfoot, Segment::RHindfoot,
    Segment::LCalf,  Segment::RCalf, Segment::LForearm,  Segment::RForearm,
};

// A bundle being built: liblo's, freed with its messages.
class Bundle {
public:
    Bundle() : b_(lo_bundle_new(LO_TT_IMMEDIATE)) {}
    ~Bundle() { lo_bundle_free_recursive(b_); }
    Bundle(const Bundle&) = delete;
    Bundle& operator=(const Bundle&) = delete;

    // Takes the message.
    void add(const char* path, lo_message m) {
        lo_bundle_add_message(b_, path, m);
        ++count_;
    }
    std::size_t length() const { return lo_bundle_length(b_); }
    int count() const { return count_; }
    void serialiseInto(std::vector<Datagram>& out) const {
        std::size_t size = lo_bundle_length(b_);
        Datagram d(size);
        lo_bundle_serialise(b_, d.data(), &size);
        d.resize(size);
        out.push_back(std::move(d));
    }

private:
    lo_bundle b_;
    int count_ = 0;
};

void addVector(lo_message m, const Eigen::Vector3f& v) {
    lo_message_add_float(m, v.x());
    lo_message_add_float(m, v.y());
    lo_message_add_float(m, v.z());
}

// Unity order: x, y, z, w.
void addQuaternionXyzw(lo_message m, const Eigen::Quaternionf& q) {
    lo_message_add_float(m, q.x());
    lo_message_add_float(m, q.y());
    lo_message_add_float(m, q.z());
    lo_message_add_float(m, q.w());
}

// A segment's origin in its parent's frame: constant for a rigid skeleton (the bone's offset).
Eigen::Vector3f localOffset(const PoseFrame& p, int s) {
    const int parent = body::parentOf(s);
    if (parent < 0) {
        return p.rootM;
    }
    const auto ps = static_cast<std::size_t>(parent);
    const auto ss = static_cast<std::size_t>(s);
    return p.world[ps].conjugate() * (p.positionM[ss] - p.positionM[ps]);
}

float secondsSince(Timestamp t, Timestamp start) {
    return static_cast<float>(toSeconds(t - start));
}

std::int64_t nanos(Timestamp t) {
    return t.time_since_epoch().count();
}

class VmcEncoder final : public StreamEncoder {
public:
    void encode(const PoseFrame& p, const EncodeContext& ctx, std::vector<Datagram>& out) override {
        auto bundle = std::make_unique<Bundle>();
        // The avatar's root stays at the receiver's origin; the pelvis carries the capture's
        // position and heading, as the Hips bone (docs/streams.md).
        lo_message root = lo_message_new();
        lo_message_add_string(root, "root");
        addVector(root, Eigen::Vector3f::Zero());
        addQuaternionXyzw(root, Eigen::Quaternionf::Identity());
        bundle->add("/VMC/Ext/Root/Pos", root);
        for (int s = 0; s < body::kSegmentCount; ++s) {
            const auto ss = static_cast<std::size_t>(s);
            lo_message m = lo_message_new();
            lo_message_add_string(m, kVmcBones[ss].data());
            addVector(m, unity::position(localOffset(p, s)));
            addQuaternionXyzw(m, unity::rotation(p.local[ss]));
            // A bone that would take the bundle over an Ethernet frame starts the next one.
            if (bundle->length() + lo_message_length(m, "/VMC/Ext/Bone/Pos") + 4 > kMaxDatagram) {
                bundle->serialiseInto(out);
                bundle = std::make_unique<Bundle>();
            }
            bundle->add("/VMC/Ext/Bone/Pos", m);
        }
        lo_message t = lo_message_new();
        lo_message_add_float(t, secondsSince(p.t, ctx.captureStart));
        lo_message ok = lo_message_new();
        // Loaded; calibration state (3 calibrated, 0 not); calibration mode (0 normal);
        // tracking status (1 every segment measured, 0 not).
        lo_message_add_int32(ok, 1);
        lo_message_add_int32(ok, p.bodyCalibrated ? 3 : 0);
        lo_message_add_int32(ok, 0);
        lo_message_add_int32(ok, p.notMeasured == 0 ? 1 : 0);
        if (bundle->length() + lo_message_length(t, "/VMC/Ext/T") +
                lo_message_length(ok, "/VMC/Ext/OK") + 8 >
            kMaxDatagram) {
            bundle->serialiseInto(out);
            bundle = std::make_unique<Bundle>();
        }
        bundle->add("/VMC/Ext/T", t);
        bundle->add("/VMC/Ext/OK", ok);
        bundle->serialiseInto(out);
    }
};

class VrChatEncoder final : public StreamEncoder {
public:
    VrChatEncoder() {
        for (int i = 0; i < kVrChatTrackers; ++i) {
            position_[static_cast<std::size_t>(i)] =
                "/tracking/trackers/" + std::to_string(i + 1) + "/position";
            rotation_[static_cast<std::size_t>(i)] =
                "/tracking/trackers/" + std::to_string(i + 1) + "/rotation";
        }
    }

    void encode(const PoseFrame& p, const EncodeContext&, std::vector<Datagram>& out) override {
        Bundle bundle;
        auto add = [&](const std::string& pos, const std::string& rot, int s) {
            const auto ss = static_cast<std::size_t>(s);
            lo_message mp = lo_message_new();
            addVector(mp, unity::position(p.positionM[ss]));
            bundle.add(pos.c_str(), mp);
            lo_message mr = lo_message_new();
            addVector(mr, unity::eulerZxyDeg(unity::rotation(p.world[ss])));
            bundle.add(rot.c_str(), mr);
        };
        for (int i = 0; i < kVrChatTrackers; ++i) {
            const auto ii = static_cast<std::size_t>(i);
            add(position_[ii], rotation_[ii], idx(kVrChatSegments[ii]));
        }
        add(headPosition_, headRotation_, vrChatHeadSegment());
        bundle.serialiseInto(out);
    }

private:
    std::array<std::string, kVrChatTrackers> position_;
    std::array<std::string, kVrChatTrackers> rotation_;
    std::string headPosition_ = "/tracking/trackers/head/position";
    std::string headRotation_ = "/tracking/trackers/head/rotation";
};

class CaphubEncoder final : public StreamEncoder {
public:
    void encode(const PoseFrame& p, const EncodeContext& ctx, std::vector<Datagram>& out) override {
        if (ctx.withSkeleton) {
            Bundle skeleton;
            lo_message m = lo_message_new();
            lo_message_add_int32(m, 1);  // the protocol's version
            lo_message_add_int32(m, body::kSegmentCount);
            for (int s = 0; s < body::kSegmentCount; ++s) {
                lo_message_add_string(m, board::kSegments[static_cast<std::size_t>(s)].name.data());
                lo_message_add_int32(m, body::parentOf(s));
                addVector(m, s == 0 ? Eigen::Vector3f(0, p.rootM.y(), 0) : localOffset(p, s));
            }
            skeleton.add("/caphub/skeleton", m);
            skeleton.serialiseInto(out);
        }
        Bundle bundle;
        lo_message frame = lo_message_new();
        lo_message_add_int64(frame, static_cast<std::int64_t>(p.serial));
        lo_message_add_int64(frame, nanos(p.t));
        lo_message_add_int64(frame, nanos(p.newestSampleT));
        lo_message_add_int64(frame, nanos(ctx.now));
        lo_message_add_int32(frame, static_cast<std::int32_t>(p.notMeasured));
        lo_message_add_int32(frame, p.bodyCalibrated ? 1 : 0);
        bundle.add("/caphub/frame", frame);
        lo_message root = lo_message_new();
        addVector(root, p.rootM);
        bundle.add("/caphub/root", root);
        lo_message local = lo_message_new();
        for (const auto& q : p.local) {
            lo_message_add_float(local, q.w());
            lo_message_add_float(local, q.x());
            lo_message_add_float(local, q.y());
            lo_message_add_float(local, q.z());
        }
        bundle.add("/caphub/local", local);
        bundle.serialiseInto(out);
    }
};

}  // namespace

std::string_view vmcBoneName(int segment) {
    return kVmcBones.at(static_cast<std::size_t>(segment));
}

int vrChatTrackerSegment(int tracker) {
    return idx(kVrChatSegments.at(static_cast<std::size_t>(tracker - 1)));
}

int vrChatHeadSegment() {
    return idx(Segment::Skull);
}

std::unique_ptr<StreamEncoder> makeEncoder(board::StreamKind kind) {
    switch (kind) {
        case board::StreamKind::Vmc:
            return std::make_unique<VmcEncoder>();
        case board::StreamKind::VrChat:
            return std::make_unique<VrChatEncoder>();
        case board::StreamKind::Caphub:
            return std::make_unique<CaphubEncoder>();
    }
    return nullptr;
}

}  // namespace caphub::firmware
