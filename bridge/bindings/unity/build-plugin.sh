#!/usr/bin/env bash
# Builds libvrsync_host (crate vrsync-host-ffi) and places it where the Unity package loads
# it: com.vrsync.host/Runtime/Plugins/x86_64/libvrsync_host.so, whose committed .meta makes
# it a native plugin for the editor and standalone players on Linux x86_64. The library is
# never committed (it is built for the machine's platform and protocol version).
#
# usage: bash bridge/bindings/unity/build-plugin.sh [--debug] [--no-build] [--dest DIR]
#   --debug     the debug build (default: --release, what a player should ship)
#   --no-build  place the library cargo already built (target/<profile>/) without building
#   --dest DIR  place it in DIR instead (e.g. YourProject/Assets/Plugins/x86_64 when the
#               package comes from a git URL, whose copy in Library/PackageCache is read-only);
#               a .meta with the same importer settings and a new GUID is written beside it
# Linux x86_64 only: the only platform built and tested here.
set -euo pipefail

here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../../.." && pwd)"
plugins="$here/com.vrsync.host/Runtime/Plugins/x86_64"
profile=release
build=1
dest="$plugins"
while (($#)); do
    case "$1" in
        --debug) profile=debug ;;
        --release) profile=release ;;
        --no-build) build=0 ;;
        --dest)
            dest="${2:?--dest needs a directory}"
            shift
            ;;
        -h | --help)
            sed -n '2,14p' "$0"
            exit 0
            ;;
        *)
            echo "build-plugin.sh: unknown argument $1 (see --help)" >&2
            exit 2
            ;;
    esac
    shift
done
if [[ "$(uname -s)-$(uname -m)" != Linux-x86_64 ]]; then
    echo "build-plugin.sh: this script builds the Linux x86_64 plugin; on $(uname -s)-$(uname -m) build" \
        "vrsync-host-ffi with cargo and set up the plugin by hand (see the package README)" >&2
    exit 2
fi

cd "$root"
if ((build)); then
    flags=(-p vrsync-host-ffi)
    [[ $profile == release ]] && flags+=(--release)
    cargo build "${flags[@]}"
fi
target_dir="$(cargo metadata --format-version 1 --no-deps | grep -o '"target_directory":"[^"]*"' | cut -d'"' -f4)"
library="$target_dir/$profile/libvrsync_host.so"
[[ -e "$library" ]] || {
    echo "build-plugin.sh: $library does not exist (build it, or drop --no-build)" >&2
    exit 1
}
mkdir -p "$dest"
cp "$library" "$dest/libvrsync_host.so.tmp"
mv "$dest/libvrsync_host.so.tmp" "$dest/libvrsync_host.so"
if [[ "$(cd "$dest" && pwd)" != "$plugins" ]]; then
    # Outside the package: the same importer settings under a GUID of its own (two assets
    # with one GUID would clash when the package's copy is present too).
    guid="$(od -An -N16 -tx1 /dev/urandom | tr -d ' \n')"
    sed "s/^guid: .*/guid: $guid/" "$plugins/libvrsync_host.so.meta" >"$dest/libvrsync_host.so.meta"
fi
echo "placed $library ($profile) as $dest/libvrsync_host.so"
echo "Unity loads a native plugin once per editor session: restart the editor after replacing it."
