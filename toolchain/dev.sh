#!/usr/bin/env bash
# The two commands of the README, and what CI runs.
#   dev.sh run         bootstrap, build (release), run caphub on the virtual suit
#   dev.sh test        bootstrap, build (debug), run every test with ctest
#   dev.sh test asan   the same under AddressSanitizer + UndefinedBehaviorSanitizer
#   dev.sh test aarch64   cross build for arm64, unit tests under qemu-aarch64 (armhf: qemu-arm)
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$root"

usage() {
    sed -n '2,6p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'
    exit 2
}

build() {
    local preset=$1
    bash toolchain/bootstrap.sh
    cmake --preset "$preset" >/dev/null
    cmake --build --preset "$preset"
}

case "${1:-}" in
run)
    build release
    out="$root/out"
    mkdir -p "$out/recordings"
    caphub=build/release/bin/caphub
    # The main job: capture the default virtual suit (17 sensors) for a while, paced to real
    # time, recording every sample and event; then describe the recording.
    "$caphub" boards validate board/sim-suit.toml --quiet
    "$caphub" run --board board/sim-suit.toml --duration "${CAPHUB_RUN_SECONDS:-10}" \
        --out "$out/recordings" | tee "$out/run-report.txt"
    recording=$(ls -t "$out"/recordings/*.cap | head -n 1)
    "$caphub" info "$recording" >"$out/recording-info.txt"
    echo
    echo "output: $recording"
    echo "        $out/run-report.txt (the capture's report)"
    echo "        $out/recording-info.txt (caphub info of the recording)"
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
*)
    usage
    ;;
esac
