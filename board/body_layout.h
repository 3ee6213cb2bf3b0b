// Which of the body's segments a suit's sensors cover: the full 17-sensor suit, the 2009 paper's
// 10-sensor upper body, a 7-sensor lower body, or any other subset that covers the pelvis. A board
// file names its layout in [body] layout (docs/sparse.md); the loader checks the sensors against
// it.
#pragma once

#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "board/segment.h"

namespace caphub::board {

enum class BodyLayout : std::uint8_t {
    Full,     // 17: pelvis, t12, skull, both clavicles, upper arms, forearms, hands, thighs,
              // shanks and feet
    Upper10,  // the paper's: pelvis, l5, t12, skull, upper arms, forearms, hands
    Lower7,   // pelvis, thighs, shanks, feet
    Sparse,   // any subset that covers the pelvis
};

std::string_view toString(BodyLayout l);
std::optional<BodyLayout> parseBodyLayout(std::string_view name);

// The segments a named layout puts a sensor on (empty for Sparse: any).
std::span<const Segment> layoutSegments(BodyLayout l);

// The named layout whose segments are exactly these (in any order); Sparse when none is but the
// pelvis is among them; none without the pelvis.
std::optional<BodyLayout> matchLayout(const std::vector<Segment>& segments);

// What is wrong with these sensors for the layout, one sentence; empty when they fit: every
// layout needs the pelvis, a named one exactly its segments.
std::string layoutMismatch(BodyLayout l, const std::vector<Segment>& segments);

}  // namespace caphub::board
