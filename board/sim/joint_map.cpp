#include "board/sim/joint_map.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <sstream>

#include <fmt/format.h>
#include <toml++/toml.h>

#include "hal/core/input_file.h"

namespace caphub::board::sim {

using board::Segment;

namespace {

constexpr int idx(Segment s) {
    return static_cast<int>(s);
}

struct Entry {
    Segment segment;
    std::vector<std::string> joints;
};

JointMap makeMap(std::string name, std::optional<ReferencePose> reference, int firstFrame,
                 std::initializer_list<Entry> entries) {
    JointMap m;
    m.name = std::move(name);
    m.unitM = kCmuUnitM;
    m.reference = reference;
    m.firstFrame = firstFrame;
    for (const Entry& e : entries) {
        m.joints[static_cast<std::size_t>(idx(e.segment))] = e.joints;
    }
    return m;
}

// The CMU clips converted with MotionBuilder names. LHipJoint/RHipJoint and LeftShoulder's
// zero-rotation twins carry no motion of their own; the finger joints are left out because a
// hand segment must not take a finger's orientation. Frame 0 is the clip's synthetic T-pose:
// the reference, and not part of the motion (frame 1 is a different pose 8 ms later).
JointMap cmuMotionBuilder() {
    return makeMap("cmu-motionbuilder", ReferencePose{ReferencePose::Kind::Frame, 0}, 1,
                   {
                       {Segment::Pelvis, {"Hips"}},
                       {Segment::L5, {"LowerBack"}},
                       {Segment::T12, {"Spine", "Spine1"}},
                       {Segment::C7, {"Neck", "Neck1"}},
                       {Segment::Skull, {"Head"}},
                       {Segment::LClavicle, {"LeftShoulder"}},
                       {Segment::LUpperarm, {"LeftArm"}},
                       {Segment::LForearm, {"LeftForeArm"}},
                       {Segment::LHand, {"LeftHand", "LeftFingerBase"}},
                       {Segment::RClavicle, {"RightShoulder"}},
                       {Segment::RUpperarm, {"RightArm"}},
                       {Segment::RForearm, {"RightForeArm"}},
                       {Segment::RHand, {"RightHand", "RightFingerBase"}},
                       {Segment::LThigh, {"LeftUpLeg"}},
                       {Segment::LCalf, {"LeftLeg"}},
                       {Segment::LHindfoot, {"LeftFoot"}},
                       {Segment::LMiddistal, {"LeftToeBase"}},
                       {Segment::RThigh, {"RightUpLeg"}},
                       {Segment::RCalf, {"RightLeg"}},
                       {Segment::RHindfoot, {"RightFoot"}},
                       {Segment::RMiddistal, {"RightToeBase"}},
                   });
}

// The CMU clips converted with 3ds Max names. Their rest pose has the arms hanging down and
// frame 0 is captured motion, not a T-pose, so the reference is the synthetic T-pose.
JointMap cmu3dsMax() {
    return makeMap("cmu-3dsmax", ReferencePose{ReferencePose::Kind::TPose, 0}, 0,
                   {
                       {Segment::Pelvis, {"Hips"}},
                       {Segment::L5, {"lowerback"}},
                       {Segment::T12, {"Chest", "Chest2"}},
                       {Segment::C7, {"lowerneck", "Neck"}},
                       {Segment::Skull, {"Head"}},
                       {Segment::LClavicle, {"LeftCollar"}},
                       {Segment::LUpperarm, {"LeftShoulder"}},
                       {Segment::LForearm, {"LeftElbow"}},
                       {Segment::LHand, {"LeftWrist", "lhand"}},
                       {Segment::RClavicle, {"RightCollar"}},
                       {Segment::RUpperarm, {"RightShoulder"}},
                       {Segment::RForearm, {"RightElbow"}},
                       {Segment::RHand, {"RightWrist", "rhand"}},
                       {Segment::LThigh, {"LeftHip"}},
                       {Segment::LCalf, {"LeftKnee"}},
                       {Segment::LHindfoot, {"LeftAnkle"}},
                       {Segment::LMiddistal, {"LeftToe"}},
                       {Segment::RThigh, {"RightHip"}},
                       {Segment::RCalf, {"RightKnee"}},
                       {Segment::RHindfoot, {"RightAnkle"}},
                       {Segment::RMiddistal, {"RightToe"}},
                   });
}

// The CMU clips in the Daz-friendly release (root "hip", abdomen, chest, lCollar, lShldr,
// lThigh, lShin, ...): centimetres; frame 0 is the rest pose (a T-pose with the hands turned a
// little forward) and frames 1-5 blend from it into the captured motion at up to 3000 deg/s (the
// arms), so the motion starts at frame 6; lButtock/rButtock (hip to thigh) carry no motion of their
// own and stay unmapped; no toes. The reference is the synthetic T-pose, so that the forearm and
// foot bones lie along the T-pose's directions like the other presets'.
JointMap cmuDaz() {
    JointMap m = makeMap("cmu-daz", ReferencePose{ReferencePose::Kind::TPose, 0}, 6,
                         {
                             {Segment::Pelvis, {"hip"}},       {Segment::L5, {"abdomen"}},
                             {Segment::T12, {"chest"}},        {Segment::C7, {"neck"}},
                             {Segment::Skull, {"head"}},       {Segment::LClavicle, {"lCollar"}},
                             {Segment::LUpperarm, {"lShldr"}}, {Segment::LForearm, {"lForeArm"}},
                             {Segment::LHand, {"lHand"}},      {Segment::RClavicle, {"rCollar"}},
                             {Segment::RUpperarm, {"rShldr"}}, {Segment::RForearm, {"rForeArm"}},
                             {Segment::RHand, {"rHand"}},      {Segment::LThigh, {"lThigh"}},
                             {Segment::LCalf, {"lShin"}},      {Segment::LHindfoot, {"lFoot"}},
                             {Segment::RThigh, {"rThigh"}},    {Segment::RCalf, {"rShin"}},
                             {Segment::RHindfoot, {"rFoot"}},
                         });
    m.unitM = 0.01;
    return m;
}

std::string segmentNames() {
    std::string out;
    for (const auto& s : board::kSegments) {
        out += out.empty() ? "" : ", ";
        out += s.name;
    }
    return out;
}

// True when a is a strict ancestor of b in the clip's joint tree.
bool isAncestor(const BvhClip& clip, int a, int b) {
    for (int p = clip.joints[static_cast<std::size_t>(b)].parent; p >= 0;
         p = clip.joints[static_cast<std::size_t>(p)].parent) {
        if (p == a) {
            return true;
        }
    }
    return false;
}

int depth(const BvhClip& clip, int j) {
    int d = 0;
    for (int p = clip.joints[static_cast<std::size_t>(j)].parent; p >= 0;
         p = clip.joints[static_cast<std::size_t>(p)].parent) {
        ++d;
    }
    return d;
}

class MapFileParser {
public:
    explicit MapFileParser(std::string_view source) : source_(source) {}

