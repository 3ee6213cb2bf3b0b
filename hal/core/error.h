// The error convention every area follows (see docs/design.md, "Errors").
//
// Lowest layers (bus backends, drivers, the hot path) return int: 0 on success, -errno on
// failure, and do not log. Code above them that needs to carry a message to a person returns
// Result<T>: a value or an Error holding a positive errno code and a message with context.
#pragma once

#include <cerrno>
#include <string>
#include <utility>
#include <variant>

namespace caphub {

// The text of a positive or negative errno value ("No such device").
std::string errnoText(int err);

struct Error {
    int code = EINVAL;  // positive errno value
    std::string message;
};

template <typename T>
class [[nodiscard]] Result {
public:
    Result(T value) : v_(std::move(value)) {}      // NOLINT(google-explicit-constructor)
    Result(Error error) : v_(std::move(error)) {}  // NOLINT(google-explicit-constructor)

    bool ok() const { return v_.index() == 0; }
    explicit operator bool() const { return ok(); }

    T& value() & { return std::get<0>(v_); }
    const T& value() const& { return std::get<0>(v_); }
    T&& value() && { return std::get<0>(std::move(v_)); }
    T& operator*() & { return value(); }
    const T& operator*() const& { return value(); }
    T* operator->() { return &value(); }
    const T* operator->() const { return &value(); }

    const Error& error() const { return std::get<1>(v_); }

private:
    std::variant<T, Error> v_;
};

template <>
class [[nodiscard]] Result<void> {
public:
    Result() = default;
    Result(Error error) : error_(std::move(error)), ok_(false) {}  // NOLINT

    bool ok() const { return ok_; }
    explicit operator bool() const { return ok_; }
    const Error& error() const { return error_; }

private:
    Error error_{0, {}};
    bool ok_ = true;
};

// An Error from a -errno return value, with context: "open '/dev/i2c-1': Permission denied".
inline Error errnoError(int negErrno, const std::string& context) {
    const int code = negErrno < 0 ? -negErrno : negErrno;
    return Error{code, context + ": " + errnoText(code)};
}

}  // namespace caphub
