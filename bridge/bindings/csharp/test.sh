#!/usr/bin/env bash
# Tests of the C# binding with a real C# runtime (Mono's mcs and mono), against the real
# libvrsync_host and real vr-agent processes:
#   1. layout        C# structs and enums == the C header, field by field (and the library's sizes)
#   2. api           errors, calls out of order, a missing agent, spans, Dispose, finalizers
#   3. console host  VrsyncConsoleHost.exe + 2 x `vr-agent --policy wander`, 100 sync cycles:
#                    0 timeouts, commands from both agents, both bodies moved
#   4. TCP           the same console host over the TCP transport, 50 cycles
#   5. stop timeout  agent 1 stops late once: a TimedOut outcome, no exception
#   6. leave, slow   agent 0 leaves after 3 cycles (Left, Stats.Leaves), agent 1 busy past the
#                    stop timeout under wait_for_stop = "alive" (Slow, Stats.SlowStops)
#   7. channels      vectors written through Span<float> reach the Rust channel_agent example,
#                    its actions come back in the reports (values checked), errors named
# The Unity package built on this binding has its own tests: bridge/bindings/unity/test.sh.
# Needs: cargo, mcs, mono (apt-get install -y mono-mcs mono-runtime), a C compiler for 1.
# Every process runs under `timeout`; children are killed on exit. Usage:
#   bash bridge/bindings/csharp/test.sh
set -euo pipefail

here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../../.." && pwd)"
cd "$root"

test_name="csharp/test.sh"
work_prefix="vrsync-csharp"
# shellcheck source=../test-lib.sh
source "$root/bridge/bindings/test-lib.sh"

for tool in cargo mcs mono timeout; do
    command -v "$tool" >/dev/null || fail "$tool not found (apt-get install -y mono-mcs mono-runtime)"
done

# Unique per run, so parallel runs and leftovers of crashed runs never meet.
session_base="cs$$-$RANDOM"

build_native

step "mcs: binding, console host, tests ($(mcs --version))"
# The binding's sources live in the Unity package (Runtime/Binding), which Unity compiles
# from there; this is the same set of files.
binding="$root/bridge/bindings/unity/com.vrsync.host/Runtime/Binding"
mcs_flags=(-langversion:7.2 -unsafe -warnaserror -nologo)
timeout 120 mcs "${mcs_flags[@]}" -target:library -out:"$work/Vrsync.dll" "$binding"/*.cs
timeout 120 mcs "${mcs_flags[@]}" -r:"$work/Vrsync.dll" -out:"$work/VrsyncConsoleHost.exe" \
    "$here"/examples/*.cs
timeout 120 mcs "${mcs_flags[@]}" -r:"$work/Vrsync.dll" -out:"$work/VrsyncTests.exe" \
    "$here"/tests/Tests.cs

# write_config FILE SESSION STOP_TIMEOUT_S [WAIT_FOR_STOP]: agents 0 and 1, small cameras.
write_config() {
    cat >"$1" <<EOF
session = "$2"
[sync]
stop_timeout = $3
wait_for_stop = "${4:-alive}"
connect_timeout = 20.0
[[agent]]
id = 0
[[agent.camera]]
name = "left"
width = 32
height = 16
[[agent.camera]]
name = "depth"
width = 32
height = 16
format = "gray8"
[[agent]]
id = 1
[[agent.camera]]
name = "left"
width = 32
height = 16
[[agent.camera]]
name = "depth"
width = 32
height = 16
format = "gray8"
EOF
}

# agent TAG CONFIG ID [ARGS...]: a vr-agent in the background; its pid goes to agent_pid.
agent() {
    local tag=$1 config=$2 id=$3
    shift 3
    timeout 90 "$bin/vr-agent" --config "$config" --id "$id" --policy wander "$@" \
        >"$work/$tag-agent$id.log" 2>&1 &
    agent_pid=$!
    pids+=("$agent_pid")
}

# expect_exit PID WHAT: the process ended with 0.
expect_exit() {
    local status=0
    wait "$1" || status=$?
    ((status == 0)) || fail "$2 exited with $status"
}

step "1. layout: C# == vrsync_host.h"
timeout 60 mono --debug "$work/VrsyncTests.exe" layout >"$work/layout-cs.txt" 2>"$work/layout.log"
cc=""
for c in "${CC:-}" cc gcc clang; do
    if [[ -n "$c" ]] && command -v "$c" >/dev/null; then
        cc=$c
        break
    fi
done
if [[ -z "$cc" ]] && command -v g++ >/dev/null; then
    cc="g++ -x c"
fi
[[ -n "$cc" ]] || fail "no C compiler (cc, gcc, clang or g++) for the layout check"
$cc -std=c11 -I bridge/ffi/include "$here/tests/layout.c" -o "$work/layout"
timeout 60 "$work/layout" >"$work/layout-c.txt"
sort "$work/layout-c.txt" >"$work/layout-c.sorted"
sort "$work/layout-cs.txt" >"$work/layout-cs.sorted"
if ! diff "$work/layout-c.sorted" "$work/layout-cs.sorted"; then
    fail "the C# binding and vrsync_host.h disagree (< C header, > C#)"
fi
echo "$(wc -l <"$work/layout-c.txt") sizes, offsets and constants agree"

step "2. api: errors, a missing agent, spans, Dispose, finalizers"
write_config "$work/api.toml" "$session_base-api" 5.0
agent api "$work/api.toml" 0
api_agent=$agent_pid
timeout 90 mono --debug "$work/VrsyncTests.exe" api "$work/api.toml" 2>&1 | tee "$work/api.log"
[[ ${PIPESTATUS[0]} == 0 ]] || fail "VrsyncTests.exe api"
expect_exit "$api_agent" "vr-agent 0 (api) after the host closed the session"

step "3. console host: 2 x vr-agent --policy wander, 100 sync cycles"
sed "s/^session = .*/session = \"$session_base-run\"/" config/default.toml >"$work/run.toml"
agent run "$work/run.toml" 0
run_agent0=$agent_pid
agent run "$work/run.toml" 1
run_agent1=$agent_pid
status=0
timeout 90 mono --debug "$work/VrsyncConsoleHost.exe" --config "$work/run.toml" --cycles 100 \
    --connect-timeout 20 >"$work/summary.txt" 2>"$work/run-host.log" || status=$?
