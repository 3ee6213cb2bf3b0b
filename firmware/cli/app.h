// The caphub command line: subcommands, their options, and the exit-code convention.
#pragma once

namespace caphub::firmware {

// 0: done; 1: the work failed at run time; 2: bad usage or a bad configuration (board file).
inline constexpr int kExitOk = 0;
inline constexpr int kExitRuntime = 1;
inline constexpr int kExitUsage = 2;

int runCli(int argc, char** argv);

}  // namespace caphub::firmware
