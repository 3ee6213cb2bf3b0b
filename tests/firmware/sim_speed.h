// How fast the tests pace the virtual suit.
#pragma once

#include <algorithm>
#include <sstream>
#include <string>

namespace caphub::testing {

// The fastest pace a test asks of the virtual suit on this build (CAPHUB_TEST_MAX_SIM_SPEED,
// tests/firmware/CMakeLists.txt): no limit in a plain build, real time under the sanitizers or
// an emulator. There the capture runs several times slower; paced beyond the machine, its
// pipeline falls behind the buses and a bus far behind is declared late, its segments not
// measured: what a hub too slow for its suit should do, but not what a test of a take, a stream
// or an export is about.
inline double simSpeed(double wanted) {
    return std::min(wanted, static_cast<double>(CAPHUB_TEST_MAX_SIM_SPEED));
}

// The same as `caphub run`'s option.
inline std::string speedOption(double wanted) {
    std::ostringstream s;
    s << "--speed " << simSpeed(wanted);
    return s.str();
}

}  // namespace caphub::testing
