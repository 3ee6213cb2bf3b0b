// The caphub command line: subcommands, their options, and the exit-code convention.
#pragma once

#include <cerrno>

namespace caphub::firmware {

// One rule for every command (docs/user-guide.md, "Exit codes"):
// 0: done.
// 1: the work started and failed: hardware or a bus, a read or write failing part-way (a full
//    disk, an I/O error), a sensor failing its self-test; `status` when no hub runs.
// 2: the command cannot start with what it was given: bad options, and every file it was given
//    to read that is missing, not a file (a directory, a device), malformed, or without what the
//    command needs; an output it may not write (a directory, a device, a FIFO, a missing folder,
//    an existing recording); a board or calibration file a recording cannot hold.
inline constexpr int kExitOk = 0;
inline constexpr int kExitRuntime = 1;
inline constexpr int kExitUsage = 2;

// For a file the command was told to create: the disk failing (full, quota, I/O error) is the
// work failing (1); any other error is in the path it was given (2).
inline int exitCodeForCreate(int err) {
    return err == ENOSPC || err == EDQUOT || err == EIO || err == EFBIG ? kExitRuntime : kExitUsage;
}

int runCli(int argc, char** argv);

}  // namespace caphub::firmware
