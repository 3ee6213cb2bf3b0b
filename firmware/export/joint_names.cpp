#include "firmware/export/joint_names.h"

#include <fstream>
#include <map>
#include <sstream>

#include <fmt/format.h>
#include <toml++/toml.h>

#include "fusion/body/skeleton.h"
#include "hal/core/input_file.h"

namespace caphub::firmware::exporter {

namespace {

using S = board::Segment;

// Side-independent part of the CMU (MotionBuilder export) and Unity humanoid names, in
// segment order; the limb names get "Left"/"Right" prefixed.
constexpr std::array<const char*, board::kSegmentCount> kCmu = {
    "Hips",      "LowerBack",   "Spine",       "Neck",          "Head",        "LeftShoulder",
    "LeftArm",   "LeftForeArm", "LeftHand",    "RightShoulder", "RightArm",    "RightForeArm",
    "RightHand", "LeftUpLeg",   "LeftLeg",     "LeftFoot",      "LeftToeBase", "RightUpLeg",
    "RightLeg",  "RightFoot",   "RightToeBase"};
constexpr std::array<const char*, board::kSegmentCount> kUnity = {
    "Hips",          "Spine",         "Chest",         "Neck",          "Head",
    "LeftShoulder",  "LeftUpperArm",  "LeftLowerArm",  "LeftHand",      "RightShoulder",
    "RightUpperArm", "RightLowerArm", "RightHand",     "LeftUpperLeg",  "LeftLowerLeg",
    "LeftFoot",      "LeftToes",      "RightUpperLeg", "RightLowerLeg", "RightFoot",
    "RightToes"};

JointNames hanim() {
    JointNames n;
    n.setName = "hanim";
    for (int s = 0; s < board::kSegmentCount; ++s) {
        const auto i = static_cast<std::size_t>(s);
        n.joint[i] = std::string(body::joints()[i].name);
        n.segment[i] = std::string(board::kSegments[i].name);
    }
    return n;
}

JointNames openSim() {
    JointNames n = hanim();
    n.setName = "opensim";
    n.stoOnly = true;
    for (int s = 0; s < board::kSegmentCount; ++s) {
        const auto i = static_cast<std::size_t>(s);
        const std::string_view body = openSimBody(static_cast<board::Segment>(s));
        n.stoColumn[i] = !body.empty();
        if (!body.empty()) {
            n.segment[i] = std::string(body);
        }
    }
    return n;
}

JointNames fromTable(const char* setName, const std::array<const char*, board::kSegmentCount>& t) {
    JointNames n;
    n.setName = setName;
    for (std::size_t i = 0; i < t.size(); ++i) {
        n.joint[i] = t[i];
        n.segment[i] = t[i];
    }
    return n;
}

// Why a name cannot be used, or empty when it can.
std::string nameProblem(std::string_view name) {
    if (name.empty()) {
        return "an empty name";
    }
    for (char c : name) {
        const auto u = static_cast<unsigned char>(c);
        if (u <= 0x20 || u == 0x7f || c == '{' || c == '}' || c == '"' || c == '#' || c == ',') {
            return fmt::format(
                "the name \"{}\" has a space, a control character or one of {{}}\"#,", name);
        }
    }
    return {};
}

}  // namespace

std::string_view openSimBody(board::Segment s) {
    switch (s) {
        case S::Pelvis:
            return "pelvis";
        case S::T12:
            return "torso";
        case S::LUpperarm:
            return "humerus_l";
        case S::LForearm:
            return "radius_l";
        case S::LHand:
            return "hand_l";
        case S::RUpperarm:
            return "humerus_r";
        case S::RForearm:
            return "radius_r";
        case S::RHand:
            return "hand_r";
        case S::LThigh:
            return "femur_l";
        case S::LCalf:
            return "tibia_l";
        case S::LHindfoot:
            return "calcn_l";
        case S::LMiddistal:
            return "toes_l";
        case S::RThigh:
            return "femur_r";
        case S::RCalf:
            return "tibia_r";
        case S::RHindfoot:
            return "calcn_r";
        case S::RMiddistal:
            return "toes_r";
        case S::L5:
        case S::C7:
        case S::Skull:
        case S::LClavicle:
        case S::RClavicle:
            return {};
    }
    return {};
}

Result<JointNames> parseJointNames(std::string_view text, const std::string& sourceName) {
    toml::table root;
    try {
        root = toml::parse(text, sourceName);
    } catch (const toml::parse_error& e) {
        return Error{EINVAL,
                     fmt::format("{}:{}: {}", sourceName, e.source().begin.line, e.description())};
    }
    JointNames names = hanim();
    names.setName = sourceName;
    std::map<std::string, std::pair<std::string, int>> used;  // name -> (segment, line)
    std::array<int, board::kSegmentCount> lineOf{};
    for (const auto& [key, node] : root) {
        const int line = static_cast<int>(node.source().begin.line);
        const auto segment = board::findSegment(key.str());
        if (!segment) {
            return Error{EINVAL, fmt::format("{}:{}: '{}' is not a segment: expected one of "
                                             "pelvis, l5, t12, ... (board/segment.h)",
                                             sourceName, line, key.str())};
        }
        const auto* value = node.as_string();
        if (value == nullptr) {
            return Error{EINVAL, fmt::format("{}:{}: {}: expected a quoted name", sourceName, line,
                                             key.str())};
        }
        const std::string name = value->get();
        if (auto problem = nameProblem(name); !problem.empty()) {
            return Error{EINVAL, fmt::format("{}:{}: {}: {}: expected a name without them",
                                             sourceName, line, key.str(), problem)};
        }
        const auto i = static_cast<std::size_t>(*segment);
        names.joint[i] = name;
        names.segment[i] = name;
        lineOf[i] = line;
    }
    // Unique among the joint names and among the segment names (H-Anim defaults included).
    for (const auto* list : {&names.joint, &names.segment}) {
        used.clear();
        for (int s = 0; s < board::kSegmentCount; ++s) {
            const auto i = static_cast<std::size_t>(s);
            const std::string& name = (*list)[i];
            auto [it, fresh] =
                used.emplace(name, std::pair{std::string(board::kSegments[i].name), lineOf[i]});
            if (!fresh) {
                const int line = lineOf[i] != 0 ? lineOf[i] : it->second.second;
                return Error{EINVAL,
                             fmt::format("{}:{}: the name \"{}\" is given to both {} and {}: "
                                         "expected unique names",
                                         sourceName, line, name, it->second.first,
                                         board::kSegments[i].name)};
            }
        }
    }
    return names;
}

Result<JointNames> jointNamesFor(std::string_view spec) {
    if (spec == "hanim") {
        return hanim();
    }
    if (spec == "cmu") {
        return fromTable("cmu", kCmu);
    }
    if (spec == "unity") {
        return fromTable("unity", kUnity);
    }
    if (spec == "opensim") {
        return openSim();
    }
    const std::string path(spec);
    auto text = readInputFile(path);
    if (!text) {
        return Error{
            text.error().code,
            fmt::format("--names '{}': expected hanim, cmu, unity, opensim or a readable map file "
                        "({})",
                        path, text.error().message)};
    }
    return parseJointNames(*text, path);
}

}  // namespace caphub::firmware::exporter
