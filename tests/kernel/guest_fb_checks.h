// The kernel-level guest's framebuffer section: the render library's framebuffer sink
// (render/framebuffer.h) writing frames into vfb's /dev/fbN, read back through the device.
#pragma once

#include <string>

#include "tests/kernel/guest_checks.h"

namespace caphub::kernel_test {

// Runs every framebuffer check on `device` (vfb loaded with vfb_enable=1), counting them in
// `checks`. Leaves the device at 32 bits per pixel.
void checkFramebuffer(const std::string& device, Checks& checks);

}  // namespace caphub::kernel_test
