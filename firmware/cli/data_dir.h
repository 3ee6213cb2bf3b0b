// Where caphub finds its shipped data (board files, meshes): $CAPHUB_DATA_DIR, the install
// prefix's share/caphub, or the source tree it was built from.
#pragma once

#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "board/board.h"

namespace caphub::firmware {

std::vector<std::filesystem::path> dataDirCandidates();

// The first candidate that holds a board/ folder.
std::optional<std::filesystem::path> dataDir();

// A board given as a path, or as the name of a shipped board ("sim-suit").
std::filesystem::path resolveBoardFile(const std::string& nameOrPath);

// Loads the board a command was given (a path or a shipped board's name); on errors prints each
// ("file:line:column: key: ...") to stderr and returns nothing. A board file a recording cannot
// hold (recordingProblem) is one of the errors.
std::optional<board::Board> loadCommandBoard(const std::string& nameOrPath);

// Why a recording of this board (and of this calibration file, when one is applied) cannot be
// written: the metadata it embeds them in holds at most 1 MiB (docs/recording-format.md). Empty
// when it fits.
std::string recordingProblem(const board::Board& b, const std::string& calibrationPath = {},
                             const std::string& calibrationText = {});
// The same for a command that needs a virtual suit (every bus simulated): a board with real
// buses is refused with a message that names the command ("caphub sim") and what it does.
std::optional<board::Board> loadVirtualSuitBoard(const std::string& nameOrPath,
                                                 std::string_view command, std::string_view needs);

// The walking clip shipped with the sources (tests/data/bvh), the virtual suit's default motion;
// empty when it cannot be found.
std::filesystem::path defaultMotionClip();

}  // namespace caphub::firmware
