// Running the caphub program (and other commands) from tests, as a person would at a shell.
#pragma once

#include <array>
#include <cstdio>
#include <filesystem>
#include <string>

#include <sys/wait.h>
#include <unistd.h>

namespace caphub::testing {

struct CliRun {
    int exitCode = -1;
    std::string output;  // stdout and stderr
};

// A shell command line, its output and exit code.
inline CliRun shell(const std::string& command) {
    CliRun r;
    FILE* p = popen((command + " 2>&1").c_str(), "r");
    if (p == nullptr) {
        return r;
    }
    std::array<char, 4096> buf{};
    std::size_t n = 0;
    while ((n = fread(buf.data(), 1, buf.size(), p)) > 0) {
        r.output.append(buf.data(), n);
    }
    const int status = pclose(p);
    r.exitCode = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    return r;
}

// The caphub program under test (CAPHUB_BINARY: its path, through the emulator when
// cross-compiled) with these arguments.
inline CliRun caphub(const std::string& args) {
    return shell(std::string(CAPHUB_BINARY) + " " + args);
}

// An empty folder of this process's own: `base` + `prefix` + the process id (ctest runs the tests
// in parallel processes; each makes its files there).
inline std::string freshFolder(const std::string& base, const std::string& prefix) {
    const std::string p = base + prefix + std::to_string(::getpid());
    std::filesystem::remove_all(p);
    std::filesystem::create_directories(p);
    return p;
}

}  // namespace caphub::testing
