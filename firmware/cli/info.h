// What this build of caphub is.
#pragma once

#include <string>

namespace caphub::firmware {

// "caphub 0.1.0 (abc123, Debug)"
std::string versionLine();

}  // namespace caphub::firmware