    Result<JointMap> run(std::string_view text) {
        toml::table root;
        try {
            root = toml::parse(text, std::string(source_));
        } catch (const toml::parse_error& e) {
            error(e.source(), "(syntax)", fmt::format("TOML syntax error: {}", e.description()));
            return finish();
        }
        JointMap map;
        map.name = std::filesystem::path(source_).stem().string();
        for (auto&& [k, v] : root) {
            const std::string key(k.str());
            if (key == "name") {
                if (const auto* s = v.as_string()) {
                    map.name = s->get();
                } else {
                    error(v.source(), key, "expected a string");
                }
            } else if (key == "unit_m") {
                const std::optional<double> u = v.value<double>();
                if (!u || !(*u > 0) || !std::isfinite(*u)) {
                    error(v.source(), key, "expected a number of metres per BVH unit, > 0");
                } else {
                    map.unitM = *u;
                }
            } else if (key == "reference") {
                readReference(v, map);
            } else if (key == "first_frame") {
                const auto* i = v.as_integer();
                if (i == nullptr || i->get() < 0 || i->get() > std::numeric_limits<int>::max()) {
                    error(v.source(), key, "expected a frame number >= 0");
                } else {
                    map.firstFrame = static_cast<int>(i->get());
                }
            } else if (key == "segments") {
                if (const auto* t = v.as_table()) {
                    readSegments(*t, map);
                } else {
                    error(v.source(), key, "expected a table of segment = \"joint\" entries");
                }
            } else {
                error(k.source(), key,
                      "unknown key (expected one of: name, unit_m, reference, first_frame, "
                      "segments)");
            }
        }
        if (!root.contains("segments")) {
            error(root.source(), "segments", "missing required table [segments]");
        }
        if (!errors_.empty()) {
            return finish();
        }
        return map;
    }

private:
    void error(const toml::source_region& r, std::string_view key, std::string_view message) {
        errors_.push_back(
            fmt::format("{}:{}:{}: {}: {}", source_, r.begin.line, r.begin.column, key, message));
    }

