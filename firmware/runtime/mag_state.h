// The online magnetometer estimates of a capture kept between runs (docs/fusion.md,
// "Persistence"): what a sensor whose magnetometer the calibration file does not correct has
// learnt of its hard and soft iron, so that the next start is magnetic from its first sample.
// The file: '#' comments, then one line per sensor, its name and formatHardIronState's numbers.
#pragma once

#include <cstdint>
#include <filesystem>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "board/board.h"
#include "firmware/runtime/fusion_stage.h"
#include "firmware/runtime/latest_writer.h"
#include "firmware/runtime/pipeline.h"
#include "fusion/calibration/online_hard_iron.h"
#include "hal/core/error.h"
#include "hal/core/time.h"

namespace caphub::firmware {

using MagStates = std::vector<std::optional<fusion::OnlineHardIronState>>;

// Reads `path` into the fusion stage's estimators (before the capture starts). A missing file is
// a first run: nothing is loaded. Every error names the file and line; a directory, an
// unreadable file, a line that is not a state or a sensor the board does not have is an error,
// and then nothing is loaded.
Result<void> loadMagState(const std::filesystem::path& path, const board::Board& board,
                          FusionStage& fusion);

// Whether `path` may be kept as a state file: missing, empty, or beginning with the comment line
// magStateText writes. Anything else (a file given by mistake) would be replaced by the first
// save: "'P' is not a magnetometer state file (...): it is not replaced".
Result<void> checkMagStateFile(const std::filesystem::path& path);

// Every sensor's estimator state now (nullopt: a calibrated magnetometer, or none).
MagStates magStates(const board::Board& board, const FusionStage& fusion);

// The file's text for those states.
std::string magStateText(const board::Board& board, const MagStates& states);

// Replaces `path` with `text` atomically: written beside it, flushed to the disk, renamed. Only a
// regular file (or nothing) is replaced.
Result<void> writeMagStateFile(const std::filesystem::path& path, const std::string& text);

// Saves the estimators every `every` of the capture's clock and at its end. The pipeline thread
// only copies the states; a writer thread of the stage's own writes the file.
class MagStateStage final : public PipelineStage {
public:
    MagStateStage(const board::Board& board, const FusionStage& fusion, std::filesystem::path path,
                  Duration every);
    ~MagStateStage() override;
    MagStateStage(const MagStateStage&) = delete;
    MagStateStage& operator=(const MagStateStage&) = delete;

    void onSample(const SensorSample&) override {}
    void onEvent(const RuntimeEvent&) override {}
    void onTick(Timestamp now) override;
    // The last save, waited for.
    void finish(Timestamp now) override;

    // Saves handed to the writer so far (every `every` and the end); files written so far (a save
    // that comes while the file is being written replaces the one pending, so under load fewer
    // than the saves, the last always); and why the last write failed (empty: it did not). Any
    // thread.
    std::uint64_t saves() const { return writer_.published(); }
    std::uint64_t written() const;
    std::string error() const;

private:
    void write(const MagStates& states);

    const board::Board& board_;
    const FusionStage& fusion_;
    std::filesystem::path path_;
    Duration every_;
    std::optional<Timestamp> last_;  // the pipeline thread's
    // The writer thread's results.
    mutable std::mutex resultMutex_;
    std::uint64_t written_ = 0;
    std::string error_;
    LatestWriter<MagStates> writer_;  // last: its thread writes with the members above
};

}  // namespace caphub::firmware
