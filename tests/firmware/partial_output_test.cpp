// What an offline command writes takes its name only when complete: a signal that ends the
// program removes the part first, a write past the file size limit is an error instead of a
// kill, and publishing never replaces an existing file.
#include "firmware/export/partial_output.h"

#include <cerrno>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

namespace caphub::firmware {
namespace {

namespace fs = std::filesystem;

std::string temp(const std::string& name) {
    const std::string d = ::testing::TempDir() + "caphub_partial_" + std::to_string(::getpid());
    fs::create_directories(d);
    return d + "/" + name;
}

// Runs `body` in a child process; its wait status.
template <typename Body>
int inChild(Body body) {
    const pid_t pid = ::fork();
    if (pid == 0) {
        body();
        ::_exit(0);
    }
    int status = 0;
    ::waitpid(pid, &status, 0);
    return status;
}

TEST(PartialOutput, ASignalThatEndsTheProgramRemovesThePartFirst) {
    for (const int sig : {SIGTERM, SIGINT, SIGHUP}) {
        const std::string part = temp("out.cap.part");
        fs::remove(part);
        const int status = inChild([&] {
            std::signal(sig, SIG_DFL);  // as a program started from a shell has it
            PartialOutput guard(part);
            std::ofstream(part) << "half a recording";
            std::raise(sig);
            ::_exit(3);  // not reached: the signal ends the program
        });
        EXPECT_TRUE(WIFSIGNALED(status)) << "signal " << sig;
        EXPECT_EQ(WTERMSIG(status), sig);
        EXPECT_FALSE(fs::exists(part)) << "signal " << sig;
    }
}

TEST(PartialOutput, ASignalIgnoredWhenItStartedStaysIgnored) {
    const std::string part = temp("ignored.cap.part");
    fs::remove(part);
    const int status = inChild([&] {
        std::signal(SIGINT, SIG_IGN);  // nohup, or a background job of a script
        PartialOutput guard(part);
        std::ofstream(part) << "a recording";
        std::raise(SIGINT);
        guard.published();
        ::_exit(0);
    });
    EXPECT_TRUE(WIFEXITED(status));
    EXPECT_EQ(WEXITSTATUS(status), 0);
    EXPECT_TRUE(fs::exists(part));
}

TEST(PartialOutput, AWritePastTheFileSizeLimitFailsInsteadOfKilling) {
    const std::string part = temp("big.csv.part");
    fs::remove(part);
    const int status = inChild([&] {
        rlimit limit{4096, 4096};
        ::setrlimit(RLIMIT_FSIZE, &limit);
        int code = 8;
        {
            PartialOutput guard(part);
            std::FILE* f = std::fopen(part.c_str(), "w");
            const std::string block(8192, 'x');
            const bool failed =
                std::fwrite(block.data(), 1, block.size(), f) < block.size() || std::fflush(f) != 0;
            code = failed && errno == EFBIG ? 7 : 8;
            std::fclose(f);
        }  // the failed output is not published: the guard removes it
        ::_exit(code);
    });
    ASSERT_TRUE(WIFEXITED(status)) << "killed by signal " << WTERMSIG(status);
    EXPECT_EQ(WEXITSTATUS(status), 7);
    EXPECT_FALSE(fs::exists(part));  // not published: the guard removed it
}

TEST(PartialOutput, PublishingNeverReplacesAnExistingFile) {
    const std::string part = temp("new.cap.part");
    const std::string target = temp("new.cap");
    fs::remove(target);
    {
        PartialOutput guard(part);
        std::ofstream(part) << "complete";
        ASSERT_TRUE(guard.publishNew(target).ok());
    }
    EXPECT_TRUE(fs::exists(target));
    EXPECT_FALSE(fs::exists(part));
    {
        PartialOutput guard(part);
        std::ofstream(part) << "another";
        auto again = guard.publishNew(target);
        ASSERT_FALSE(again.ok());
        EXPECT_EQ(again.error().code, EEXIST);
    }
    std::ifstream in(target);
    std::string text;
    std::getline(in, text);
    EXPECT_EQ(text, "complete");
    EXPECT_FALSE(fs::exists(part));  // the unpublished part is removed with its guard
}

}  // namespace
}  // namespace caphub::firmware
