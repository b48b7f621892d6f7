# Shared by the binding tests (bridge/bindings/csharp/test.sh, bridge/bindings/unity/test.sh),
# which source it after setting `test_name` (for messages) and `work_prefix` (their temp
# folder's name): step lines, failures, a work folder whose background processes (`pids`)
# are killed on exit and whose logs are shown when the test failed, and the build of
# libvrsync_host and the agents.

step() { printf '\n--- %s (%ss)\n' "$*" "$SECONDS"; }
fail() {
    echo "$test_name: FAIL: $*" >&2
    exit 1
}

work="$(mktemp -d "${TMPDIR:-/tmp}/$work_prefix.XXXXXX")"
pids=()
cleanup() {
    local status=$?
    for pid in "${pids[@]}"; do
        kill "$pid" 2>/dev/null || true
    done
    for pid in "${pids[@]}"; do
        wait "$pid" 2>/dev/null || true
    done
    if ((status != 0)); then
        for log in "$work"/*.log; do
            [[ -e "$log" ]] || continue
            echo "==== $log (last lines)" >&2
            tail -n 20 "$log" >&2
        done
    fi
    rm -rf "$work"
}
trap cleanup EXIT
trap 'exit 130' INT TERM

# Builds the whole workspace with its tests, as `cargo test --workspace` builds it, with the
# same feature set (scripts/test-all passes its own in VRSYNC_FEATURES), so after that
# command nothing is compiled again. (Building only `-p vrsync-host-ffi` resolves dependency
# features without the dev-dependencies and rebuilds a large part of the tree.) Sets `bin`
# (the folder of libvrsync_host.so and vr-agent) and puts it on LD_LIBRARY_PATH.
build_native() {
    step "cargo build --workspace --all-targets (libvrsync_host, vr-agent)"
    local features=()
    [[ -n "${VRSYNC_FEATURES:-}" ]] && features=(--features "$VRSYNC_FEATURES")
    timeout 1800 cargo build --workspace --all-targets "${features[@]}"
    local target_dir
    target_dir="$(cargo metadata --format-version 1 --no-deps | grep -o '"target_directory":"[^"]*"' | cut -d'"' -f4)"
    bin="$target_dir/debug"
    [[ -e "$bin/libvrsync_host.so" ]] || fail "$bin/libvrsync_host.so was not built"
    export LD_LIBRARY_PATH="$bin${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
}
