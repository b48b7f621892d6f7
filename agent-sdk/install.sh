#!/usr/bin/env bash
# Installs the vrsync agent SDK for C and C++ into PREFIX:
#   PREFIX/lib/libvrsync_agent.so, PREFIX/lib/libvrsync_agent.a
#   PREFIX/include/vrsync.h, PREFIX/include/vrsync/{agent,compat}.hpp
#   PREFIX/lib/cmake/vrsync/  (find_package(vrsync) -> vrsync::agent)
#   PREFIX/lib/pkgconfig/vrsync.pc
#
# usage: agent-sdk/install.sh [--debug] [--no-build] [--lib-dir DIR] PREFIX
#   --debug        use the debug build (target/debug) instead of the release build
#   --no-build     do not run cargo; copy what is already built
#   --lib-dir DIR  take libvrsync_agent.{so,a} from DIR (implies --no-build)
# Honours CARGO_TARGET_DIR. Exit codes: 0 ok, 1 failure, 2 bad usage.
set -euo pipefail

usage() { sed -n '2,13p' "$0" | sed 's/^# \{0,1\}//' >&2; exit 2; }

sdk_dir="$(cd "$(dirname "$0")" && pwd)"
workspace="$(cd "$sdk_dir/.." && pwd)"
profile=release
build=1
lib_dir=""
prefix=""
while (($#)); do
    case "$1" in
        --debug) profile=debug ;;
        --no-build) build=0 ;;
        --lib-dir) shift; (($#)) || usage; lib_dir="$1"; build=0 ;;
        -h|--help) usage ;;
        -*) echo "install.sh: unknown option $1" >&2; usage ;;
        *) [[ -z "$prefix" ]] || usage; prefix="$1" ;;
    esac
    shift
done
[[ -n "$prefix" ]] || usage

if ((build)); then
    args=(build -p vrsync-agent-ffi --lib)
    [[ "$profile" == release ]] && args+=(--release)
    (cd "$workspace" && cargo "${args[@]}")
fi
if [[ -z "$lib_dir" ]]; then
    lib_dir="${CARGO_TARGET_DIR:-$workspace/target}/$profile"
fi
for f in libvrsync_agent.so libvrsync_agent.a; do
    if [[ ! -f "$lib_dir/$f" ]]; then
        echo "install.sh: $lib_dir/$f not found (build with: cargo build --release -p vrsync-agent-ffi)" >&2
        exit 1
    fi
done

version="$(sed -n '/^\[workspace.package\]/,/^\[/s/^version *= *"\(.*\)"/\1/p' "$workspace/Cargo.toml")"
[[ -n "$version" ]] || { echo "install.sh: no version in $workspace/Cargo.toml" >&2; exit 1; }

mkdir -p "$prefix"
prefix="$(cd "$prefix" && pwd)"
install -d "$prefix/lib" "$prefix/include/vrsync" "$prefix/lib/cmake/vrsync" "$prefix/lib/pkgconfig"
install -m 0755 "$lib_dir/libvrsync_agent.so" "$prefix/lib/"
install -m 0644 "$lib_dir/libvrsync_agent.a" "$prefix/lib/"
install -m 0644 "$sdk_dir/include/vrsync.h" "$prefix/include/"
install -m 0644 "$sdk_dir/include/vrsync/agent.hpp" "$sdk_dir/include/vrsync/compat.hpp" \
    "$prefix/include/vrsync/"
install -m 0644 "$sdk_dir/cmake/vrsyncConfig.cmake" "$prefix/lib/cmake/vrsync/"
sed "s|@VERSION@|$version|g" "$sdk_dir/cmake/vrsyncConfigVersion.cmake.in" \
    > "$prefix/lib/cmake/vrsync/vrsyncConfigVersion.cmake"
sed -e "s|@PREFIX@|$prefix|g" -e "s|@VERSION@|$version|g" "$sdk_dir/cmake/vrsync.pc.in" \
    > "$prefix/lib/pkgconfig/vrsync.pc"
echo "vrsync agent SDK $version ($profile) installed in $prefix"