    Error finish() {
        std::string msg;
        for (const auto& e : errors_) {
            msg += msg.empty() ? "" : "\n";
            msg += e;
        }
        return Error{EINVAL, msg};
    }

    void readReference(const toml::node& v, JointMap& map) {
        if (const auto* s = v.as_string()) {
            if (s->get() == "rest") {
                map.reference = ReferencePose{ReferencePose::Kind::Rest, 0};
                return;
            }
            if (s->get() == "tpose") {
                map.reference = ReferencePose{ReferencePose::Kind::TPose, 0};
                return;
            }
        } else if (const auto* i = v.as_integer()) {
            if (i->get() >= 0 && i->get() <= std::numeric_limits<int>::max()) {
                map.reference =
                    ReferencePose{ReferencePose::Kind::Frame, static_cast<int>(i->get())};
                return;
            }
        }
        error(v.source(), "reference", "expected \"rest\", \"tpose\" or a frame number >= 0");
    }

    void readSegments(const toml::table& t, JointMap& map) {
        for (auto&& [k, v] : t) {
            const std::string key = "segments." + std::string(k.str());
            const auto seg = board::findSegment(k.str());
            if (!seg) {
                error(k.source(), key,
                      fmt::format("unknown segment (expected one of: {})", segmentNames()));
                continue;
            }
            auto& joints = map.joints[static_cast<std::size_t>(idx(*seg))];
            if (const auto* s = v.as_string()) {
                if (s->get().empty()) {
                    error(v.source(), key, "expected a BVH joint name, found an empty string");
                } else {
                    joints.push_back(s->get());
                }
            } else if (const auto* a = v.as_array()) {
                if (a->empty()) {
                    error(v.source(), key, "expected at least one BVH joint name");
                }
                for (const toml::node& e : *a) {
                    const auto* es = e.as_string();
                    if (es == nullptr || es->get().empty()) {
                        error(e.source(), key, "expected BVH joint names (non-empty strings)");
                    } else {
                        joints.push_back(es->get());
                    }
                }
            } else {
                error(v.source(), key, "expected a BVH joint name or an array of them");
            }
        }
    }

