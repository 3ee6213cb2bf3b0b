#!/usr/bin/env bash
# The flash test: builds a small disk image the way an SD card image is laid out (a partition
# table, a FAT boot partition with config.txt, an ext4 root with a minimal Debian tree and dpkg
# database), installs the host build's caphub .deb into it with toolchain/caphub-flash, and then
# checks the image independently of the tool's own verification.
#
#   flash_test.sh BUILD_DIR WORK_DIR
#
# CAPHUB_FLASH=FILE tests another caphub-flash (e.g. an older one) than toolchain/'s;
# CAPHUB_FLASH_DEB=FILE a .deb made elsewhere instead of packaging BUILD_DIR with cpack.
# The image's dpkg database declares the base libraries installed (libc6, libstdc++6, ...);
# every other dependency of the package is given as a small stand-in .deb this test builds,
# so that the dependency path of the tool is exercised without network access.
set -euo pipefail

build=$1
work=$2
src=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
flash=$(realpath "${CAPHUB_FLASH:-$src/toolchain/caphub-flash}")
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
if [ -n "${CAPHUB_FLASH_DEB:-}" ]; then
    mkdir -p "$work/pkg"
    cp "$CAPHUB_FLASH_DEB" "$work/pkg/"
else
    cpack -G DEB --config "$build/CPackConfig.cmake" -B "$work/pkg" >cpack.log 2>&1 || {
        tail -20 cpack.log
        exit 1
    }
fi
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
make_image() { # OUT ROOT_TREE CONFIG_TXT
    rm -rf img.tmp && mkdir img.tmp
    truncate -s 58M "$1"
    printf 'label: dos\nstart=2048, size=32768, type=c\nstart=34816, type=83\n' | sfdisk -q "$1"
    mkfs.vfat -C img.tmp/boot.img 16384 >/dev/null
    mcopy -i img.tmp/boot.img "$3" ::config.txt
    mkfs.ext4 -q -d "$2" -L rootfs img.tmp/root.img 40M
    dd if=img.tmp/boot.img of="$1" bs=512 seek=2048 conv=notrunc status=none
    dd if=img.tmp/root.img of="$1" bs=512 seek=34816 conv=notrunc status=none
    rm -rf img.tmp
}
make_image disk.img rootfs boot/config.txt
cp disk.img fresh.img # for the cases of 7.
root="disk.img?offset=$((34816 * 512))"
boot="disk.img@@$((2048 * 512))"

rd() { debugfs -R "cat \"$1\"" "$root" 2>/dev/null; }

# The checks below pipe a reader (debugfs, mtools) into grep -q, which leaves as soon as it
# finds its line: with pipefail the reader's SIGPIPE failed a check that had found it
# (flash.image_install failed so once under load). The checks take grep's word.
set +o pipefail

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
if grep -q '^caphub:x:[0-9]*:[0-9]*:.*:/usr/sbin/nologin$' <<<"$(rd /etc/passwd)"; then pass "the caphub user exists"; else fail "no caphub user"; fi
for g in i2c spi gpio video; do
    if grep -Eq "^$g:x:[0-9]+:(.*,)?caphub$" <<<"$(rd /etc/group)"; then pass "caphub is in group $g (once)"; else fail "group $g: $(rd /etc/group | grep "^$g:")"; fi
done
if [ "$(rd /etc/group | grep -c '^video:x:44:')" = 1 ]; then pass "the image's video group keeps its id"; else fail "video group changed"; fi
if grep -q '^i2c:!::caphub$' <<<"$(rd /etc/gshadow)"; then pass "gshadow has the new groups"; else fail "gshadow: $(rd /etc/gshadow | tr '\n' ' ')"; fi
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

if grep -qx /etc/caphub/caphub.conf <<<"$(rd /var/lib/dpkg/info/caphub.list)"; then
    pass "after a re-flash caphub.list still names the kept conffile /etc/caphub/caphub.conf"
else
    fail "caphub.list lacks /etc/caphub/caphub.conf after the re-flash"
