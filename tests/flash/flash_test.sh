#!/usr/bin/env bash
# The flash test: builds a small disk image the way an SD card image is laid out (a partition
# table, a FAT boot partition with config.txt, an ext4 root with a minimal Debian tree and dpkg
# database), installs the host build's caphub .deb into it with toolchain/caphub-flash, and then
# checks the image independently of the tool's own verification.
#
#   flash_test.sh BUILD_DIR WORK_DIR
#
# The image's dpkg database declares the base libraries installed (libc6, libstdc++6, ...);
# every other dependency of the package is given as a small stand-in .deb this test builds,
# so that the dependency path of the tool is exercised without network access.
set -euo pipefail

build=$1
work=$2
src=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
flash=$src/toolchain/caphub-flash
rm -rf "$work"
mkdir -p "$work"
cd "$work"
failures=0
pass() { echo "PASS: $*"; }
fail() {
    echo "FAIL: $*"
    failures=$((failures + 1))
}

# 1. The package, from this build.
cpack -G DEB --config "$build/CPackConfig.cmake" -B "$work/pkg" >cpack.log 2>&1 || {
    tail -20 cpack.log
    exit 1
}
deb=$(ls "$work"/pkg/caphub_*.deb)
arch=$(dpkg-deb -f "$deb" Architecture)
echo "package: $(basename "$deb")"

# 1b. The package's program is for the package's architecture, and its Depends names the
# package of every shared library the program links (found here with ldconfig and dpkg -S,
# independently of dpkg-shlibdeps, which made the field).
dpkg-deb --fsys-tarfile "$deb" | tar -xOf - ./usr/bin/caphub >caphub.bin
case "$arch" in
amd64) machine="x86-64" ;;
arm64) machine="ARM aarch64" ;;
armhf) machine="ARM, EABI5" ;;
*) machine="unknown architecture $arch" ;;
esac
if file -b caphub.bin | grep -q "ELF .*$machine"; then
    pass "the package's program is an ELF for $arch ($machine)"
else
    fail "package $arch holds: $(file -b caphub.bin)"
fi
depends=$(dpkg-deb -f "$deb" Depends)
depNames=$(echo "$depends" | tr ',|' '\n\n' | sed -e 's/(.*)//' -e 's/:.*//' -e 's/[[:space:]]//g')
for so in $(objdump -p caphub.bin | awk '$1 == "NEEDED" {print $2}'); do
    # ldconfig -p: "libfmt.so.9 (libc6,x86-64) => /usr/lib/x86_64-linux-gnu/libfmt.so.9".
    # (awk reads to the end: an early exit would end ldconfig with SIGPIPE, fatal under pipefail)
    lib=$(ldconfig -p | awk -v s="$so" -v m="$machine" '!found && $1 == s && (m != "x86-64" || /x86-64/) {print $NF; found = 1}')
    owner=""
    for f in "$lib" "$(realpath -e "$lib" 2>/dev/null)" "${lib#/usr}" "/usr${lib#/usr}"; do
        [ -n "$f" ] || continue
        owner=$(dpkg -S "$f" 2>/dev/null | sed -n '1s/:.*//p') && [ -n "$owner" ] && break
    done
    # The package, or a virtual package it provides (libspdlog1.10 provides libspdlog1.10-fmt9,
    # the name its shlibs file asks for).
    names="$owner"
    if [ -n "$owner" ]; then
        names+=$'\n'$(dpkg-query -W -f='${Provides}' "$owner" 2>/dev/null | tr ',' '\n' |
            sed -e 's/(.*)//' -e 's/:.*//' -e 's/[[:space:]]//g')
    fi
    if [ -n "$owner" ] && grep -qxF -f <(grep -v '^$' <<<"$names") <<<"$depNames"; then
        pass "$so ($owner) is in Depends"
    else
        fail "$so: owner '${owner:-not found}' not in Depends: $depends"
    fi
done

