#!/usr/bin/env bash
# Builds the libFuzzer targets with clang (build/fuzz) and runs each for a bounded time on a
# copy of its corpus. Exit non-zero when a target finds a crash, a leak or a timeout; the
# reproducer is left in build/fuzz/findings/<target>/.
#   fuzz.sh [SECONDS_PER_TARGET]   (default 60)
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$root"
seconds=${1:-60}

bash toolchain/bootstrap.sh
CXX=clang++ cmake -S . -B build/fuzz -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    -DCAPHUB_BUILD_FUZZERS=ON -DCAPHUB_BUILD_BENCHMARKS=OFF >/dev/null
targets=(bvh recording)
cmake --build build/fuzz -j2 --target "${targets[@]/#/caphub_fuzz_}"

status=0
for t in "${targets[@]}"; do
    work="build/fuzz/work/$t"
    findings="build/fuzz/findings/$t"
    rm -rf "$work" && mkdir -p "$work" "$findings"
    cp tests/fuzz/corpus/"$t"/* "$work"/
    dict=()
    [ -f "tests/fuzz/$t.dict" ] && dict=(-dict="tests/fuzz/$t.dict")
    echo "fuzz: $t for ${seconds} s"
    if ! "build/fuzz/tests/fuzz/caphub_fuzz_$t" -max_total_time="$seconds" -max_len=65536 \
        -timeout=10 -rss_limit_mb=2048 -artifact_prefix="$findings/" "${dict[@]}" "$work" \
        >"build/fuzz/$t.log" 2>&1; then
        echo "fuzz: $t FAILED (see build/fuzz/$t.log and $findings/)"
        tail -n 30 "build/fuzz/$t.log"
        status=1
    else
        grep -E "^Done [0-9]+ runs" "build/fuzz/$t.log" | sed "s/^/fuzz: $t: /"
    fi
done
exit $status
