#!/usr/bin/env bash
# The Khronos glTF validator on a .glb exported by caphub from the walk recording.
# Usage: export_glb_validate.sh CAPHUB MAKE_RECORDING VALIDATE_JS NPM_PREFIX WORK_DIR
# Exit 0: no errors; 1: errors, or a tool missing; 77 (skipped): the npm registry is unreachable.
set -euo pipefail
caphub=$1 make_recording=$2 validate_js=$3 npm_prefix=$4 work=$5

for tool in node npm; do
  if ! command -v "$tool" >/dev/null; then
    echo "FAIL: $tool is not installed (toolchain/bootstrap.sh installs nodejs and npm)"
    exit 1
  fi
done
if [ ! -f "$npm_prefix/node_modules/gltf-validator/package.json" ]; then
  if ! timeout 30 npm view gltf-validator version >/dev/null 2>&1; then
    echo "SKIPPED: the npm registry cannot be reached, so gltf-validator cannot be installed;"
    echo "SKIPPED: the exported .glb was NOT validated"
    exit 77
  fi
  npm install --prefix "$npm_prefix" --no-audit --no-fund gltf-validator
fi

mkdir -p "$work"
rm -f "$work/walk.cap" "$work/walk.glb"
"$make_recording" "$work/walk.cap"
"$caphub" export "$work/walk.cap" --format glb -o "$work/walk.glb"
node "$validate_js" "$npm_prefix" "$work/walk.glb"
