// The HTTP helpers every group of routes uses (web_state.h).
#include <algorithm>
#include <cmath>
#include <fstream>
#include <memory>
#include <vector>

#include <fmt/format.h>

#include "firmware/serve/web_state.h"

namespace caphub::firmware::serve {

namespace fs = std::filesystem;

void reply(httplib::Response& res, int status, const Json& body) {
    res.status = status;
    res.set_header("Cache-Control", "no-store");
    // Bytes that are not UTF-8 (a request's path echoed, a file name) as U+FFFD: the JSON
    // library throws on them, and from an error handler that ended the process.
    res.set_content(body.dump(-1, ' ', false, Json::error_handler_t::replace), "application/json");
}

void fail(httplib::Response& res, int status, const std::string& message) {
    reply(res, status, Json{{"error", message}});
}

// The HTTP status for an error of a Hub command or a file operation.
int statusFor(const Error& e) {
    switch (e.code) {
        case EINVAL:
            return 400;
        case EPERM:
        case EACCES:
            return 403;
        case ENOENT:
            return 404;
        case ESRCH:
        case ETIMEDOUT:
        case EBUSY:
            return 503;
        default:
            return 500;
    }
}

void failWith(httplib::Response& res, const Error& e) {
    fail(res, statusFor(e), e.message);
}

std::string cookieValue(const httplib::Request& req, const std::string& name) {
    const std::string header = req.get_header_value("Cookie");
    std::size_t pos = 0;
    while (pos < header.size()) {
        const std::size_t end = std::min(header.find(';', pos), header.size());
        std::string item = header.substr(pos, end - pos);
        const std::size_t first = item.find_first_not_of(' ');
        item = first == std::string::npos ? "" : item.substr(first);
        if (item.size() > name.size() && item.compare(0, name.size(), name) == 0 &&
            item[name.size()] == '=') {
            return item.substr(name.size() + 1);
        }
        pos = end + 1;
    }
    return {};
}

// The host part of a Host header ("127.0.0.1:8080", "[::1]:8080", "localhost").
std::string hostOf(const std::string& header) {
    if (header.starts_with('[')) {
        const auto close = header.find(']');
        return close == std::string::npos ? header : header.substr(1, close - 1);
    }
    return header.substr(0, header.find(':'));
}

// Streams a file in 64 KiB pieces; `removeAfter` deletes it when the response is done.
void streamFile(httplib::Response& res, const fs::path& path, const std::string& mime,
                const std::string& downloadName, bool removeAfter, std::function<void()> done) {
    std::error_code ec;
    const auto size = fs::file_size(path, ec);
    auto in = std::make_shared<std::ifstream>(path, std::ios::binary);
    if (ec || !*in) {
        fail(res, 500, fmt::format("cannot read '{}'", downloadName));
        if (removeAfter) {
            fs::remove(path, ec);
        }
        if (done) {
            done();
        }
        return;
    }
    res.set_header("Content-Disposition", fmt::format("attachment; filename=\"{}\"", downloadName));
    res.set_header("Cache-Control", "no-store");
    res.set_content_provider(
        static_cast<std::size_t>(size), mime,
        [in](std::size_t offset, std::size_t length, httplib::DataSink& sink) {
            std::vector<char> buf(std::min<std::size_t>(length, 64 * 1024));
            in->seekg(static_cast<std::streamoff>(offset));
            in->read(buf.data(), static_cast<std::streamsize>(buf.size()));
            const auto n = static_cast<std::size_t>(in->gcount());
            return n > 0 && sink.write(buf.data(), n);
        },
        [path, removeAfter, done = std::move(done)](bool) {
            if (removeAfter) {
                std::error_code e;
                fs::remove(path, e);
            }
            if (done) {
                done();
            }
        });
}

std::optional<double> numberParam(const httplib::Request& req, const char* key,
                                  std::string& error) {
    if (!req.has_param(key)) {
        return std::nullopt;
    }
    const std::string v = req.get_param_value(key);
    try {
        std::size_t used = 0;
        const double d = std::stod(v, &used);
        if (used == v.size() && std::isfinite(d) && d >= 0) {
            return d;
        }
    } catch (const std::exception&) {
    }
    error = fmt::format("{}: expected a number >= 0, got '{}'", key, v);
    return std::nullopt;
}

}  // namespace caphub::firmware::serve
