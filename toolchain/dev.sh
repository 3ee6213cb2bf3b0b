#!/usr/bin/env bash
# The two commands of the README, and what CI runs.
#   dev.sh run         bootstrap, build (release), run caphub on the virtual suit
#   dev.sh test        bootstrap, build (debug), run every test with ctest
#   dev.sh test asan   the same under AddressSanitizer + UndefinedBehaviorSanitizer
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$root"

usage() {
    sed -n '2,5p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'
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
    mkdir -p "$out"
    # Until the capture runtime lands, the main job validates the default suit and describes
    # its plan: sensors per bus and each bus's utilisation.
    report="$out/sim-suit-plan.txt"
    build/release/bin/caphub boards validate board/sim-suit.toml | tee "$report"
    echo
    echo "output: $report"
    ;;
test)
    preset=${2:-debug}
    case "$preset" in debug | asan | release) ;; *) usage ;; esac
    build "$preset"
    ctest --preset "$preset"
    ;;
*)
    usage
    ;;
esac
