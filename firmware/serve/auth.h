// The web control plane's access control (docs/serve.md, "Security"): the password, stored only
// as a libsodium crypto_pwhash_str hash (Argon2id) in the state folder, and the sessions a login
// gives: a random session token (sent as an HttpOnly, SameSite=Strict cookie) and its CSRF token
// (sent back by the page in a header with every state-changing request).
#pragma once

#include <chrono>
#include <cstddef>
#include <filesystem>
#include <map>
#include <mutex>
#include <optional>
#include <string>

#include "hal/core/error.h"

namespace caphub::firmware::serve {

// Where the hash is kept: DIR/web-password (mode 0600).
std::filesystem::path passwordFile(const std::filesystem::path& stateDir);
bool hasPassword(const std::filesystem::path& stateDir);
// Hashes and stores a password (at least 8 characters, at most 256); replaces an older one.
Result<void> setPassword(const std::filesystem::path& stateDir, const std::string& password);
// True when it matches the stored hash (false: none stored, or another password).
bool checkPassword(const std::filesystem::path& stateDir, const std::string& password);

// True for an address in 127.0.0.0/8, ::1 and the name "localhost"; nothing else (a name that
// merely starts with "127." is anybody's).
bool isLoopbackHost(const std::string& host);

// Random tokens as 64 hex digits (256 bits from libsodium's randombytes).
std::string randomToken();
// Equality that takes as long whatever the first difference (sodium_memcmp).
bool sameToken(const std::string& a, const std::string& b);

class Sessions {
public:
    struct Session {
        std::string csrf;
        std::chrono::steady_clock::time_point expires;
    };
    explicit Sessions(std::size_t maxSessions = 32,
                      std::chrono::seconds lifetime = std::chrono::hours(12))
        : max_(maxSessions), lifetime_(lifetime) {}
    // A new session: {token, csrf}. The oldest is dropped when there are too many.
    std::pair<std::string, std::string> create();
    // The session's CSRF token, if the token names a live session.
    std::optional<std::string> csrfOf(const std::string& token);
    void remove(const std::string& token);

private:
    std::mutex mutex_;
    std::map<std::string, Session> sessions_;
    std::size_t max_;
    std::chrono::seconds lifetime_;
};

}  // namespace caphub::firmware::serve
