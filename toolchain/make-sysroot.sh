#!/usr/bin/env bash
# Assembles a cross sysroot for arm64 or armhf from Debian 12 packages: the packages named in
# toolchain/sysroot-packages.txt and everything they depend on are downloaded and unpacked into
# a folder with dpkg -x. Nothing is installed on the host: a multiarch install would pull
# i2c-tools:ARCH for libi2c-dev, which is not multi-arch and would replace the host's.
#
#   make-sysroot.sh ARCH [DIR]     ARCH: arm64 (or aarch64) | armhf; DIR: build/sysroot/ARCH
#
# apt runs with a private state folder and the target architecture (the host's apt
# configuration and package lists stay untouched). Downloads are cached in build/sysroot-cache/
# ARCH; a second run with the same package list does nothing. The control files of every
# package (shlibs, symbols) are kept in DIR/var/lib/caphub-sysroot/info for the package's
# dependency computation (toolchain/cpack_shlibdeps.cmake).
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)

case "${1:-}" in
arm64 | aarch64) arch=arm64 ;;
armhf) arch=armhf ;;
*)
    sed -n '7p' "${BASH_SOURCE[0]}" | sed 's/^# *//' >&2
    exit 2
    ;;
esac
sysroot=${2:-$root/build/sysroot/$arch}
cache=$root/build/sysroot-cache/$arch
list=$root/toolchain/sysroot-packages.txt

mapfile -t wanted < <(sed -e 's/#.*//' -e 's/[[:space:]]//g' "$list" | grep -v '^$')
# The stamp holds the package list and this script's checksum: a sysroot made by an older
# version of the script (say, before a fix-up of the CMake package files below) is made again.
stamp_text="$(printf '%s\n' "${wanted[@]}")
script $(sha256sum "${BASH_SOURCE[0]}" | cut -d' ' -f1)"
if [ -f "$sysroot/.caphub-sysroot" ] && [ "$(cat "$sysroot/.caphub-sysroot")" = "$stamp_text" ]; then
    echo "make-sysroot: $sysroot is up to date (${#wanted[@]} packages listed)"
    exit 0
fi

# A private apt: the host's sources, the target's architecture, state and cache under $cache.
apt_dir=$cache/apt
mkdir -p "$apt_dir/lists/partial" "$apt_dir/archives/partial" "$cache/debs"
: >"$apt_dir/status"
apt_opts=(
    -o "APT::Architecture=$arch" -o "APT::Architectures::=$arch"
    -o "Dir::State=$apt_dir" -o "Dir::State::Lists=$apt_dir/lists"
    -o "Dir::State::status=$apt_dir/status" -o "Dir::Cache=$apt_dir"
    -o "Dir::Cache::archives=$apt_dir/archives"
    -o "Debug::NoLocking=1" -o "APT::Sandbox::User=root"
)
if [ ! -f "$apt_dir/updated" ] || [ -n "$(find "$apt_dir/updated" -mtime +7)" ]; then
    echo "make-sysroot: updating the $arch package lists"
    # A mirror in the middle of a sync answers with index files of the wrong size: try again.
    for attempt in 1 2 3 4; do
        if apt-get "${apt_opts[@]}" -q update >"$cache/apt-update.log" 2>&1 &&
            ! grep -q '^E:' "$cache/apt-update.log"; then
            break
        fi
        if [ "$attempt" -eq 4 ]; then
            # A suite whose index stays broken (bookworm-security mid-sync) leaves the others:
            # go on with those, and update again on the next run.
            if [ -n "$(find "$apt_dir/lists" -maxdepth 1 -name '*_main_binary-*_Packages*' -print -quit)" ]; then
                echo "make-sysroot: warning: some package lists failed, using those that did:" >&2
                grep '^E:' "$cache/apt-update.log" | head -3 >&2
                rm -f "$apt_dir/updated"
                break
            fi
            tail -20 "$cache/apt-update.log" >&2
            exit 1
        fi
        echo "make-sysroot: apt-get update failed (attempt $attempt), retrying in 20 s"
        sleep 20
    done
    if ! grep -q '^E:' "$cache/apt-update.log"; then
        touch "$apt_dir/updated"
    fi
fi

# The dependency closure; <virtual> names are provided by a real package already in the list.
mapfile -t closure < <(apt-cache "${apt_opts[@]}" depends --recurse --no-recommends \
    --no-suggests --no-conflicts --no-breaks --no-replaces --no-enhances "${wanted[@]}" |
    grep -E '^[a-z0-9]' | sort -u)