fi
caphub_ids=$(rd /etc/passwd | awk -F: '$1=="caphub"{print $3, $4}')
state_ids=$(debugfs -R 'stat /var/lib/caphub' "$root" 2>/dev/null | awk '/Type: directory/ { d = 1 } /^User: / && d { print $2, $4 }')
if [ -n "$caphub_ids" ] && [ "$state_ids" = "$caphub_ids" ]; then
    pass "/var/lib/caphub is a folder owned by caphub ($caphub_ids) before the service's first start"
else
    fail "/var/lib/caphub: owner '$state_ids', caphub is '$caphub_ids'"
fi
if [ "$(sed -n '/^# caphub begin/{n;p;q}' config.out)" = "[all]" ]; then
    pass "config.txt's caphub block starts with [all]"
else
    fail "config.txt's block does not start with [all]: $(cat config.out)"
fi

# 7. Images and arguments the tool must handle or refuse cleanly. Each case flashes a copy of the
# fresh image (or one built for it) and checks the outcome independently.
ri() { debugfs -R "cat \"$2\"" "$1?offset=$((34816 * 512))" 2>/dev/null; } # IMAGE PATH
bi() { mcopy -n -i "$1@@$((2048 * 512))" ::config.txt - 2>/dev/null; }   # IMAGE
run() { # ARGS...: the tool's output in $out, its exit code in $rc
    set +e
    out=$("$flash" "$@" 2>&1)
    rc=$?
    set -e
}

# passwd and group without a final newline (hand-edited): the new entries are lines of their own.
rm -rf rootfs-nl && cp -a rootfs rootfs-nl
printf 'root:x:0:0:root:/root:/bin/bash\npi:x:1000:1000:,,,:/home/pi:/bin/bash' >rootfs-nl/etc/passwd
printf 'root:x:0:\nvideo:x:44:pi\nshadow:x:42:\npi:x:1000:' >rootfs-nl/etc/group
make_image nl.img rootfs-nl boot/config.txt
run --image nl.img --board rpi4-suit --deb "$deb" --deps deps
if [ $rc -eq 0 ] && ri nl.img /etc/passwd | grep -qx 'pi:x:1000:1000:,,,:/home/pi:/bin/bash' &&
    ri nl.img /etc/passwd | grep -q '^caphub:x:[0-9]*:[0-9]*:.*:/usr/sbin/nologin$' &&
    ri nl.img /etc/group | grep -qx 'pi:x:1000:' && ri nl.img /etc/group | grep -q '^i2c:x:[0-9]*:caphub$'; then
    pass "passwd/group without a final newline: no entry is joined to the last line"
else
    fail "passwd/group without a final newline: exit $rc, passwd: $(ri nl.img /etc/passwd | tr '\n' '|') group: $(ri nl.img /etc/group | tr '\n' '|') output: $out"
fi

# A full boot partition: refused before anything is written, config.txt kept.
{
    printf '# Raspberry Pi settings\narm_64bit=1\nenable_uart=1\n'
    # 1.9 KiB: one 2 KiB cluster now, two with the board's lines
    for _ in $(seq 40); do echo '# the user comments of a well-kept config.txt'; done
} >config-full.txt
make_image full.img rootfs config-full.txt
head -c "$(mdir -i "full.img@@$((2048 * 512))" :: | sed -n 's/ bytes free$//p' | tr -cd '0-9')" /dev/zero >fill.bin
mcopy -i "full.img@@$((2048 * 512))" fill.bin ::fill.bin
rm -f fill.bin
run --image full.img --board rpi4-suit --deb "$deb" --deps deps
if [ $rc -eq 1 ] && [[ "$out" == *"boot partition has 0 bytes free"*"nothing was changed"* ]] &&
    bi full.img | cmp -s - config-full.txt && [ -z "$(ri full.img /usr/bin/caphub)" ]; then
    pass "a full boot partition is refused (exit 1) before anything is written; config.txt kept"
else
    fail "full boot partition: exit $rc, config.txt $(bi full.img | cmp -s - config-full.txt && echo kept || echo changed/lost), output: $out"
fi

