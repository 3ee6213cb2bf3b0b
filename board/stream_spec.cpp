#include "board/stream_spec.h"

#include <charconv>

#include <fmt/format.h>

namespace caphub::board {

std::string_view streamKindName(StreamKind kind) {
    switch (kind) {
        case StreamKind::Vmc:
            return "vmc";
        case StreamKind::VrChat:
            return "vrchat";
        case StreamKind::Caphub:
            return "caphub";
    }
    return "?";
}

int defaultStreamPort(StreamKind kind) {
    switch (kind) {
        case StreamKind::Vmc:
            return 39539;
        case StreamKind::VrChat:
            return 9000;
        case StreamKind::Caphub:
            return 39600;
    }
    return 0;
}

namespace {

Error bad(std::string_view spec, std::string_view what) {
    return Error{EINVAL, fmt::format("stream '{}': {} (expected KIND:HOST:PORT[@RATE], KIND one "
                                     "of vmc, vrchat, caphub; e.g. \"vmc:127.0.0.1:39539@60\")",
                                     spec, what)};
}

template <typename T>
bool parseNumber(std::string_view text, T& out) {
    if (text.empty()) {
        return false;
    }
    const char* end = text.data() + text.size();
    const auto r = std::from_chars(text.data(), end, out);
    return r.ec == std::errc() && r.ptr == end;
}

}  // namespace

Result<StreamConfig> parseStreamSpec(std::string_view spec) {
    StreamConfig s;
    std::string_view rest = spec;
    if (const auto at = rest.rfind('@'); at != std::string_view::npos) {
        double rate = 0;
        if (!parseNumber(rest.substr(at + 1), rate) || !(rate >= 1 && rate <= 1000)) {
            return bad(spec, fmt::format("the rate '{}' is not a number of Hz from 1 to 1000",
                                         rest.substr(at + 1)));
        }
        s.rateHz = rate;
        rest = rest.substr(0, at);
    }
    const auto colon = rest.find(':');
    const std::string_view kind = rest.substr(0, colon);
    if (kind == "vmc") {
        s.kind = StreamKind::Vmc;
    } else if (kind == "vrchat") {
        s.kind = StreamKind::VrChat;
    } else if (kind == "caphub") {
        s.kind = StreamKind::Caphub;
    } else {
        return bad(spec, fmt::format("unknown kind '{}'", kind));
    }
    s.host = "127.0.0.1";
    s.port = defaultStreamPort(s.kind);
    if (colon == std::string_view::npos) {
        return s;
    }
    rest = rest.substr(colon + 1);
    std::string_view host;
    std::string_view port;
    if (rest.starts_with('[')) {
        const auto close = rest.find(']');
        if (close == std::string_view::npos) {
            return bad(spec, "an IPv6 address without its closing ']'");
        }
        host = rest.substr(1, close - 1);
        rest = rest.substr(close + 1);
        if (!rest.empty()) {
            if (rest[0] != ':') {
                return bad(spec, "':' expected after the IPv6 address");
            }
            port = rest.substr(1);
            if (port.empty()) {
                return bad(spec, "an empty port");
            }
        }
    } else {
        const auto c = rest.find(':');
        host = rest.substr(0, c);
        if (c != std::string_view::npos) {
            port = rest.substr(c + 1);
            if (port.empty()) {
                return bad(spec, "an empty port");
            }
        }
    }
    if (host.empty()) {
        return bad(spec, "an empty host");
    }
    // A name or an address: letters, digits, '.', '-', '_' and (IPv6) ':' and '%' (a zone). A
    // second '@' made "h@60@70" stream to the host "h@60".
    for (char c : host) {
        const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') ||
                        (c >= '0' && c <= '9') || c == '.' || c == '-' || c == '_' || c == ':' ||
                        c == '%';
        if (!ok) {
            return bad(spec, fmt::format("the host '{}' is not a host name or an address", host));
        }
    }
    s.host = std::string(host);
    if (!port.empty()) {
        int p = 0;
        if (!parseNumber(port, p) || p < 1 || p > 65535) {
            return bad(spec, fmt::format("the port '{}' is not a number from 1 to 65535", port));
        }
        s.port = p;
    }
    return s;
}

std::string toString(const StreamConfig& s) {
    const bool v6 = s.host.find(':') != std::string::npos;
    return fmt::format("{}:{}{}{}:{}@{:g}", streamKindName(s.kind), v6 ? "[" : "", s.host,
                       v6 ? "]" : "", s.port, s.rateHz);
}

}  // namespace caphub::board