cat "$work/summary.txt"
((status == 0)) || fail "VrsyncConsoleHost.exe exited with $status"
expect_exit "$run_agent0" "vr-agent 0 (console host run)"
expect_exit "$run_agent1" "vr-agent 1 (console host run)"
value() { sed -n "s/^$1=//p" "$work/summary.txt"; }
[[ "$(value cycles)" == 100 ]] || fail "cycles=$(value cycles), expected 100"
[[ "$(value stop_timeouts)" == 0 ]] || fail "stop_timeouts=$(value stop_timeouts), expected 0"
[[ "$(value agent_timeouts)" == 0 ]] || fail "agent_timeouts=$(value agent_timeouts), expected 0"
[[ "$(value leaves)" == 0 ]] || fail "leaves=$(value leaves), expected 0 (the agents stay until the host closes)"
for id in 0 1; do
    n="$(value "agent${id}_commands")"
    ((n > 0)) || fail "no commands from agent $id"
    walked="$(value "agent${id}_walked_m")"
    awk -v w="$walked" 'BEGIN { exit !(w > 1.0) }' || fail "agent $id walked only ${walked} m"
done
echo "100 cycles, 0 timeouts; commands: agent 0 $(value agent0_commands), agent 1" \
    "$(value agent1_commands); walked: $(value agent0_walked_m) m, $(value agent1_walked_m) m;" \
    "$(value cycles_per_s) cycles/s"

step "4. console host over TCP: 2 x vr-agent, 50 sync cycles"
# The host binds port 0; the agents get the port it reports.
sed -e "s/^session = .*/session = \"$session_base-tcp\"/" -e 's/^kind = "shm"/kind = "tcp"/' \
    -e 's/^tcp_listen = .*/tcp_listen = "127.0.0.1:0"/' config/default.toml >"$work/tcp-host.toml"
grep -q '^kind = "tcp"' "$work/tcp-host.toml" || fail "config/default.toml: no kind = \"shm\" line to switch"
timeout 90 mono --debug "$work/VrsyncConsoleHost.exe" --config "$work/tcp-host.toml" --cycles 50 \
    --connect-timeout 20 >"$work/tcp-summary.txt" 2>"$work/tcp-host.log" &
tcp_host=$!
pids+=("$tcp_host")
port=""
for _ in $(seq 400); do # up to 20 s for mono to start and the host to bind
    port="$(sed -n 's/^tcp_port=//p' "$work/tcp-host.log")"
    [[ -n "$port" ]] && break
    kill -0 "$tcp_host" 2>/dev/null || break
    sleep 0.05
