// Registration of the caphub subcommands; each sets the exit code through the reference.
#pragma once

#include <CLI/CLI.hpp>

namespace caphub::firmware {

void addBoardsCommand(CLI::App& app, int& exitCode);
void addInfoCommands(CLI::App& app, int& exitCode);
void addRunCommand(CLI::App& app, int& exitCode);
void addFusionCommand(CLI::App& app, int& exitCode);
void addSimCommand(CLI::App& app, int& exitCode);
void addCalibrateCommand(CLI::App& app, int& exitCode);
void addSelftestCommand(CLI::App& app, int& exitCode);
void addReplayCommand(CLI::App& app, int& exitCode);
void addStatusCommand(CLI::App& app, int& exitCode);
void addExportCommand(CLI::App& app, int& exitCode);
void addEvaluateCommand(CLI::App& app, int& exitCode);
void addImportCommand(CLI::App& app, int& exitCode);
void addServeCommand(CLI::App& app, int& exitCode);
void addReprocessCommand(CLI::App& app, int& exitCode);

}  // namespace caphub::firmware