# "# caphub begin" without "# caphub end": refused (exit 2) naming the line; nothing changed.
printf 'arm_64bit=1\n# caphub begin: old\ndtparam=i2c_arm=on\nenable_uart=1\ngpu_mem=128\n' >config-open.txt
make_image open.img rootfs config-open.txt
run --image open.img --board rpi4-suit --deb "$deb" --deps deps
if [ $rc -eq 2 ] && [[ "$out" == *"'# caphub begin' at line 2 without '# caphub end'"* ]] &&
    bi open.img | cmp -s - config-open.txt && [ -z "$(ri open.img /usr/bin/caphub)" ]; then
    pass "an unterminated caphub block is refused (exit 2, line 2), nothing written"
else
    fail "unterminated caphub block: exit $rc, config.txt: $(bi open.img | tr '\n' '|') output: $out"
fi

# config.txt ending in a conditional section: the block starts with [all]; on a re-flash the
# user's lines after the old block stay in [all].
printf 'arm_64bit=1\n[pi4]\ndtoverlay=vc4-fkms-v3d\nmax_framebuffers=2\n' >config-pi4.txt
make_image pi4.img rootfs config-pi4.txt
run --image pi4.img --board rpi-zero2w-suit --deb "$deb" --deps deps
rc1=$rc
bi pi4.img >config-pi4.out
if [ $rc1 -eq 0 ] && [ "$(sed -n '/^# caphub begin/{n;p;q}' config-pi4.out)" = "[all]" ]; then
    pass "after a [pi4] section the caphub block starts with [all]"
else
    fail "[pi4] section: exit $rc1, config.txt: $(tr '\n' '|' <config-pi4.out)"
fi
echo 'gpu_mem=99' >>config-pi4.out
mcopy -o -i "pi4.img@@$((2048 * 512))" config-pi4.out ::config.txt
run --image pi4.img --board rpi-zero2w-suit --deb "$deb" --deps deps
if [ $rc -eq 0 ] && bi pi4.img | grep -B1 -x 'gpu_mem=99' | head -1 | grep -qx '\[all\]' &&
    [ "$(bi pi4.img | grep -c '^# caphub begin')" = 1 ] && [ "$(bi pi4.img | tail -1)" = "# caphub end" ]; then
    pass "a re-flash keeps the user's lines after the old block in [all]"
else
    fail "re-flash after [pi4]: exit $rc, config.txt: $(bi pi4.img | tr '\n' '|')"
fi

# --root mode into a folder tree: installs (relative symbolic links are the card's own) ...
rm -rf card && mkdir -p card/boot && cp -a rootfs card/root && cp boot/config.txt card/boot/
mkdir -p card/root/usr/lib/udev && ln -s usr/lib/udev card/root/udev-link
run --root card/root --boot card/boot --board rpi4-suit --deb "$deb" --deps deps
if [ $rc -eq 0 ] && cmp -s card/root/etc/caphub/board.toml "$src/board/rpi4-suit.toml" &&
    [ "$(stat -c '%u %g' card/root/var/lib/caphub)" = "$(awk -F: '$1=="caphub"{print $3, $4}' card/root/etc/passwd)" ] &&
    grep -qx '\[all\]' card/boot/config.txt; then
    pass "--root mode installs into a mounted tree, /var/lib/caphub owned by caphub"
else
    fail "--root mode: exit $rc, output: $out"
fi
# ... but refuses an absolute symbolic link on the card, which the host would resolve to its own
# files (exit 2), writing nothing anywhere.
rm -rf card && mkdir -p card/boot victim && cp -a rootfs card/root && cp boot/config.txt card/boot/
echo 'a host file' >victim/board.toml
ln -s "$work/victim" card/root/etc/caphub
run --root card/root --boot card/boot --board rpi4-suit --deb "$deb" --deps deps
if [ $rc -eq 2 ] && [[ "$out" == *"/etc/caphub leads to $work/victim, outside"* ]] &&
    [ "$(cat victim/board.toml)" = 'a host file' ] && [ "$(ls victim)" = board.toml ] &&
    [ ! -e card/root/usr/bin/caphub ] && cmp -s card/boot/config.txt boot/config.txt; then
    pass "--root mode refuses a card symbolic link leading out of the card (exit 2), nothing written"
else
    fail "--root symlink escape: exit $rc, host folder: $(find victim | tr '\n' ' ') board.toml: $(head -1 victim/board.toml) output: $out"
