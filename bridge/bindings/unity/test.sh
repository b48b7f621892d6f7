#!/usr/bin/env bash
# Tests of the Unity package com.vrsync.host WITHOUT Unity: the package's Runtime is compiled
# with Mono's mcs against stubs of Unity's API (com.vrsync.host/Tests~/UnityStubs, written
# from Unity's scripting reference; Unity never imports a folder ending in `~`), and a scene
# is played through those stubs against the real libvrsync_host and real agent processes:
#   1. layout   package.json and the asmdefs parse with their required fields, every file and
#               folder has a .meta, GUIDs are unique, the native plugin's PluginImporter
#               enables the editor and standalone Linux x86_64 only
#   2. compile  Runtime (binding + components) against the stubs, with and without
#               ENABLE_UNITY_COLLECTIONS_CHECKS (editor / player), -warnaserror; the sample too
#   3. editor tests  the package's own Tests/Editor (the ones a user runs in Unity's Test
#               Runner) against the stubs and a stub of NUnit: the plugin matches the binding;
#               a camera's image reaches the loaned frame top row first, R, G, B(, A) in order
#   4. plugin   build-plugin.sh places the library and writes a .meta with a GUID of its own
#   5. scene    VrsyncHost, agents 0 and 1 (two VrsyncCameras each, textures holding known
#               patterns) for 100 sync cycles with `vr-agent --policy circle` as one agent and
#               a Python agent (Tests~/SceneTest/pattern_agent.py) as the other, then swapped:
#               every image the Python agent receives is the pattern, top row first; the
#               vectors it reads and the actions it sends are checked; commands reach
#               IVrsyncBody; Time.captureDeltaTime = simulation_time_per_frame; 0 stop
#               timeouts; the ReadPixels path (chosen, and after a refused readback format);
#               and 30 cycles in async mode (readbacks not waited for, no captureDeltaTime)
# Needs: cargo, mcs, mono, python3; a Python with the vrsync package for 3 (VRSYNC_PYTHON, else
# .venv/bin/python, else python3). Every process runs under `timeout`; children are killed on
# exit. Usage: bash bridge/bindings/unity/test.sh
set -euo pipefail

here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../../.." && pwd)"
package="$here/com.vrsync.host"
cd "$root"

test_name="unity/test.sh"
work_prefix="vrsync-unity"
# shellcheck source=../test-lib.sh
source "$root/bridge/bindings/test-lib.sh"

for tool in cargo mcs mono timeout python3; do
    command -v "$tool" >/dev/null || fail "$tool not found (apt-get install -y mono-mcs mono-runtime python3)"
done
python="${VRSYNC_PYTHON:-}"
if [[ -z "$python" ]]; then
    for candidate in "$root/.venv/bin/python" python3; do
        if "$candidate" -c 'import vrsync' 2>/dev/null; then
            python=$candidate
            break
        fi
    done
fi
[[ -n "$python" ]] && "$python" -c 'import vrsync' 2>/dev/null ||
    fail "no Python with the vrsync package (pip install ./agent-sdk/python, or set VRSYNC_PYTHON)"

session_base="unity$$-$RANDOM"

step "1. layout: package.json, asmdefs, .meta files, GUIDs, PluginImporter"
timeout 60 python3 "$package/Tests~/check_layout.py" "$package"

build_native