echo "make-sysroot: ${#wanted[@]} listed packages, ${#closure[@]} with their dependencies"

# The candidate version of each (one apt-cache run: each run reads all package lists).
declare -A version=()
while read -r p v; do
    version[$p]=${v//:/%3a}
done < <(apt-cache "${apt_opts[@]}" show --no-all-versions "${closure[@]}" |
    awk '/^Package: /{p=$2} /^Version: /{print p, $2}')

# Download what the cache does not hold yet (apt-get download names files pkg_version_arch.deb).
missing=()
for p in "${closure[@]}"; do
    v=${version[$p]:-}
    [ -n "$v" ] || { echo "make-sysroot: no version of $p in the $arch lists" >&2; exit 1; }
    if ! compgen -G "$cache/debs/${p}_${v}_*.deb" >/dev/null; then
        missing+=("$p")
    fi
done
if [ ${#missing[@]} -gt 0 ]; then
    echo "make-sysroot: downloading ${#missing[@]} packages"
    (cd "$cache/debs" && apt-get "${apt_opts[@]}" -q download "${missing[@]}" \
        >"$cache/apt-download.log" 2>&1) || {
        tail -20 "$cache/apt-download.log" >&2
        exit 1
    }
fi

# Unpack into a fresh folder, so a package removed from the list leaves nothing behind.
rm -rf "$sysroot.tmp"
mkdir -p "$sysroot.tmp/var/lib/caphub-sysroot/info"
for p in "${closure[@]}"; do
    deb=$(compgen -G "$cache/debs/${p}_${version[$p]}_*.deb" | head -1)
    dpkg-deb -x "$deb" "$sysroot.tmp"
    ctl=$(mktemp -d)
    dpkg-deb -e "$deb" "$ctl"
    for f in control shlibs symbols; do
        [ -f "$ctl/$f" ] && cp "$ctl/$f" "$sysroot.tmp/var/lib/caphub-sysroot/info/$p.$f"
    done
    rm -rf "$ctl"
done

# Debian 12 is merged-/usr: /lib is /usr/lib. The packages still ship some files under /lib
# (the dynamic loader's path is /lib/ld-linux-*.so.*), so give the sysroot the same layout.
for d in lib bin sbin; do
    if [ -d "$sysroot.tmp/$d" ] && [ ! -L "$sysroot.tmp/$d" ]; then
        mkdir -p "$sysroot.tmp/usr/$d"
        cp -a "$sysroot.tmp/$d/." "$sysroot.tmp/usr/$d/"
        rm -rf "$sysroot.tmp/$d"
    fi
    if [ -d "$sysroot.tmp/usr/$d" ]; then
        ln -sfn "usr/$d" "$sysroot.tmp/$d"
    fi
done

# Absolute symbolic links (e.g. lib/ld-linux-aarch64.so.1 -> /usr/lib/...) would point into the
# host; rewrite them relative to the sysroot.
while IFS= read -r -d '' link; do
    target=$(readlink "$link")
    case "$target" in
    /*)
        rel=$(realpath -m --relative-to="$(dirname "$link")" "$sysroot.tmp$target")
        ln -sfn "$rel" "$link"
        ;;
    esac
done < <(find "$sysroot.tmp" -type l -print0)

# Some CMake package files name their libraries by absolute path (libjpeg-turbo's
# "/usr/lib/<triplet>/libjpeg.so.62.3.0", toml++'s prefix "/usr"): point those at the sysroot.
while IFS= read -r -d '' f; do
    if grep -q '"/usr[/"]' "$f"; then
        sed -i -e 's|"/usr/|"${CMAKE_SYSROOT}/usr/|g' -e 's|"/usr"|"${CMAKE_SYSROOT}/usr"|g' "$f"
    fi
done < <(find "$sysroot.tmp/usr/lib" "$sysroot.tmp/usr/share" -path '*/cmake/*' -name '*.cmake' -print0)

printf '%s\n' "$stamp_text" >"$sysroot.tmp/.caphub-sysroot"
rm -rf "$sysroot"
mv "$sysroot.tmp" "$sysroot"
echo "make-sysroot: $sysroot ready ($(du -sh "$sysroot" | cut -f1))"
