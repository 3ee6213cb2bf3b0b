// The body segments a sensor can be strapped to: caphub's 21 segments, named after H-Anim
// (ISO/IEC 19774). The skeleton that joins them (fusion/body) is documented in docs/skeleton.md.
#pragma once

#include <array>
#include <optional>
#include <string_view>

namespace caphub::board {

enum class Segment : int {
    Pelvis,
    L5,   // lumbar spine (abdomen)
    T12,  // thoracic spine (chest)
    C7,   // cervical spine (neck)
    Skull,
    LClavicle,
    LUpperarm,
    LForearm,
    LHand,
    RClavicle,
    RUpperarm,
    RForearm,
    RHand,
    LThigh,
    LCalf,
    LHindfoot,
    LMiddistal,  // toes
    RThigh,
    RCalf,
    RHindfoot,
    RMiddistal,
};

inline constexpr int kSegmentCount = 21;

struct SegmentInfo {
    Segment id;
    std::string_view name;         // H-Anim segment name, as written in board files
    std::string_view description;  // for people
};

inline constexpr std::array<SegmentInfo, kSegmentCount> kSegments = {{
    {Segment::Pelvis, "pelvis", "pelvis (sacrum, the root)"},
    {Segment::L5, "l5", "lumbar spine / abdomen"},
    {Segment::T12, "t12", "thoracic spine / chest"},
    {Segment::C7, "c7", "cervical spine / neck"},
    {Segment::Skull, "skull", "head"},
    {Segment::LClavicle, "l_clavicle", "left shoulder (clavicle)"},
    {Segment::LUpperarm, "l_upperarm", "left upper arm"},
    {Segment::LForearm, "l_forearm", "left forearm"},
    {Segment::LHand, "l_hand", "left hand"},
    {Segment::RClavicle, "r_clavicle", "right shoulder (clavicle)"},
    {Segment::RUpperarm, "r_upperarm", "right upper arm"},
    {Segment::RForearm, "r_forearm", "right forearm"},
    {Segment::RHand, "r_hand", "right hand"},
    {Segment::LThigh, "l_thigh", "left thigh"},
    {Segment::LCalf, "l_calf", "left shank"},
    {Segment::LHindfoot, "l_hindfoot", "left foot"},
    {Segment::LMiddistal, "l_middistal", "left toes"},
    {Segment::RThigh, "r_thigh", "right thigh"},
    {Segment::RCalf, "r_calf", "right shank"},
    {Segment::RHindfoot, "r_hindfoot", "right foot"},
    {Segment::RMiddistal, "r_middistal", "right toes"},
}};

constexpr const SegmentInfo& segmentInfo(Segment s) {
    return kSegments[static_cast<int>(s)];
}
constexpr std::string_view segmentName(Segment s) {
    return segmentInfo(s).name;
}

constexpr std::optional<Segment> findSegment(std::string_view name) {
    for (const auto& s : kSegments) {
        if (s.name == name) {
            return s.id;
        }
    }
    return std::nullopt;
}

}  // namespace caphub::board
