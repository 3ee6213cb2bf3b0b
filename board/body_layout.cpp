#include "board/body_layout.h"

#include <algorithm>
#include <array>

#include <fmt/format.h>

namespace caphub::board {

namespace {

using S = Segment;

constexpr std::array<S, 17> kFull = {
    S::Pelvis, S::T12,       S::Skull,     S::LClavicle, S::LUpperarm, S::LForearm,
    S::LHand,  S::RClavicle, S::RUpperarm, S::RForearm,  S::RHand,     S::LThigh,
    S::LCalf,  S::LHindfoot, S::RThigh,    S::RCalf,     S::RHindfoot};
constexpr std::array<S, 10> kUpper10 = {S::Pelvis,    S::L5,       S::T12,   S::Skull,
                                        S::LUpperarm, S::LForearm, S::LHand, S::RUpperarm,
                                        S::RForearm,  S::RHand};
constexpr std::array<S, 7> kLower7 = {S::Pelvis, S::LThigh, S::LCalf,    S::LHindfoot,
                                      S::RThigh, S::RCalf,  S::RHindfoot};

bool contains(std::span<const Segment> set, Segment s) {
    return std::find(set.begin(), set.end(), s) != set.end();
}

std::string names(const std::vector<Segment>& v) {
    std::string out;
    for (Segment s : v) {
        out += (out.empty() ? "" : ", ") + std::string(segmentName(s));
    }
    return out;
}

}  // namespace

std::string_view toString(BodyLayout l) {
    switch (l) {
        case BodyLayout::Full:
            return "full";
        case BodyLayout::Upper10:
            return "upper10";
        case BodyLayout::Lower7:
            return "lower7";
        case BodyLayout::Sparse:
            return "sparse";
    }
    return "?";
}

std::optional<BodyLayout> parseBodyLayout(std::string_view name) {
    for (BodyLayout l :
         {BodyLayout::Full, BodyLayout::Upper10, BodyLayout::Lower7, BodyLayout::Sparse}) {
        if (toString(l) == name) {
            return l;
        }
    }
    return std::nullopt;
}

std::span<const Segment> layoutSegments(BodyLayout l) {
    switch (l) {
        case BodyLayout::Full:
            return kFull;
        case BodyLayout::Upper10:
            return kUpper10;
        case BodyLayout::Lower7:
            return kLower7;
        case BodyLayout::Sparse:
            break;
    }
    return {};
}

std::optional<BodyLayout> matchLayout(const std::vector<Segment>& segments) {
    if (std::find(segments.begin(), segments.end(), S::Pelvis) == segments.end()) {
        return std::nullopt;
    }
    for (BodyLayout l : {BodyLayout::Full, BodyLayout::Upper10, BodyLayout::Lower7}) {
        if (layoutMismatch(l, segments).empty()) {
            return l;
        }
    }
    return BodyLayout::Sparse;
}

std::string layoutMismatch(BodyLayout l, const std::vector<Segment>& segments) {
    if (std::find(segments.begin(), segments.end(), S::Pelvis) == segments.end()) {
        return fmt::format(
            "layout '{}' needs a sensor on the pelvis (segment = \"pelvis\"): the body is solved "
            "from the root out, and no sensor says where the pelvis faces",
            toString(l));
    }
    const std::span<const Segment> want = layoutSegments(l);
    if (want.empty()) {
        return {};
    }
    std::vector<Segment> missing;
    std::vector<Segment> extra;
    for (Segment s : want) {
        if (std::find(segments.begin(), segments.end(), s) == segments.end()) {
            missing.push_back(s);
        }
    }
    for (Segment s : segments) {
        if (!contains(want, s)) {
            extra.push_back(s);
        }
    }
    if (missing.empty() && extra.empty()) {
        return {};
    }
    std::string what;
    if (!missing.empty()) {
        what = "no sensor on " + names(missing);
    }
    if (!extra.empty()) {
        what += (what.empty() ? "" : "; ") + std::string("not part of it: ") + names(extra);
    }
    return fmt::format(
        "layout '{}' puts its {} sensors on {}: {} (layout = \"sparse\" takes any sensors that "
        "cover the pelvis)",
        toString(l), want.size(), names(std::vector<Segment>(want.begin(), want.end())), what);
}

}  // namespace caphub::board
