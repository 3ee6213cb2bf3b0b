#!/usr/bin/env bash
# Kernel-level test: boots Debian's own kernel under qemu (TCG) with a busybox initramfs that
# loads i2c-stub, i2c-dev and vfb, then runs a static guest program built from the project's hal
# and framebuffer sink against /dev/i2c-N and /dev/fbN. The run is judged by the marker the
# guest's /init prints.
#
#   run_kernel_test.sh GUEST_BINARY WORK_DIR
#
# WORK_DIR keeps the downloaded kernel package between runs (kernel-cache/). Exit codes:
# 0 pass, 1 fail, 77 skip (only when qemu-system-x86_64 itself is missing).
# Environment: CAPHUB_KERNEL_TIMEOUT_S (default 60) bounds the boot-to-poweroff time.
set -euo pipefail

readonly kMarker="CAPHUB-KERNEL-TEST"
readonly kSkip=77

die() {
    echo "kernel test: FAIL: $*" >&2
    exit 1
}

note() {
    echo "kernel test: $*"
}

if [ $# -ne 2 ]; then
    echo "usage: $0 GUEST_BINARY WORK_DIR" >&2
    exit 2
fi
guest=$(realpath "$1")
work=$(realpath -m "$2")
timeoutS=${CAPHUB_KERNEL_TIMEOUT_S:-60}

if ! command -v qemu-system-x86_64 >/dev/null 2>&1; then
    echo "kernel test: SKIP: qemu-system-x86_64 is not installed (bash toolchain/bootstrap.sh)"
    exit "$kSkip"
fi
# Everything else is installed by toolchain/bootstrap.sh too; its absence is a failure, not a
# reason to skip.
for tool in busybox cpio gzip xz depmod modprobe dpkg apt-get apt-cache timeout; do
    command -v "$tool" >/dev/null 2>&1 || die "'$tool' not found (run bash toolchain/bootstrap.sh)"
done
[ -x "$guest" ] || die "guest program '$guest' does not exist or is not executable"

busybox=$(command -v busybox)
# The initramfs has no libraries: busybox and the guest must be static executables.
for exe in "$busybox" "$guest"; do
    if LC_ALL=C readelf -l "$exe" 2>/dev/null | grep -q 'INTERP'; then
        die "'$exe' is dynamically linked; the initramfs needs a static executable"
    fi
done

asRoot=()
if [ "$(id -u)" -ne 0 ]; then
    command -v sudo >/dev/null 2>&1 || die "apt-get update needs root or sudo"
    asRoot=(sudo)
fi

cache="$work/kernel-cache"
mkdir -p "$cache"

# --- 1. Which kernel: the package linux-image-amd64 depends on (linux-image-6.1.0-NN-amd64).
resolveKernelPackage() {
    apt-cache depends linux-image-amd64 2>/dev/null |
        sed -n 's/^ *Depends: \(linux-image-[0-9][^ ]*-amd64\)$/\1/p' | head -n 1
}
package=$(resolveKernelPackage || true)
if [ -z "$package" ]; then
    note "apt has no candidate for linux-image-amd64; running apt-get update"
    if ! "${asRoot[@]}" apt-get update -q >"$cache/apt-update.log" 2>&1; then
        tail -n 5 "$cache/apt-update.log" >&2
        die "apt-get update failed (log: $cache/apt-update.log)"
    fi
    package=$(resolveKernelPackage || true)
fi
if [ -z "$package" ]; then
    # Offline: fall back to a kernel downloaded by an earlier run, if any.
    cached=$(ls -1 "$cache"/linux-image-*-amd64_*.deb 2>/dev/null | sort -V | tail -n 1 || true)
    [ -n "$cached" ] || die "cannot resolve linux-image-amd64's kernel package and none is cached"
    package=$(basename "$cached" | sed 's/_.*//')
    note "using cached $package (apt could not resolve linux-image-amd64)"
fi
release=${package#linux-image-}

# --- 2. Download once into the cache and unpack it (no install on the host).
deb=$(ls -1 "$cache/${package}"_*.deb 2>/dev/null | sort -V | tail -n 1 || true)
if [ -z "$deb" ]; then
    note "downloading $package"
    if ! (cd "$cache" && apt-get -q -o APT::Sandbox::User=root download "$package" \
        >"$cache/apt-download.log" 2>&1); then
        tail -n 5 "$cache/apt-download.log" >&2
        die "apt-get download $package failed (log: $cache/apt-download.log)"
    fi
    deb=$(ls -1 "$cache/${package}"_*.deb 2>/dev/null | sort -V | tail -n 1 || true)
    [ -n "$deb" ] || die "apt-get download $package left no .deb in $cache"
    # A new kernel ABI replaces the old one in the cache.
    for old in "$cache"/linux-image-*.deb; do
        [ "$old" = "$deb" ] || rm -f "$old"
    done
    for old in "$cache"/*/; do
        [ "$old" = "$cache/$release/" ] || rm -rf "$old"
    done
fi

root="$cache/$release/root"
if [ ! -f "$cache/$release/unpacked" ]; then
    rm -rf "${cache:?}/${release:?}"
    mkdir -p "$root"
    dpkg -x "$deb" "$root" || die "dpkg -x $deb failed"
    depmod -b "$root" "$release" || die "depmod -b $root $release failed"
    touch "$cache/$release/unpacked"
fi
[ -d "$root/lib/modules/$release" ] || die "$deb has no lib/modules/$release"

# --- 3. The uncompressed vmlinux (PVH entry: boots directly, no firmware decompression).
vmlinuz="$root/boot/vmlinuz-$release"
vmlinux="$cache/$release/vmlinux"
[ -f "$vmlinuz" ] || die "$deb has no boot/vmlinuz-$release"
isElf() { [ "$(head -c 4 "$1" | od -An -tx1 | tr -d ' \n')" = "7f454c46" ]; }
if [ ! -f "$vmlinux" ]; then
    # The bzImage carries the kernel as an xz stream (magic FD 37 7A 58 5A 00); the first such
    # stream that decompresses to an ELF file is the kernel.
    for offset in $(LC_ALL=C grep -obUaP '\xFD7zXZ\x00' "$vmlinuz" | cut -d: -f1); do
        # xz stops reading at the stream's end, so tail may die of SIGPIPE: not an error.
        if { tail -c "+$((offset + 1))" "$vmlinuz" || true; } |
            xz -dc --single-stream >"$vmlinux.tmp" 2>/dev/null && isElf "$vmlinux.tmp"; then
            mv "$vmlinux.tmp" "$vmlinux"
            break
        fi
    done
    rm -f "$vmlinux.tmp"
fi
kernelImage=$vmlinux
if [ ! -f "$vmlinux" ]; then
    note "no xz-compressed ELF kernel found in $vmlinuz; booting the bzImage (slower)"
    kernelImage=$vmlinuz
fi

# --- 4. The initramfs: busybox, the modules in load order, the guest, /init.
modules=()
readonly kModules=(i2c-dev i2c-stub vfb)
for module in "${kModules[@]}"; do
    deps=$(modprobe -d "$root" -S "$release" --show-depends "$module" 2>&1) ||
        die "modprobe --show-depends $module: $deps"
    while read -r verb path _; do
        [ "$verb" = "insmod" ] || continue
        already=0
        for m in "${modules[@]}"; do [ "$m" = "$path" ] && already=1; done
        [ $already -eq 1 ] || modules+=("$path")
    done <<<"$deps"
done
[ ${#modules[@]} -gt 0 ] || die "no modules found for ${kModules[*]} in $release"

# The part that depends only on the kernel and busybox (a few hundred applet symlinks, ~2 s of
# forks) is kept between runs; the guest and /init are copied in every run. The stamp names the
# module list, so that adding a module rebuilds it.
stage="$work/initramfs"
baseStamp="$stage/.base-$release-$(echo "${kModules[*]}" | cksum | cut -d' ' -f1)"
if [ ! -f "$baseStamp" ] || [ "$busybox" -nt "$baseStamp" ]; then
    rm -rf "$stage"
    mkdir -p "$stage"/{bin,dev,proc,sys,etc,lib/modules/"$release"}
    cp "$busybox" "$stage/bin/busybox"
    for applet in $("$busybox" --list); do
        [ "$applet" = "busybox" ] || ln -s busybox "$stage/bin/$applet"
    done
    : >"$stage/etc/modules"
    for path in "${modules[@]}"; do
        # Modules may be shipped compressed (.ko.xz); busybox insmod wants them plain.
        name=$(basename "$path")
        case "$name" in
        *.ko.xz) xz -dc "$path" >"$stage/lib/modules/$release/${name%.xz}" ;;
        *.ko) cp "$path" "$stage/lib/modules/$release/$name" ;;
        *) die "unexpected module file $path" ;;
        esac
        echo "/lib/modules/$release/${name%.xz}" >>"$stage/etc/modules"
    done
    touch "$baseStamp"
fi
cp "$guest" "$stage/bin/caphub-guest"
cp "$(dirname "${BASH_SOURCE[0]}")/guest_init.sh" "$stage/init"
chmod 755 "$stage/init"
initramfs="$work/initramfs.cpio.gz"
(cd "$stage" && find . ! -name '.base-*' -print | LC_ALL=C sort | cpio -o -H newc --quiet |
    gzip -1 >"$initramfs") ||
    die "building the initramfs failed"

# --- 5. Boot. TCG (no KVM here), -M pc (microvm hung at times), the serial console on stdout;
# -no-reboot and panic=-1 turn a crash into an exit.
log="$work/guest-console.log"
note "booting $release ($(basename "$kernelImage")) under qemu (TCG), at most ${timeoutS} s"
start=$(date +%s%N)
set +e
timeout --kill-after=5 "$timeoutS" qemu-system-x86_64 -M pc -accel tcg -m 256M -smp 1 \
    -nographic -no-reboot -net none \
    -kernel "$kernelImage" -initrd "$initramfs" \
    -append "console=ttyS0 panic=-1 loglevel=4 i8042.noaux i8042.nokbd" \
    </dev/null >"$log" 2>&1
qemuStatus=$?
set -e
end=$(date +%s%N)
bootMs=$(((end - start) / 1000000))

# The guest's output, without the serial line's carriage returns and the firmware's terminal
# escapes.
sed -e 's/\r$//' -e 's/\x1b\[[0-9;?]*[A-Za-z]//g' -e 's/\x1bc//g' "$log"
echo "----"
note "boot to poweroff: $((bootMs / 1000)).$(printf '%03d' $((bootMs % 1000))) s"

if [ $qemuStatus -eq 124 ] || [ $qemuStatus -eq 137 ]; then
    die "qemu did not power off within ${timeoutS} s (log: $log)"
fi
if grep -q 'Kernel panic' "$log"; then
    die "the guest kernel panicked (log: $log)"
fi
if [ $qemuStatus -ne 0 ]; then
    die "qemu exited with status $qemuStatus (log: $log)"
fi
if grep -q "^$kMarker: FAIL" <(sed 's/\r$//' "$log"); then
    die "the guest reported failure: $(sed 's/\r$//' "$log" | grep "^$kMarker: FAIL" | head -n 1)"
fi
if ! grep -qx "$kMarker: PASS" <(sed 's/\r$//' "$log"); then
    die "the guest printed no '$kMarker: PASS' marker (log: $log)"
fi
note "PASS"
