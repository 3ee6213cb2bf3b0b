// caphub import of caphub's own per-sensor streams in the BROAD layout (what `caphub sim --all`
// writes; docs/import.md): one .csv or .csv.gz per sensor into a .cap with the raw samples, and
// the orientations and poses of caphub's filter and body solver run on them (`reprocess`).
#pragma once

#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "board/segment.h"

namespace caphub::firmware {

struct BroadImportArgs {
    // Files, or folders whose .csv / .csv.gz files are taken (the ground truth skeleton.csv.gz
    // of `caphub sim --all` left out).
    std::vector<std::string> inputs;
    // From --map: sensor name = segment (overrides the files' comment lines), the height.
    std::map<std::string, board::Segment> segmentOf;
    std::optional<double> heightM;
    std::string mapPath;
    // The board the streams were simulated on (nominal mountings, positions, subject); empty:
    // the board named in the files' comment lines, when it can be found.
    std::string board;
    std::string output;
    std::string calibrate = "none";  // none, npose, tpose: the pose held at the start
    double poseRateHz = 60;
};

// Prints what it did, or the error (file:line:column for malformed input); the exit code.
int runBroadImport(const BroadImportArgs& a);

// The end of an imported recording's metadata, the same for every importer: the generated board
// (`boardName`, its text) and the sensors' names and segments.
std::string importedBoardMetadata(const std::string& boardName, const std::string& boardText,
                                  const std::vector<std::string>& names,
                                  const std::vector<board::Segment>& segments);

// The files an input list stands for: folders expanded into their .csv / .csv.gz files (sorted,
// without skeleton.csv[.gz]). Errors name the input.
struct BroadInputs {
    std::vector<std::filesystem::path> files;
    std::string error;
};
BroadInputs expandBroadInputs(const std::vector<std::string>& inputs);

// Whether the inputs look like BROAD-layout streams (a folder, or .csv / .csv.gz files).
bool looksLikeBroad(const std::vector<std::string>& inputs);

}  // namespace caphub::firmware
