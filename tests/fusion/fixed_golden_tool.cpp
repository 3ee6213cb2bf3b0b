// caphub_fixed_golden: writes the golden hashes of the fixed-point filter's raw state over the
// shipped excerpt (tests/data/fusion/fixed_golden.txt), which fixed_golden_test.cpp compares
// with on every architecture. Run on x86-64 only, through the target caphub_update_fixed_golden:
//   cmake --build build/debug --target caphub_update_fixed_golden
// GOLDEN "-" prints the hashes instead (allowed on any architecture); the optional third argument
// writes a CSV of the raw values per sample, to diff two architectures' runs.
#include <cstdio>
#include <fstream>
#include <string>

#include "tests/fusion/fixed_golden.h"

namespace golden = caphub::fusion::golden;

int main(int argc, char** argv) {
    if (argc < 3 || argc > 4) {
        std::fprintf(stderr, "usage: caphub_fixed_golden INPUT.csv.gz GOLDEN.txt|- [RAW.csv]\n");
        return 2;
    }
    const std::string input = argv[1];
    const std::string goldenPath = argv[2];
#if !defined(__x86_64__)
    if (goldenPath != "-") {
        std::fprintf(stderr, "caphub_fixed_golden: the golden file is written on x86-64 only\n");
        return 2;
    }
#endif
    auto samples = golden::readExcerpt(input);
    if (!samples) {
        std::fprintf(stderr, "caphub_fixed_golden: %s\n", samples.error().message.c_str());
        return 1;
    }
    const auto raw = golden::runFixedRaw(*samples);
    const auto points = golden::checkpoints(raw);
    const std::string comment =
        "FNV-1a 64 of the raw int32 state (quaternion w x y z, bias x y z; little-endian) of\n"
        "OrientationFilter<FixedTypes> after each sample of " +
        std::string(golden::kInputName) +
        ",\n"
        "hashed over the first SAMPLES samples. Written on x86-64 by caphub_fixed_golden\n"
        "(target caphub_update_fixed_golden); never edit by hand. Read by\n"
        "tests/fusion/fixed_golden_test.cpp on every architecture.";
    if (goldenPath == "-") {
        std::fputs(golden::formatGolden(points, comment).c_str(), stdout);
    } else {
        std::ofstream out(goldenPath, std::ios::trunc);
        out << golden::formatGolden(points, comment);
        out.close();
        if (!out) {
            std::fprintf(stderr, "caphub_fixed_golden: cannot write '%s'\n", goldenPath.c_str());
            return 1;
        }
    }
    if (argc == 4) {
        std::ofstream csv(argv[3], std::ios::trunc);
        csv << "sample,qw,qx,qy,qz,bias_x,bias_y,bias_z\n";
        for (std::size_t i = 0; i < raw.size() / golden::kValuesPerSample; ++i) {
            csv << i;
            for (std::size_t k = 0; k < golden::kValuesPerSample; ++k) {
                csv << ',' << raw[i * golden::kValuesPerSample + k];
            }
            csv << '\n';
        }
        if (!csv) {
            std::fprintf(stderr, "caphub_fixed_golden: cannot write '%s'\n", argv[3]);
            return 1;
        }
    }
    std::printf("caphub_fixed_golden: %zu samples, final hash %016llx -> %s\n",
                points.back().samples, static_cast<unsigned long long>(points.back().hash),
                goldenPath.c_str());
    return 0;
}
