// Loads and validates a board (suit) file. Every problem is reported, not just the first, each
// with the file, line, column and key it concerns and what was expected there.
#pragma once

#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "board/board.h"
#include "board/bus_budget.h"

namespace caphub::board {

struct Diagnostic {
    Diagnostic(SourceLocation where, std::string key, std::string message);

    SourceLocation where;
    std::string key;  // dotted path in the file, e.g. "sensor[3].odr_hz"
    std::string message;

    // "board/suit.toml:42:10: sensor[3].odr_hz: ..."
    std::string str() const;
};

struct LoadResult {
    std::optional<Board> board;  // set when there are no errors
    std::vector<BusLoad> loads;  // the bus budget, also computed for a plan that failed it
    std::vector<Diagnostic> errors;
    std::vector<Diagnostic> warnings;

    bool ok() const { return board.has_value(); }
};

// A recording embeds the board file in its metadata (at most 1 MiB, docs/recording-format.md):
// a larger board file is refused unread. The copy embedded is escaped (a newline takes two
// bytes), so a file under this size can still be too large: `caphub boards validate` and
// `caphub run` check the metadata it makes.
inline constexpr std::size_t kMaxBoardFileBytes = 1u << 20;

LoadResult loadBoardFile(const std::filesystem::path& path);

// A board's and a sensor's name name files (a recording is TIMESTAMP-BOARD.cap, `caphub sim
// --all` writes SENSOR.csv.gz), keys of the calibration and magnetometer state files and the web
// API's paths: 1 to 64 letters, digits, '_', '-' and '.', not starting with '.' or '-'. Empty
// when `name` is one, else what is wrong with it ("sensor name '../x': expected ...").
std::string nameProblem(std::string_view what, std::string_view name);

// The same from text; sourceName stands for the file name in diagnostics.
LoadResult loadBoardText(std::string_view text, const std::string& sourceName);

}  // namespace caphub::board
