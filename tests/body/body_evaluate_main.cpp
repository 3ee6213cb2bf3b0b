// caphub_body_evaluate: the per-joint error table of the body solver on BVH clips through the
// virtual suit's ground truth (ideal orientations).
//   caphub_body_evaluate [--suit board.toml] [--rate HZ] [--speed X] clip.bvh...
#include <cstdio>
#include <cstdlib>
#include <string>
#include <string_view>
#include <vector>

#include <fmt/format.h>

#include "tests/body/body_evaluation.h"

int main(int argc, char** argv) {
    std::filesystem::path suit =
        std::filesystem::path(CAPHUB_SOURCE_DIR) / "board" / "sim-suit.toml";
    double rateHz = 100;
    double speed = 1.0;
    std::vector<std::filesystem::path> clips;
    for (int i = 1; i < argc; ++i) {
        const std::string_view a = argv[i];
        if (a == "--suit" && i + 1 < argc) {
            suit = argv[++i];
        } else if (a == "--rate" && i + 1 < argc) {
            char* end = nullptr;
            rateHz = std::strtod(argv[++i], &end);
            if (*end != '\0' || !(rateHz > 0 && rateHz <= 10000)) {
                fmt::print(stderr, "--rate {}: expected a rate in Hz, 0 to 10000\n", argv[i]);
                return 2;
            }
        } else if (a == "--speed" && i + 1 < argc) {
            char* end = nullptr;
            speed = std::strtod(argv[++i], &end);
            if (*end != '\0' || !(speed >= 0.1 && speed <= 10)) {
                fmt::print(stderr, "--speed {}: expected a playback factor, 0.1 to 10\n", argv[i]);
                return 2;
            }
        } else if (!a.empty() && a[0] == '-') {
            fmt::print(stderr, "unknown option '{}': expected --suit FILE, --rate HZ, --speed X\n",
                       a);
            return 2;
        } else {
            clips.emplace_back(a);
        }
    }
    if (clips.empty()) {
        fmt::print(stderr,
                   "usage: caphub_body_evaluate [--suit board.toml] [--rate HZ] [--speed X] "
                   "clip.bvh...\n");
        return 2;
    }
    int rc = 0;
    for (const auto& c : clips) {
        auto s = caphub::body::evaluation::scoreClip(c, suit, rateHz, speed);
        if (!s) {
            fmt::print(stderr, "{}\n", s.error().message);
            rc = 1;
            continue;
        }
        fmt::print("{}\n", caphub::body::evaluation::formatTable(*s));
    }
    return rc;
}
