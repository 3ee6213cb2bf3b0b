#include "firmware/serve/auth.h"

#include <cstring>
#include <fstream>
#include <sstream>

#include <arpa/inet.h>
#include <fcntl.h>
#include <fmt/format.h>
#include <sodium.h>
#include <sys/stat.h>
#include <unistd.h>

namespace caphub::firmware::serve {

namespace fs = std::filesystem;

namespace {

bool sodiumReady() {
    static const bool ok = sodium_init() >= 0;
    return ok;
}

}  // namespace

fs::path passwordFile(const fs::path& stateDir) {
    return stateDir / "web-password";
}

bool hasPassword(const fs::path& stateDir) {
    std::error_code ec;
    return fs::is_regular_file(passwordFile(stateDir), ec) &&
           fs::file_size(passwordFile(stateDir), ec) > 0;
}

Result<void> setPassword(const fs::path& stateDir, const std::string& password) {
    // The hash takes a C string: the password would end at the NUL.
    if (password.find('\0') != std::string::npos) {
        return Error{EINVAL, "the password cannot contain a NUL byte"};
    }
    if (password.size() < 8 || password.size() > 256) {
        return Error{EINVAL, fmt::format("the password must have 8 to 256 characters ({} given)",
                                         password.size())};
    }
    if (!sodiumReady()) {
        return Error{EIO, "libsodium could not be initialised"};
    }
    char hash[crypto_pwhash_STRBYTES];
    if (crypto_pwhash_str(hash, password.data(), password.size(),
                          crypto_pwhash_OPSLIMIT_INTERACTIVE,
                          crypto_pwhash_MEMLIMIT_INTERACTIVE) != 0) {
        return Error{ENOMEM, "hashing the password ran out of memory"};
    }
    std::error_code ec;
    fs::create_directories(stateDir, ec);
    if (ec) {
        return Error{ec.value(),
                     fmt::format("cannot create '{}': {}", stateDir.string(), ec.message())};
    }
    // Written beside, then renamed: a reader never sees half a hash; only the owner reads it.
    const fs::path file = passwordFile(stateDir);
    const fs::path tmp = fs::path(file.string() + ".tmp");
    const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
    if (fd < 0) {
        const int e = errno;
        return Error{e, fmt::format("cannot write '{}': {}", tmp.string(), std::strerror(e))};
    }
    const std::string text = std::string(hash) + "\n";
    const bool written =
        ::write(fd, text.data(), text.size()) == static_cast<ssize_t>(text.size()) &&
        ::fsync(fd) == 0;
    ::close(fd);
    if (!written) {
        fs::remove(tmp, ec);
        return Error{EIO, fmt::format("cannot write '{}'", tmp.string())};
    }
    fs::rename(tmp, file, ec);
    if (ec) {
        return Error{ec.value(),
                     fmt::format("cannot replace '{}': {}", file.string(), ec.message())};
    }
    return {};
}

bool checkPassword(const fs::path& stateDir, const std::string& password) {
    if (!sodiumReady()) {
        return false;
    }
    std::ifstream in(passwordFile(stateDir));
    std::string hash;
    if (!std::getline(in, hash) || hash.empty() || hash.size() >= crypto_pwhash_STRBYTES) {
        return false;
    }
    return crypto_pwhash_str_verify(hash.c_str(), password.data(), password.size()) == 0;
}

bool isLoopbackHost(const std::string& host) {
    // An address, parsed: a prefix test took "127.0.0.1.evil.example" (a name any DNS can point
    // at the hub: a rebound page) for this machine.
    in_addr v4{};
    if (::inet_pton(AF_INET, host.c_str(), &v4) == 1) {
        return (ntohl(v4.s_addr) >> 24) == 127;
    }
    in6_addr v6{};
    if (::inet_pton(AF_INET6, host.c_str(), &v6) == 1) {
        return IN6_IS_ADDR_LOOPBACK(&v6);
    }
    return host == "localhost";
}

std::string randomToken() {
    (void)sodiumReady();
    unsigned char bytes[32];
    randombytes_buf(bytes, sizeof bytes);
    char hex[sizeof bytes * 2 + 1];
    sodium_bin2hex(hex, sizeof hex, bytes, sizeof bytes);
    return hex;
}

bool sameToken(const std::string& a, const std::string& b) {
    return a.size() == b.size() && !a.empty() && sodium_memcmp(a.data(), b.data(), a.size()) == 0;
}

std::pair<std::string, std::string> Sessions::create() {
    std::lock_guard lock(mutex_);
    const auto now = std::chrono::steady_clock::now();
    std::erase_if(sessions_, [&](const auto& kv) { return kv.second.expires <= now; });
    while (sessions_.size() >= max_) {
        auto oldest = sessions_.begin();
        for (auto it = sessions_.begin(); it != sessions_.end(); ++it) {
            if (it->second.expires < oldest->second.expires) {
                oldest = it;
            }
        }
        sessions_.erase(oldest);
    }
    std::string token = randomToken();
    std::string csrf = randomToken();
    sessions_[token] = Session{csrf, now + lifetime_};
    return {token, csrf};
}

std::optional<std::string> Sessions::csrfOf(const std::string& token) {
    if (token.empty()) {
        return std::nullopt;
    }
    std::lock_guard lock(mutex_);
    // Compared one by one in constant time, not looked up: no timing hint of a near miss.
    const auto now = std::chrono::steady_clock::now();
    for (const auto& [t, s] : sessions_) {
        if (sameToken(t, token) && s.expires > now) {
            return s.csrf;
        }
    }
    return std::nullopt;
}

void Sessions::remove(const std::string& token) {
    std::lock_guard lock(mutex_);
    sessions_.erase(token);
}

}  // namespace caphub::firmware::serve
