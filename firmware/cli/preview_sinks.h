// The preview's destinations as the commands take them: png:DIR (PNG files), fb:/dev/fbN (a
// framebuffer), http:[HOST:]PORT (an MJPEG stream).
#pragma once

#include <string>
#include <vector>

#include "hal/core/error.h"
#include "render/sinks.h"

namespace caphub::firmware {

struct PreviewSpec {
    std::string kind;  // png, fb, http
    std::string path;  // png: the folder; fb: the device
    std::string host = "127.0.0.1";
    int port = 0;
};

// One destination as given; EINVAL (with what was expected) for anything else - a command
// refuses it before it starts rather than leave the preview off or listen on another port.
Result<PreviewSpec> parsePreviewSpec(const std::string& spec);

// Opens each; one that cannot be opened is in failures(), and the others work.
render::SinkSet openPreviewSinks(const std::vector<std::string>& specs);

}  // namespace caphub::firmware
