#include "firmware/export/partial_output.h"

#include <array>
#include <cerrno>
#include <csignal>
#include <cstdio>
#include <cstring>

#include <fcntl.h>
#include <fmt/format.h>
#include <unistd.h>

namespace caphub::firmware {

namespace {

// What the handler may touch: a fixed buffer and a flag (async-signal-safe).
std::array<char, 4096> gPartial{};
volatile std::sig_atomic_t gArmed = 0;

extern "C" void removePartialAndEnd(int sig) {
    if (gArmed != 0) {
        (void)::unlink(gPartial.data());
    }
    // Ends as the signal would have: the shell sees 128 + sig.
    std::signal(sig, SIG_DFL);
    (void)std::raise(sig);
}

}  // namespace

PartialOutput::PartialOutput(std::string partial) : partial_(std::move(partial)) {
    if (partial_.size() < gPartial.size()) {
        std::memcpy(gPartial.data(), partial_.c_str(), partial_.size() + 1);
        gArmed = 1;
    }
    struct sigaction ours {};
    ours.sa_handler = removePartialAndEnd;
    sigemptyset(&ours.sa_mask);
    for (std::size_t i = 0; i < kEnding.size(); ++i) {
        // A signal ignored when the program started (nohup, a background job of a script)
        // stays ignored.
        (void)::sigaction(kEnding[i], nullptr, &previous_[i]);
        if (previous_[i].sa_handler != SIG_IGN) {
            (void)::sigaction(kEnding[i], &ours, nullptr);
        }
    }
    struct sigaction ignore {};
    ignore.sa_handler = SIG_IGN;
    sigemptyset(&ignore.sa_mask);
    (void)::sigaction(SIGXFSZ, &ignore, &previous_[kEnding.size()]);
}

PartialOutput::~PartialOutput() {
    gArmed = 0;
    for (std::size_t i = 0; i < kEnding.size(); ++i) {
        (void)::sigaction(kEnding[i], &previous_[i], nullptr);
    }
    (void)::sigaction(SIGXFSZ, &previous_[kEnding.size()], nullptr);
    if (!published_) {
        (void)::unlink(partial_.c_str());
    }
}

Result<void> PartialOutput::publishNew(const std::string& target) {
    // renameat2 NOREPLACE where the filesystem has it, else a hard link (which fails on an
    // existing name too) and the part's removal.
    if (::renameat2(AT_FDCWD, partial_.c_str(), AT_FDCWD, target.c_str(), RENAME_NOREPLACE) != 0) {
        int err = errno;
        if (err == EINVAL || err == ENOSYS) {
            if (::link(partial_.c_str(), target.c_str()) == 0) {
                (void)::unlink(partial_.c_str());
                err = 0;
            } else {
                err = errno;
            }
        }
        if (err != 0) {
            return errnoError(err, fmt::format("rename '{}' to '{}'", partial_, target));
        }
    }
    published();
    return {};
}

void PartialOutput::published() {
    gArmed = 0;
    published_ = true;
}

}  // namespace caphub::firmware
