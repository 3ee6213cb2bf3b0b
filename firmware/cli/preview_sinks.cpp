#include "firmware/cli/preview_sinks.h"

#include <cstdlib>

#include <fmt/format.h>

#include "render/framebuffer.h"
#include "render/mjpeg_server.h"

namespace caphub::firmware {

render::SinkSet openPreviewSinks(const std::vector<std::string>& specs) {
    render::SinkSet sinks;
    for (const auto& spec : specs) {
        const auto colon = spec.find(':');
        const std::string kind = spec.substr(0, colon);
        const std::string arg = colon == std::string::npos ? "" : spec.substr(colon + 1);
        if (kind == "png" && !arg.empty()) {
            sinks.add(render::makePngFolderSink(arg));
        } else if (kind == "fb" && !arg.empty()) {
            auto fb = render::FramebufferSink::openDevice(arg, 32);
            if (fb) {
                sinks.add(render::makeFramebufferSink(std::move(*fb)));
            } else {
                sinks.addFailure(spec, fb.error());
            }
        } else if (kind == "http" && !arg.empty()) {
            render::MjpegOptions mo;
            const auto hostColon = arg.rfind(':');
            if (hostColon != std::string::npos) {
                mo.host = arg.substr(0, hostColon);
            }
            mo.port = std::atoi(arg.c_str() + (hostColon == std::string::npos ? 0 : hostColon + 1));
            auto server = render::MjpegServer::start(mo);
            if (server) {
                fmt::print("preview: http://{}:{}/\n", mo.host, (*server)->port());
                sinks.add(render::makeMjpegSink(std::move(*server)));
            } else {
                sinks.addFailure(spec, server.error());
            }
        } else {
            sinks.addFailure(spec,
                             Error{EINVAL, "expected png:DIR, fb:/dev/fbN or http:[HOST:]PORT"});
        }
    }
    return sinks;
}

}  // namespace caphub::firmware
