#!/usr/bin/env bash
# The two commands of the README, and what CI runs.
#   dev.sh run         bootstrap, build (release), a scripted caphub serve session on the virtual suit
#   dev.sh test        bootstrap, build (debug), run every test with ctest
#   dev.sh test asan   the same under AddressSanitizer + UndefinedBehaviorSanitizer
#   dev.sh test aarch64   cross build for arm64, unit tests under qemu-aarch64 (armhf: qemu-arm)
#   dev.sh package [host|aarch64|armhf]   the .deb for amd64 (release build), arm64 or armhf
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$root"

usage() {
    sed -n '2,7p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'
    exit 2
}

build() {
    local preset=$1
    bash toolchain/bootstrap.sh
    cmake --preset "$preset" -DCAPHUB_BUILD_TESTS=ON -DCAPHUB_BUILD_BENCHMARKS=ON >/dev/null
    cmake --build --preset "$preset"
}

case "${1:-}" in
run)
    # Only what the program needs: its packages, and the program alone (no tests).
    bash toolchain/bootstrap.sh run
    # (The release build's -O2 without its debug information: a third less compile time.)
    cmake --preset program >/dev/null
    cmake --build --preset program
    out="$root/out"
    rm -rf "$out/recordings" "$out/exports" "$out/state" "$out/preview"
    mkdir -p "$out/recordings" "$out/exports"
    caphub=build/program/bin/caphub
    board=board/sim-suit.toml
    "$caphub" boards validate "$board" --quiet
    # The main job: `caphub serve` on the default virtual suit (17 sensors, paced to real time,
    # 127.0.0.1 only) operated through its HTTP API as the web page does it
    # (toolchain/serve_session.py, docs/serve.md): the sensors' guided calibration (the virtual
    # subject does each motion), saved on the hub and applied at its restart; the body's
    # calibration in the T-pose; two named takes; BVH and glTF exports downloaded.
    python3 toolchain/serve_session.py "$caphub" "$board" "$out"
    echo
    echo "the hub for a browser: $caphub serve --board $board --state-dir $out/state \\"
    echo "    --recordings $out/recordings     then open http://127.0.0.1:8080/"
    ;;
test)
    preset=${2:-debug}
    case "$preset" in
    debug | asan | release) ;;
    aarch64) bash toolchain/bootstrap.sh && bash toolchain/make-sysroot.sh arm64 ;;
    armhf) bash toolchain/bootstrap.sh && bash toolchain/make-sysroot.sh armhf ;;
    *) usage ;;
    esac
    build "$preset"
    ctest --preset "$preset"
    ;;
package)
    # The package of one architecture into out/packages. CAPHUB_BUILD_DIR picks another build
    # folder than the preset's, CAPHUB_JOBS the parallel build jobs (default: the preset's 2).
    case "${2:-host}" in
    host) preset=release ;;
    aarch64 | arm64) preset=aarch64 ;;
    armhf) preset=armhf ;;
    *) usage ;;
    esac
    bash toolchain/bootstrap.sh
    case "$preset" in
    aarch64) bash toolchain/make-sysroot.sh arm64 ;;
    armhf) bash toolchain/make-sysroot.sh armhf ;;
    esac
    dir=${CAPHUB_BUILD_DIR:-build/$preset}
    cmake --preset "$preset" -B "$dir" >/dev/null
    # The package holds the program and data files: building `caphub` is enough.
    cmake --build "$dir" --target caphub -j "${CAPHUB_JOBS:-2}"
    out="$root/out/packages"
    mkdir -p "$out"
    cpack -G DEB --config "$dir/CPackConfig.cmake" -B "$out" >"$dir/cpack.log" 2>&1 || {
        tail -20 "$dir/cpack.log" >&2
        exit 1
    }
    rm -rf "$out/_CPack_Packages"  # cpack's staging folder
    deb=$(grep -o "$out/caphub_[^ ]*\.deb" "$dir/cpack.log" | tail -n 1)
    echo "package: $deb"
    dpkg-deb -f "$deb" Package Version Architecture Depends
    ;;
*)
    usage
    ;;
esac
