// The subject a suit is worn by, as a board file's [subject] describes them: their height and
// any measured segment lengths. Part of the segment vocabulary (caphub_segments) so that the body
// (fusion/body) can build a skeleton from it without depending on the board loader.
#pragma once

#include <optional>
#include <utility>
#include <vector>

#include "board/segment.h"

namespace caphub::board {

struct SubjectConfig {
    double heightM = 1.75;
    std::optional<double> massKg;
    // Measured segment lengths, overriding those derived from the height.
    std::vector<std::pair<Segment, double>> segmentLengthsM;
};

}  // namespace caphub::board