fi

# A nearly full root file system: refused before writing (never a half-installed package that
# dpkg calls installed).
cp fresh.img rootfull.img
rf="rootfull.img?offset=$((34816 * 512))"
free_kib=$(debugfs -R 'stats -h' "$rf" 2>/dev/null | awk '/^Free blocks:/ { f = $3 } /^Block size:/ { b = $3 } END { print int(f * b / 1024) }')
head -c "$(((free_kib - 1024) * 1024))" /dev/zero | tr '\0' x >fill.bin # (zeros would be holes)
debugfs -w -R "write fill.bin fill" "$rf" >/dev/null 2>&1
rm -f fill.bin
run --image rootfull.img --board rpi4-suit --deb "$deb" --deps deps
if [ $rc -eq 1 ] && [[ "$out" == *"root file system has"*"nothing was changed"* ]] &&
    ! ri rootfull.img /var/lib/dpkg/status | grep -q '^Package: caphub$' && [ -z "$(ri rootfull.img /usr/bin/caphub)" ] &&
    bi rootfull.img | cmp -s - boot/config.txt; then
    pass "a nearly full root file system is refused (exit 1) before anything is written"
else
    fail "full root file system: exit $rc, dpkg status: $(ri rootfull.img /var/lib/dpkg/status | grep -A1 '^Package: caphub$' | tr '\n' ' ') output: $out"
fi

# --board is the name of one of the package's board files, not a path.
mkdir -p evil && printf '[board]\nname = "evil"\n' >evil/x.toml && echo 'dtoverlay=evil' >evil/x.config.txt
cp fresh.img board.img
run --image board.img --board "../../../../../../../../..$work/evil/x" --deb "$deb" --deps deps
if [ $rc -eq 2 ] && [[ "$out" == *"not a board name"* ]] && [ -z "$(ri board.img /usr/bin/caphub)" ]; then
    pass "--board with a path is refused (exit 2)"
else
    fail "--board path: exit $rc, output: $out"
fi

# Image paths with a '?' (debugfs' option separator), "@@" (mtools' offset) and a leading '-'.
mkdir -p 'q?x' 'a@@1'
cp fresh.img 'q?x/disk.img'
cp fresh.img 'a@@1/disk.img'
cp fresh.img ./-d.img
for img in 'q?x/disk.img' 'a@@1/disk.img' -d.img; do
    run --image "$img" --board rpi4-suit --deb "$deb" --deps deps
    ln -sfn "$work/$img" check.img # a name debugfs takes as it is
    if [ $rc -eq 0 ] && ri check.img /usr/bin/caphub | cmp -s - caphub.bin; then
        pass "an image path like '$img' works"
    else
        fail "image path '$img': exit $rc, output: $out"
    fi
done
run --image fresh.img --board
if [ $rc -eq 2 ] && [[ "$out" == *"--board needs a value"* ]]; then
    pass "an option without its value is a usage error (exit 2)"
else
    fail "option without a value: exit $rc, output: $out"
fi

# The package's postinst makes /var/lib/caphub for caphub (commands stubbed, nothing changed).
mkdir -p postinst-run/bin postinst-run/ctl
dpkg-deb -e "$deb" postinst-run/ctl
for c in getent addgroup adduser mkdir chown udevadm deb-systemd-helper systemctl; do
    printf '#!/bin/sh\necho "%s $*" >>"%s"\n' "$c" "$work/postinst-run/calls" >"postinst-run/bin/$c"
    chmod +x "postinst-run/bin/$c"
done
rm -f postinst-run/calls
if PATH="$work/postinst-run/bin" /bin/sh postinst-run/ctl/postinst configure >postinst-run/log 2>&1 &&
    grep -qx 'chown caphub:caphub /var/lib/caphub' postinst-run/calls &&
    { [ -d /var/lib/caphub ] || grep -q '^mkdir .*/var/lib/caphub$' postinst-run/calls; }; then
    pass "postinst configure makes /var/lib/caphub owned by caphub"
else
    fail "postinst: $(cat postinst-run/log postinst-run/calls 2>/dev/null | tr '\n' '|')"
fi

echo "flash test: $failures failure(s)"
exit $((failures > 0))