step "2. mcs: Runtime against the Unity stubs ($(mcs --version))"
mcs_flags=(-langversion:7.2 -unsafe -warnaserror -nologo)
runtime=()
while IFS= read -r -d '' f; do runtime+=("$f"); done < <(find "$package/Runtime" -name '*.cs' -print0 | sort -z)
# The editor defines ENABLE_UNITY_COLLECTIONS_CHECKS (safety handles); a player build does not.
mkdir -p "$work/editor" "$work/player"
timeout 120 mcs "${mcs_flags[@]}" -define:ENABLE_UNITY_COLLECTIONS_CHECKS -target:library \
    -out:"$work/editor/UnityEngine.dll" "$package"/Tests~/UnityStubs/*.cs
timeout 120 mcs "${mcs_flags[@]}" -define:ENABLE_UNITY_COLLECTIONS_CHECKS -target:library \
    -r:"$work/editor/UnityEngine.dll" -out:"$work/editor/Vrsync.dll" "${runtime[@]}"
timeout 120 mcs "${mcs_flags[@]}" -target:library -out:"$work/player/UnityEngine.dll" \
    "$package"/Tests~/UnityStubs/*.cs
timeout 120 mcs "${mcs_flags[@]}" -target:library -r:"$work/player/UnityEngine.dll" \
    -out:"$work/player/Vrsync.dll" "${runtime[@]}"
for sample in "$package"/Samples~/*/; do
    timeout 120 mcs "${mcs_flags[@]}" -target:library -r:"$work/player/UnityEngine.dll" \
        -r:"$work/player/Vrsync.dll" -out:"$work/player/sample-$(basename "$sample").dll" "$sample"*.cs
done
timeout 120 mcs "${mcs_flags[@]}" -r:"$work/editor/UnityEngine.dll" -r:"$work/editor/Vrsync.dll" \
    -out:"$work/editor/SceneTest.exe" "$package/Tests~/SceneTest/SceneTest.cs"
timeout 120 mcs -langversion:7.2 -warnaserror -nologo -target:library -out:"$work/editor/nunit.framework.dll" \
    "$package/Tests~/NUnitStub/NUnit.cs"