done
[[ -n "$port" ]] || fail "the TCP console host did not report its port"
sed "s/^tcp_listen = .*/tcp_listen = \"127.0.0.1:$port\"/" "$work/tcp-host.toml" >"$work/tcp.toml"
agent tcp "$work/tcp.toml" 0
tcp_agent0=$agent_pid
agent tcp "$work/tcp.toml" 1
tcp_agent1=$agent_pid
expect_exit "$tcp_host" "VrsyncConsoleHost.exe over TCP"
expect_exit "$tcp_agent0" "vr-agent 0 (TCP)"
expect_exit "$tcp_agent1" "vr-agent 1 (TCP)"
tcp_value() { sed -n "s/^$1=//p" "$work/tcp-summary.txt"; }
[[ "$(tcp_value cycles)" == 50 && "$(tcp_value stop_timeouts)" == 0 ]] ||
    fail "TCP: cycles=$(tcp_value cycles) stop_timeouts=$(tcp_value stop_timeouts)"
for id in 0 1; do
    n="$(tcp_value "agent${id}_commands")"
    ((n > 0)) || fail "TCP: no commands from agent $id"
done
echo "TCP: 50 cycles, 0 timeouts, port $port; $(tcp_value cycles_per_s) cycles/s"

step "5. stop timeout: agent 1 stops late in cycle 2"
# wait_for_stop = "timeout": the original semantics (the default waits for a live agent).
write_config "$work/late.toml" "$session_base-late" 0.4 timeout
agent late "$work/late.toml" 0
late_agent0=$agent_pid
agent late "$work/late.toml" 1 --late-stop-at 2
late_agent1=$agent_pid
timeout 90 mono --debug "$work/VrsyncTests.exe" stop-timeout "$work/late.toml" 2>&1 |
    tee "$work/late.log"
[[ ${PIPESTATUS[0]} == 0 ]] || fail "VrsyncTests.exe stop-timeout"
expect_exit "$late_agent0" "vr-agent 0 (stop timeout)"
expect_exit "$late_agent1" "vr-agent 1 (stop timeout)"

step "6. leave and slow: agent 0 leaves after 3 cycles, agent 1 is busy in cycle 1"
write_config "$work/leave.toml" "$session_base-leave" 0.4 alive
agent leave "$work/leave.toml" 0 --frames 3
leave_agent0=$agent_pid
agent leave "$work/leave.toml" 1 --late-stop-at 1
leave_agent1=$agent_pid
timeout 90 mono --debug "$work/VrsyncTests.exe" leave-slow "$work/leave.toml" 2>&1 |
    tee "$work/leave.log"
[[ ${PIPESTATUS[0]} == 0 ]] || fail "VrsyncTests.exe leave-slow"
expect_exit "$leave_agent0" "vr-agent 0 (leave after 3 frames)"
expect_exit "$leave_agent1" "vr-agent 1 (slow once)"

step "7. channels: vectors and actions with the Rust channel_agent example"
cat >"$work/channels.toml" <<EOF
session = "$session_base-channels"
[sync]
stop_timeout = 5.0
connect_timeout = 20.0
[[agent]]
id = 0
[[agent.camera]]
name = "left"
width = 16
height = 8
[[agent.vector]]
name = "joints"
len = 3
low = -1.0
high = 1.0
[[agent.vector]]
name = "vel"
len = 2
[[agent.action]]
name = "torque"
len = 3
low = -2.0
high = 2.0
[[agent.action]]
name = "gear"
n = 3
EOF
[[ -x "$bin/examples/channel_agent" ]] || fail "$bin/examples/channel_agent was not built"
channel_seed=5
timeout 90 "$bin/examples/channel_agent" "$work/channels.toml" 0 "$channel_seed" \
    >"$work/channels-agent0.log" 2>&1 &
channel_agent=$!
pids+=("$channel_agent")
timeout 90 mono --debug "$work/VrsyncTests.exe" channels "$work/channels.toml" "$channel_seed" 2>&1 |
    tee "$work/channels.log"
[[ ${PIPESTATUS[0]} == 0 ]] || fail "VrsyncTests.exe channels"
expect_exit "$channel_agent" "channel_agent 0 after the host closed the session"

step "C# binding: all tests passed"
