// The preview's destinations as the commands take them: png:DIR (PNG files), fb:/dev/fbN (a
// framebuffer), http:[HOST:]PORT (an MJPEG stream).
#pragma once

#include <string>
#include <vector>

#include "render/sinks.h"

namespace caphub::firmware {

// Opens each; one that cannot be opened is in failures(), and the others work.
render::SinkSet openPreviewSinks(const std::vector<std::string>& specs);

}  // namespace caphub::firmware