timeout 120 mcs "${mcs_flags[@]}" -target:library -r:"$work/editor/UnityEngine.dll" -r:"$work/editor/Vrsync.dll" \
    -r:"$work/editor/nunit.framework.dll" -out:"$work/editor/Vrsync.Tests.Editor.dll" "$package"/Tests/Editor/*.cs
timeout 120 mcs -langversion:7.2 -warnaserror -nologo -r:"$work/editor/nunit.framework.dll" \
    -out:"$work/editor/Runner.exe" "$package/Tests~/NUnitStub/Runner.cs"
echo "Runtime (${#runtime[@]} files) compiled for the editor and the player; samples; editor tests; scene test"

step "3. editor tests (Tests/Editor) against the stubs"
(cd "$work/editor" && timeout 60 mono --debug Runner.exe Vrsync.Tests.Editor.dll)

step "4. build-plugin.sh --no-build --debug --dest DIR"
bash "$here/build-plugin.sh" --no-build --debug --dest "$work/plugin"
cmp -s "$bin/libvrsync_host.so" "$work/plugin/libvrsync_host.so" || fail "build-plugin.sh placed another library"
plugin_meta="$package/Runtime/Plugins/x86_64/libvrsync_host.so.meta"
grep -q '^guid: [0-9a-f]\{32\}$' "$work/plugin/libvrsync_host.so.meta" || fail "build-plugin.sh wrote no GUID"
[[ "$(grep '^guid:' "$work/plugin/libvrsync_host.so.meta")" != "$(grep '^guid:' "$plugin_meta")" ]] ||
    fail "build-plugin.sh copied the package's GUID"
diff <(grep -v '^guid:' "$plugin_meta") <(grep -v '^guid:' "$work/plugin/libvrsync_host.so.meta") ||
    fail "build-plugin.sh's .meta has other importer settings than the package's"

# write_config FILE SESSION [SYNC_MODE]: agents 0 and 1 with two cameras each (formats rgb8, rgba8,
# gray8), a vector and an action each.
write_config() {
    cat >"$1" <<EOF
session = "$2"
[sync]
sync_mode = ${3:-true}
simulation_time_per_frame = 0.02
stop_timeout = 10.0
connect_timeout = 30.0
[[agent]]
id = 0
[[agent.camera]]
name = "left"
width = 32
height = 16
[[agent.camera]]
name = "right"
width = 24
height = 12
format = "rgba8"
[[agent.vector]]
name = "joints"
len = 3
[[agent.action]]
name = "torque"
len = 2
low = -1.0
high = 1.0
[[agent]]
id = 1
[[agent.camera]]
name = "left"
width = 32
height = 16
[[agent.camera]]
name = "gray"
width = 20
height = 10
format = "gray8"
[[agent.vector]]
name = "joints"
len = 3
[[agent.action]]
name = "torque"
len = 2
low = -1.0
high = 1.0
EOF
}

# scene TAG PYTHON_ID VR_AGENT_ID SCENE_ARGS...: the scene with a Python agent and a vr-agent
# (SCENE_CYCLES cycles, default 100; SCENE_SYNC_MODE true or false, default true).
scene() {
    local tag=$1 py_id=$2 vr_id=$3
    shift 3
    local config="$work/$tag/vrsync.toml" cycles="${SCENE_CYCLES:-100}"
    mkdir -p "$work/$tag"
    write_config "$config" "$session_base-$tag" "${SCENE_SYNC_MODE:-true}"
    timeout 120 "$python" "$package/Tests~/SceneTest/pattern_agent.py" "$config" "$py_id" \
        >"$work/$tag-python.out" 2>"$work/$tag-python$py_id.log" &
    local py_pid=$!
    pids+=("$py_pid")
    timeout 120 "$bin/vr-agent" --config "$config" --id "$vr_id" --policy circle \
        >"$work/$tag-vr-agent$vr_id.log" 2>&1 &
    local vr_pid=$!
    pids+=("$vr_pid")
    local status=0
    timeout 120 mono --debug "$work/editor/SceneTest.exe" --config "$config" --cycles "$cycles" \
        --exact-commands "$py_id" --actions-from "$py_id" "$@" \
        >"$work/$tag-summary.txt" 2>"$work/$tag-scene.log" || status=$?
    cat "$work/$tag-summary.txt"
    ((status == 0)) || fail "SceneTest.exe ($tag) exited with $status"
    status=0
    wait "$py_pid" || status=$?
    cat "$work/$tag-python.out"
    ((status == 0)) || fail "pattern_agent.py (agent $py_id, $tag) exited with $status"
    status=0
    wait "$vr_pid" || status=$?
    ((status == 0)) || fail "vr-agent $vr_id ($tag) exited with $status"
    local v
    v="$(sed -n 's/^python_agent[0-9]*_cycles=//p' "$work/$tag-python.out")"
    if [[ ${SCENE_SYNC_MODE:-true} == true ]]; then
        ((v >= cycles)) || fail "the Python agent saw $v cycles of $cycles ($tag)"
    else
        ((v > 0)) || fail "the Python agent saw no cycle ($tag)"
    fi
    grep -q '^stop_timeouts=0$' "$work/$tag-summary.txt" || fail "stop timeouts in $tag"
}

step "5a. scene: Python agent 1 (checks images), vr-agent 0; agent 1's left camera on ReadPixels"
scene a 1 0 --readpixels 1:left

step "5b. scene: Python agent 0, vr-agent 1; RGB24 readback refused (falls back to ReadPixels)"
scene b 0 1 --refuse RGB24
grep -q '^agent0_left_path=ReadPixels$' "$work/b-summary.txt" || fail "5b: agent 0's left camera did not fall back"
grep -q 'using ReadPixels for it from now on' "$work/b-scene.log" || fail "5b: the fallback was not logged"

step "5c. scene in async mode: 30 cycles, Python agent 1, vr-agent 0"
SCENE_CYCLES=30 SCENE_SYNC_MODE=false scene c 1 0 --async
grep -q '^capture_delta_time=0$' "$work/c-summary.txt" || fail "5c: async mode set Time.captureDeltaTime"

step "Unity package: all tests passed"
