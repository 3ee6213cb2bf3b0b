#!/usr/bin/env bash
# toolchain/cpack_shlibdeps.cmake (the Depends of a cross package) agrees with dpkg-shlibdeps:
# both run on this host build's program, the cross script reading the host's own symbols and
# shlibs files from a folder laid out like a sysroot's var/lib/caphub-sysroot/info.
#
#   shlibdeps_test.sh PROGRAM WORK_DIR
set -euo pipefail

program=$1
work=$2
src=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
rm -rf "$work"
mkdir -p "$work/sysroot/var/lib/caphub-sysroot/info" "$work/pkg/debian"
cd "$work"

# The control files of the packages that own the program's libraries, named as make-sysroot.sh
# names them (PACKAGE.symbols, PACKAGE.shlibs).
for so in $(objdump -p "$program" | awk '$1 == "NEEDED" {print $2}'); do
    # (awk reads to the end: an early exit would end ldconfig with SIGPIPE, fatal under pipefail)
    lib=$(ldconfig -p | awk -v s="$so" '!found && $1 == s && /x86-64/ {print $NF; found = 1}')
    owner=""
    for f in "$lib" "$(realpath -e "$lib")" "${lib#/usr}"; do
        owner=$(dpkg -S "$f" 2>/dev/null | sed -n '1s/:.*//p') && [ -n "$owner" ] && break
    done
    [ -n "$owner" ] || { echo "FAIL: no package owns $so ($lib)"; exit 1; }
    for kind in symbols shlibs; do
        for c in "/var/lib/dpkg/info/$owner:amd64.$kind" "/var/lib/dpkg/info/$owner.$kind"; do
            if [ -f "$c" ]; then
                cp "$c" "sysroot/var/lib/caphub-sysroot/info/$owner.$kind"
                break
            fi
        done
    done
done

expected=$(cd pkg && printf 'Source: t\nMaintainer: t <t@localhost>\n\nPackage: t\nArchitecture: any\nDescription: t\n' \
    >debian/control && dpkg-shlibdeps -O -e "$program" 2>/dev/null | sed -n 's/^shlibs:Depends=//p')
actual=$(cmake -DCPACK_GENERATOR=DEB -DCPACK_CAPHUB_OBJDUMP=objdump -DCPACK_CAPHUB_PROGRAM="$program" \
    -DCPACK_CAPHUB_SYSROOT="$work/sysroot" -DCPACK_DEBIAN_PACKAGE_DEPENDS= \
    -P "$src/toolchain/cpack_shlibdeps.cmake" 2>&1 | sed -n 's/^-- cpack_shlibdeps: Depends: //p')
echo "dpkg-shlibdeps:     $expected"
echo "cpack_shlibdeps:    $actual"
if [ -n "$expected" ] && [ "$actual" = "$expected" ]; then
    echo "PASS: cpack_shlibdeps.cmake gives dpkg-shlibdeps' Depends"
else
    echo "FAIL: the two differ"
    exit 1
fi
