#!/usr/bin/env bash
# liblo's oscdump (Debian liblo-tools) as a second independent receiver: a VRChat stream from a
# short `caphub run` on the virtual suit arrives as the 18 addresses of VRChat's OSC trackers, each
# with three floats, in about one bundle per frame at the asked rate.
# usage: oscdump_check.sh CAPHUB WORKDIR
set -euo pipefail
caphub=$1
work=$2
mkdir -p "$work"
command -v oscdump >/dev/null || { echo "oscdump not installed (liblo-tools)"; exit 1; }
port=$(python3 -c 'import socket; s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
oscdump -L "$port" >"$work/oscdump.txt" 2>&1 &
dump=$!
trap 'kill "$dump" 2>/dev/null || true' EXIT
sleep 0.5
"$caphub" run --board sim-suit --duration 3 --realtime 0 --no-preview --no-record \
  --status-file "$work/status.json" --stream "vrchat:127.0.0.1:$port@30" >"$work/run.txt"
sleep 0.5
kill "$dump"
wait "$dump" 2>/dev/null || true
frames=$(grep -c ' /tracking/trackers/1/position fff ' "$work/oscdump.txt" || true)
sent=$(sed -n 's/^stream vrchat:.*: \([0-9]*\) frames sent.*/\1/p' "$work/run.txt")
echo "oscdump: $(wc -l <"$work/oscdump.txt") messages, $frames frames; caphub sent $sent"
fail=0
for n in 1 2 3 4 5 6 7 8 head; do
  for what in position rotation; do
    c=$(grep -c " /tracking/trackers/$n/$what fff [-0-9.]* [-0-9.]* [-0-9.]*\$" "$work/oscdump.txt" || true)
    if [ "$c" != "$frames" ]; then
      echo "FAIL: /tracking/trackers/$n/$what: $c messages with three floats, expected $frames"
      fail=1
    fi
  done
done
others=$(grep -vc ' /tracking/trackers/[1-8a-z]*/\(position\|rotation\) fff ' "$work/oscdump.txt" || true)
[ "$others" = 0 ] || { echo "FAIL: $others other lines"; fail=1; }
# Every frame sent arrived (loopback), about 30 a second over the 3 s (the first poses come once
# the sensors are up).
[ "$frames" = "$sent" ] || { echo "FAIL: $sent sent, $frames received"; fail=1; }
[ "$frames" -ge 60 ] && [ "$frames" -le 100 ] || { echo "FAIL: $frames frames in 3 s at 30 Hz"; fail=1; }
exit $fail