    std::string_view source_;
    std::vector<std::string> errors_;
};

}  // namespace

std::span<const JointMap> builtInJointMaps() {
    static const std::array<JointMap, 3> kMaps = {cmuMotionBuilder(), cmu3dsMax(), cmuDaz()};
    return kMaps;
}

const JointMap* findBuiltInJointMap(std::string_view name) {
    for (const JointMap& m : builtInJointMaps()) {
        if (m.name == name) {
            return &m;
        }
    }
    return nullptr;
}

const JointMap* detectJointMap(const BvhClip& clip) {
    for (const JointMap& m : builtInJointMaps()) {
        bool all = true;
        for (const auto& joints : m.joints) {
            for (const auto& j : joints) {
                all = all && clip.findJoint(j) >= 0;
            }
        }
        if (all) {
            return &m;
        }
    }
    return nullptr;
}

Result<JointMap> parseJointMap(std::string_view text, std::string_view sourceName) {
    return MapFileParser(sourceName).run(text);
}

Result<JointMap> loadJointMap(const std::filesystem::path& path) {
    auto text = readInputFile(path);
    if (!text) {
        return text.error();
    }
    return parseJointMap(*text, path.string());
}

std::optional<Segment> parentSegment(Segment s) {
    switch (s) {
        case Segment::Pelvis:
            return std::nullopt;
        case Segment::L5:
        case Segment::LThigh:
        case Segment::RThigh:
            return Segment::Pelvis;
        case Segment::T12:
            return Segment::L5;
        case Segment::C7:
        case Segment::LClavicle:
        case Segment::RClavicle:
            return Segment::T12;
        case Segment::Skull:
            return Segment::C7;
        case Segment::LUpperarm:
            return Segment::LClavicle;
        case Segment::LForearm:
            return Segment::LUpperarm;
        case Segment::LHand:
            return Segment::LForearm;
        case Segment::RUpperarm:
            return Segment::RClavicle;
        case Segment::RForearm:
            return Segment::RUpperarm;
        case Segment::RHand:
            return Segment::RForearm;
        case Segment::LCalf:
            return Segment::LThigh;
        case Segment::LHindfoot:
            return Segment::LCalf;
        case Segment::LMiddistal:
            return Segment::LHindfoot;
        case Segment::RCalf:
            return Segment::RThigh;
        case Segment::RHindfoot:
            return Segment::RCalf;
        case Segment::RMiddistal:
            return Segment::RHindfoot;
    }
    return std::nullopt;
}

Result<SegmentBinding> bindJointMap(const JointMap& map, const BvhClip& clip) {
    std::vector<std::string> problems;
    SegmentBinding b;
    b.orientationJoint.fill(-1);
    b.positionJoint.fill(-1);
    std::vector<int> usedBy(clip.joints.size(), -1);

    for (const auto& info : board::kSegments) {
        const int s = idx(info.id);
        std::vector<int> chain;
        for (const std::string& name : map.joints[static_cast<std::size_t>(s)]) {
            const int j = clip.findJoint(name);
            if (j < 0) {
                problems.push_back(
                    fmt::format("segment {}: joint '{}' is not in the clip", info.name, name));
                continue;
            }
            for (std::size_t k = static_cast<std::size_t>(j) + 1; k < clip.joints.size(); ++k) {
                if (clip.joints[k].name == name) {
                    problems.push_back(fmt::format(
                        "segment {}: the clip has two joints named '{}' (lines {} and {})",
                        info.name, name, clip.joints[static_cast<std::size_t>(j)].line,
                        clip.joints[k].line));
                    break;
                }
            }
            int& owner = usedBy[static_cast<std::size_t>(j)];
            if (owner >= 0 && owner != s) {
                problems.push_back(
                    fmt::format("joint '{}' is mapped to both {} and {}", name,
                                board::kSegments[static_cast<std::size_t>(owner)].name, info.name));
            }
            owner = s;
            chain.push_back(j);
        }
        if (chain.empty()) {
            continue;
        }
        // Proximal (shallowest) first; then every joint must be an ancestor of the next.
        std::sort(chain.begin(), chain.end(),
                  [&](int a, int c) { return depth(clip, a) < depth(clip, c); });
        bool isChain = true;
        for (std::size_t k = 1; k < chain.size(); ++k) {
            isChain = isChain && isAncestor(clip, chain[k - 1], chain[k]);
        }
        if (!isChain) {
            problems.push_back(fmt::format(
                "segment {}: its joints are not on one chain of the skeleton (each must be an "
                "ancestor of the next)",
                info.name));
            continue;
        }
        b.positionJoint[static_cast<std::size_t>(s)] = chain.front();
        b.orientationJoint[static_cast<std::size_t>(s)] = chain.back();
    }
    if (b.orientationJoint[static_cast<std::size_t>(idx(Segment::Pelvis))] < 0 &&
        map.joints[static_cast<std::size_t>(idx(Segment::Pelvis))].empty()) {
        problems.push_back("segment pelvis: no joint mapped (the pelvis anchors the others)");
    }
    if (!problems.empty()) {
        std::string msg = fmt::format("joint map '{}' does not fit the clip:", map.name);
        for (const auto& p : problems) {
            msg += "\n  " + p;
        }
        return Error{EINVAL, msg};
    }
    for (const auto& info : board::kSegments) {
        Segment src = info.id;
        while (b.orientationJoint[static_cast<std::size_t>(idx(src))] < 0) {
            src = *parentSegment(src);  // the pelvis is mapped, so this ends
        }
        b.poseSource[static_cast<std::size_t>(idx(info.id))] = src;
    }
    return b;
}

}  // namespace caphub::board::sim
