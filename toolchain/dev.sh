#!/usr/bin/env bash
# The two commands of the README, and what CI runs.
#   dev.sh run         bootstrap, build (release), run caphub on the virtual suit
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
    cmake --preset release -DCAPHUB_BUILD_TESTS=OFF -DCAPHUB_BUILD_BENCHMARKS=OFF >/dev/null
    cmake --build --preset release --target caphub
    out="$root/out"
    rm -rf "$out/recordings" "$out/preview" "$out/exports"
    mkdir -p "$out/recordings" "$out/exports"
    caphub=build/release/bin/caphub
    board=board/sim-suit.toml
    "$caphub" boards validate "$board" --quiet
    # The main job on the default virtual suit (17 sensors): calibrate the sensors (gyro bias
    # at rest, accelerometer and gyroscope axes in fourteen positions, magnetometer turned
    # through every direction), then
    # capture paced to real time: the subject calibrates in the T-pose, then walks; every sample,
    # orientation, pose and event is recorded and preview frames are rendered. Then the
    # recording is described and exported to BVH and glTF.
    calibration="$out/calibration.toml"
    rm -f "$calibration"
    for kind in gyro accel mag; do
        "$caphub" calibrate "$kind" --board "$board" --file "$calibration" | tail -n 1
    done
    recording="$out/recordings/capture.cap"
    "$caphub" run --board "$board" --duration "${CAPHUB_RUN_SECONDS:-12}" --calibrate tpose \
        --calibration "$calibration" --preview "png:$out/preview" --preview-fps 5 \
        --record "$recording" | tee "$out/run-report.txt"
    "$caphub" info "$recording" >"$out/recording-info.txt"
    "$caphub" export "$recording" --format bvh -o "$out/exports/capture.bvh"
    "$caphub" export "$recording" --format glb -o "$out/exports/capture.glb"
    echo
    echo "output: $calibration (the sensors' calibration)"
    echo "        $recording (the recording)"
    echo "        $out/run-report.txt (the capture's report)"
    echo "        $out/recording-info.txt (caphub info of the recording)"
    echo "        $out/preview/ ($(ls "$out/preview" | wc -l) preview frames, PNG)"
    echo "        $out/exports/capture.bvh, $out/exports/capture.glb (the exports)"
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