# 2. Stand-ins for the dependencies a base image lacks.
base=(libc6 libstdc++6 libgcc-s1 adduser)
mkdir -p deps
IFS=',' read -r -a entries <<<"$(dpkg-deb -f "$deb" Depends)"
standins=()
for e in "${entries[@]}"; do
    name=$(echo "${e%%|*}" | sed -e 's/(.*)//' -e 's/[[:space:]]//g')
    [[ " ${base[*]} " == *" $name "* ]] && continue
    mkdir -p "sd/$name/DEBIAN" "sd/$name/usr/share/doc/$name"
    echo "stand-in for $name, made by the caphub flash test" >"sd/$name/usr/share/doc/$name/flash-test"
    printf 'Package: %s\nVersion: 999\nArchitecture: %s\nMaintainer: test <test@localhost>\nDescription: flash test stand-in\n' \
        "$name" "$arch" >"sd/$name/DEBIAN/control"
    dpkg-deb --root-owner-group -b "sd/$name" "deps/${name}_999_$arch.deb" >/dev/null
    standins+=("$name")
done
echo "stand-in dependencies: ${standins[*]:-none}"

# 3. The image: 1 MiB alignment, 16 MiB FAT boot, 40 MiB ext4 root.
mkdir -p rootfs/etc rootfs/usr/bin rootfs/usr/lib rootfs/var/lib/dpkg/info rootfs/lib/systemd/system \
    rootfs/etc/systemd/system/multi-user.target.wants boot
printf 'root:x:0:0:root:/root:/bin/bash\ndaemon:x:1:1:daemon:/usr/sbin:/usr/sbin/nologin\n' >rootfs/etc/passwd
printf 'root:x:0:\ndaemon:x:1:\nvideo:x:44:\nshadow:x:42:\n' >rootfs/etc/group
printf 'root:*:19000:0:99999:7:::\ndaemon:*:19000:0:99999:7:::\n' >rootfs/etc/shadow
printf 'root:*::\ndaemon:*::\nvideo:*::\nshadow:*::\n' >rootfs/etc/gshadow
for p in "${base[@]}"; do
    a=$arch
    [ "$p" = adduser ] && a=all
    printf 'Package: %s\nStatus: install ok installed\nVersion: 1\nArchitecture: %s\nDescription: base\n\n' "$p" "$a"
done >rootfs/var/lib/dpkg/status
printf '# Raspberry Pi settings\narm_64bit=1\n' >boot/config.txt
truncate -s 58M disk.img
printf 'label: dos\nstart=2048, size=32768, type=c\nstart=34816, type=83\n' | sfdisk -q disk.img
mkfs.vfat -C boot.img 16384 >/dev/null
mcopy -i boot.img boot/config.txt ::config.txt
mkfs.ext4 -q -d rootfs -L rootfs root.img 40M
dd if=boot.img of=disk.img bs=512 seek=2048 conv=notrunc status=none
dd if=root.img of=disk.img bs=512 seek=34816 conv=notrunc status=none
root="disk.img?offset=$((34816 * 512))"
boot="disk.img@@$((2048 * 512))"

rd() { debugfs -R "cat \"$1\"" "$root" 2>/dev/null; }

# 4. Bad input is refused with a clear message and exit code 2, the image untouched.
set +e
out=$("$flash" --image disk.img --board no-such-board --deb "$deb" --deps deps 2>&1)
rc=$?
set -e
if [ $rc -eq 2 ] && [[ "$out" == *"no board 'no-such-board'"* ]]; then
    pass "an unknown board is refused (exit 2) and the message lists the shipped boards"
else
    fail "unknown board: exit $rc, output: $out"
