// Writes the export tests' walk recording to a path: used by the glTF validator test, which
// runs the caphub binary and the Khronos validator on what it exports.
#include <cstdio>
#include <exception>

#include "tests/firmware/export_fixture.h"

int main(int argc, char** argv) {
    if (argc != 2) {
        std::fprintf(stderr, "usage: %s OUT.cap\n", argv[0]);
        return 2;
    }
    try {
        caphub::firmware::testing::writeWalkRecording(argv[1]);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "%s\n", e.what());
        return 1;
    }
    return 0;
}
