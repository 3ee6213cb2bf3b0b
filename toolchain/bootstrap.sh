#!/usr/bin/env bash
# Installs every Debian 12 package caphub needs to build, run and test on the host (`run`: only
# what building and running the program needs).
# Idempotent: only packages that are missing are installed; nothing is downloaded from anywhere
# but the Debian archive. Works as root, or through sudo for a normal user.
set -euo pipefail

# What building and running the program needs (`bootstrap.sh run`, the README's main job).
program_packages=(
  # Build tools.
  build-essential cmake ninja-build ccache pkg-config
  # Libraries (architecture: Dependencies).
  libeigen3-dev libfmt-dev libspdlog-dev libtomlplusplus-dev libcli11-dev zlib1g-dev
  libi2c-dev libgpiod-dev
  # Render: OSMesa, PNG, JPEG, HTTP, glTF.
  libosmesa6-dev mesa-common-dev libpng-dev libturbojpeg0-dev libcpp-httplib-dev libtinygltf-dev
  nlohmann-json3-dev libstb-dev
  # libturbojpeg0-dev's CMake package also names libjpeg.so.62 and libjpeg.a (libjpeg62-turbo-dev)
  # without depending on them: find_package(libjpeg-turbo) fails on a fresh machine without it.
  libjpeg62-turbo-dev
  # Live streams: OSC (VMC, VRChat, caphub's own) with liblo.
  liblo-dev
  # caphub serve: password hashing (libsodium), three.js for its page; the main job's scripted
  # session against it is a python3 script (standard library only).
  libsodium-dev libjs-three python3
)
# Besides, for the tests, the cross builds and the packages (`bootstrap.sh`, the default).
test_packages=(
  git clang-format
  # Tests and benchmarks; clang and its runtime for the libFuzzer targets.
  libgtest-dev libgmock-dev libbenchmark-dev clang libclang-rt-14-dev
  # Kernel-level tests: Debian's kernel booted under qemu with a busybox initramfs.
  qemu-system-x86 busybox-static cpio kmod xz-utils
  # Cross builds for the board (sysroot: toolchain/make-sysroot.sh), their tests under qemu-user,
  # .deb packages, and caphub-flash's offline image editing (sfdisk, mtools, debugfs).
  g++-aarch64-linux-gnu g++-arm-linux-gnueabihf qemu-user dpkg-dev fakeroot file
  fdisk dosfstools mtools e2fsprogs
  # Live streams: liblo's oscdump receives them in the stream tests.
  liblo-tools
  # The Blender add-on's test: Debian's Blender 3.4 headless; numpy for its glTF importer.
  blender python3-numpy
  # Export tests: the Khronos glTF validator (npm gltf-validator) runs on node.
  nodejs npm
  # caphub serve's browser test drives Debian's headless Chromium with Selenium.
  chromium chromium-driver python3-selenium
)

case "${1:-all}" in
run) packages=("${program_packages[@]}") ;;
all) packages=("${program_packages[@]}" "${test_packages[@]}") ;;
*)
  echo "usage: bootstrap.sh [run|all]" >&2
  exit 2
  ;;
esac

missing=()
# What installed packages provide: one counts as present (NodeSource's nodejs provides npm).
provided=$(dpkg-query -W -f='${db:Status-Status} ${Provides}\n' 2>/dev/null || true)
for p in "${packages[@]}"; do
  status=$(dpkg-query -W -f='${db:Status-Status}' "$p" 2>/dev/null || true)
  if [ "$status" != "installed" ] &&
    ! grep -qE "^installed (.*[ ,])?$p( |,|$)" <<<"$provided"; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "bootstrap: all ${#packages[@]} packages present"
  exit 0
fi

if [ "$(id -u)" -eq 0 ]; then
  sudo=()
elif command -v sudo >/dev/null 2>&1; then
  sudo=(sudo)
else
  echo "bootstrap: need root or sudo to install: ${missing[*]}" >&2
  exit 1
fi

echo "bootstrap: installing ${missing[*]}"
apt=("${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get)
"${apt[@]}" update -q
# dpkg's unsafe-io: no fsync after each unpacked file (a fresh machine's install spends its time
# unpacking, not downloading: 167 MB came in 9 s, docs/serve.md). A power cut during the install
# can leave files unwritten: `apt-get install --reinstall` the packages it was installing.
"${apt[@]}" install -y -q --no-install-recommends -o Dpkg::Options::=--force-unsafe-io "${missing[@]}"
