#include "firmware/cli/preview_sinks.h"

#include <charconv>

#include <fmt/format.h>

#include "render/framebuffer.h"
#include "render/mjpeg_server.h"

namespace caphub::firmware {

namespace {

constexpr const char* kExpected = "expected png:DIR, fb:/dev/fbN or http:[HOST:]PORT";

}  // namespace

Result<PreviewSpec> parsePreviewSpec(const std::string& spec) {
    const auto colon = spec.find(':');
    PreviewSpec p;
    p.kind = spec.substr(0, colon);
    const std::string arg = colon == std::string::npos ? "" : spec.substr(colon + 1);
    if ((p.kind == "png" || p.kind == "fb") && !arg.empty()) {
        p.path = arg;
        return p;
    }
    if (p.kind != "http" || arg.empty()) {
        return Error{EINVAL, fmt::format("preview '{}': {}", spec, kExpected)};
    }
    const auto hostColon = arg.rfind(':');
    if (hostColon != std::string::npos) {
        p.host = arg.substr(0, hostColon);
        // An IPv6 address in brackets ([::1]:8081), as --listen and --stream take it.
        if (p.host.size() > 2 && p.host.front() == '[' && p.host.back() == ']') {
            p.host = p.host.substr(1, p.host.size() - 2);
        }
    }
    // The whole port must be a number from 0 to 65535 (atoi read "abc" as 0: any free port).
    const std::string portText = hostColon == std::string::npos ? arg : arg.substr(hostColon + 1);
    int port = -1;
    const auto [end, ec] =
        std::from_chars(portText.data(), portText.data() + portText.size(), port);
    if (portText.empty() || ec != std::errc{} || end != portText.data() + portText.size() ||
        port < 0 || port > 65535 || p.host.empty()) {
        return Error{EINVAL, fmt::format("preview '{}': expected http:[HOST:]PORT with a port "
                                         "from 0 to 65535",
                                         spec)};
    }
    p.port = port;
    return p;
}

render::SinkSet openPreviewSinks(const std::vector<std::string>& specs) {
    render::SinkSet sinks;
    for (const auto& spec : specs) {
        auto p = parsePreviewSpec(spec);
        if (!p) {
            sinks.addFailure(spec, p.error());
        } else if (p->kind == "png") {
            sinks.add(render::makePngFolderSink(p->path));
        } else if (p->kind == "fb") {
            auto fb = render::FramebufferSink::openDevice(p->path, 32);
            if (fb) {
                sinks.add(render::makeFramebufferSink(std::move(*fb)));
            } else {
                sinks.addFailure(spec, fb.error());
            }
        } else {
            render::MjpegOptions mo;
            mo.host = p->host;
            mo.port = p->port;
            auto server = render::MjpegServer::start(mo);
            if (server) {
                const bool v6 = mo.host.find(':') != std::string::npos;
                fmt::print("preview: http://{}{}{}:{}/\n", v6 ? "[" : "", mo.host, v6 ? "]" : "",
                           (*server)->port());
                sinks.add(render::makeMjpegSink(std::move(*server)));
            } else {
                sinks.addFailure(spec, server.error());
            }
        }
    }
    return sinks;
}

}  // namespace caphub::firmware