fi
if [ -z "$(rd /usr/bin/caphub)" ]; then pass "a refused flash writes nothing"; else fail "a refused flash wrote /usr/bin/caphub"; fi
set +e
out=$("$flash" --image disk.img --board rpi-zero2w-suit --deb "$deb" 2>&1)
rc=$?
set -e
if [ ${#standins[@]} -eq 0 ] || { [ $rc -ne 0 ] && [[ "$out" == *"dependency '"*"' of caphub is not installed in the image"* ]]; }; then
    pass "a dependency neither in the image nor in --deps is an error"
else
    fail "missing dependency: exit $rc, output: $out"
fi

# 5. The install, then a second one (re-flash) that must not duplicate anything.
"$flash" --image disk.img --board rpi-zero2w-suit --deb "$deb" --deps deps | tee flash1.log
"$flash" --image disk.img --board rpi-zero2w-suit --deb "$deb" --deps deps >flash2.log

# 6. Independent checks of the image.
if rd /usr/bin/caphub | cmp -s - <(dpkg-deb --fsys-tarfile "$deb" | tar -xOf - ./usr/bin/caphub); then
    pass "/usr/bin/caphub is the package's program"
else
    fail "/usr/bin/caphub is missing or differs"
fi
for f in /lib/systemd/system/caphub.service /lib/udev/rules.d/60-caphub.rules /etc/caphub/caphub.conf \
    /usr/share/caphub/board/rpi4-suit.toml /usr/share/caphub/board/sim-suit.toml; do
    if [ -n "$(rd "$f")" ]; then pass "$f is installed"; else fail "$f is missing"; fi
done
if rd /etc/caphub/board.toml | cmp -s - "$src/board/rpi-zero2w-suit.toml"; then
    pass "/etc/caphub/board.toml is the chosen board's file"
else
    fail "/etc/caphub/board.toml is not board/rpi-zero2w-suit.toml"
fi
link=$(debugfs -R 'stat /etc/systemd/system/multi-user.target.wants/caphub.service' "$root" 2>/dev/null |
    sed -n 's/^Fast link dest: "\(.*\)"$/\1/p')
if [ "$link" = /lib/systemd/system/caphub.service ]; then pass "the service is enabled"; else fail "service link: '$link'"; fi
if rd /etc/passwd | grep -q '^caphub:x:[0-9]*:[0-9]*:.*:/usr/sbin/nologin$'; then pass "the caphub user exists"; else fail "no caphub user"; fi
for g in i2c spi gpio video; do
    if rd /etc/group | grep -Eq "^$g:x:[0-9]+:(.*,)?caphub$"; then pass "caphub is in group $g (once)"; else fail "group $g: $(rd /etc/group | grep "^$g:")"; fi
done
if [ "$(rd /etc/group | grep -c '^video:x:44:')" = 1 ]; then pass "the image's video group keeps its id"; else fail "video group changed"; fi
if rd /etc/gshadow | grep -q '^i2c:!::caphub$'; then pass "gshadow has the new groups"; else fail "gshadow: $(rd /etc/gshadow | tr '\n' ' ')"; fi
mcopy -n -i "$boot" ::config.txt config.out
while IFS= read -r line; do
    [ -n "$line" ] || continue
    [ "$(grep -cxF -- "$line" config.out)" = 1 ] || fail "config.txt has '$line' $(grep -cxF -- "$line" config.out) times"
done < <(grep -v '^#' "$src/board/rpi-zero2w-suit.config.txt")
if grep -q '^arm_64bit=1$' config.out && [ "$(grep -c '^# caphub begin' config.out)" = 1 ]; then
    pass "config.txt keeps its own lines and has the board's lines once after two flashes"
else
    fail "config.txt: $(cat config.out)"
fi
status=$(rd /var/lib/dpkg/status)
if [ "$(echo "$status" | grep -c '^Package: caphub$')" = 1 ] &&
    echo "$status" | grep -A1 '^Package: caphub$' | grep -q 'Status: install ok installed'; then
    pass "dpkg knows caphub as installed (once)"
else
    fail "dpkg status: $status"
fi
if echo "$status" | grep -A12 '^Package: caphub$' | grep -q '^ /etc/caphub/board.toml [0-9a-f]\{32\}$'; then
    pass "the conffiles are registered with their checksums"
else
    fail "no Conffiles for /etc/caphub/board.toml"
fi
for s in "${standins[@]}"; do
    if [ -n "$(rd "/usr/share/doc/$s/flash-test")" ] && echo "$status" | grep -q "^Package: $s$"; then
        pass "the missing dependency $s was unpacked and registered"
    else
        fail "dependency $s not installed"
    fi
done
if [ -n "$(rd /var/lib/dpkg/info/caphub.postinst)" ]; then pass "the maintainer scripts are kept for dpkg"; else fail "no caphub.postinst"; fi
if grep -q "keeping the image's /etc/caphub/caphub.conf" flash2.log; then
    pass "a re-flash keeps the image's conffiles"
else
    fail "re-flash did not keep conffiles: $(cat flash2.log)"
fi
if e2fsck -fn "$(dd if=disk.img of=root.check bs=512 skip=34816 status=none && echo root.check)" >e2fsck.log 2>&1; then
    pass "the root file system is consistent (e2fsck -fn)"
else
    fail "e2fsck: $(tail -5 e2fsck.log)"
fi

echo "flash test: $failures failure(s)"
exit $((failures > 0))
