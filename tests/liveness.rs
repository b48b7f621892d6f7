//! The world waits for a live agent (`wait_for_stop = "alive"`, the default): an agent
//! that computes for several stop timeouts costs no stop timeout, no late stop and no
//! skipped frame, and is reported slow while the host waits; one that dies meanwhile is
//! evicted at once. Over every transport that can tell liveness.

use std::time::{Duration, Instant};

use serde_json::Value;

use crate::util::{
    EVENT_DEADLINE, HostRun, RUN_DEADLINE, TestConfig, Transport, cycle_log, summary,
    wait_for_cycle_line,
};

const STOP_TIMEOUT_S: f64 = 0.2;

/// A run of `frames` cycles of two `circle` agents; agent 1 gets `late_args` besides.
/// Returns the summary, the events and agent 1's cycle log.
fn run_two(
    t: Transport,
    tag: &str,
    frames: &str,
    late_args: &[&str],
) -> (Value, Vec<Value>, Vec<crate::util::CycleLine>) {
    let mut cfg = TestConfig::with_transport(tag, 2, t);
    cfg.stop_timeout_s = STOP_TIMEOUT_S;
    let run = HostRun::start(cfg, &["--frames", frames]);
    let (a0, _) = run.agent(0, "a0.log", &["--policy", "circle"]);
    let mut args = vec!["--policy", "circle"];
    args.extend_from_slice(late_args);
    let (a1, log1) = run.agent(1, "a1.log", &args);
    let out = run.host.wait(RUN_DEADLINE);
    assert_eq!(out.code(), Some(0), "{t:?}: stderr:\n{}", out.stderr);
    assert_eq!(a0.wait(Duration::from_secs(10)).code(), Some(0));
    assert_eq!(a1.wait(Duration::from_secs(10)).code(), Some(0));
    (summary(&run.summary), run.events.read(), cycle_log(&log1))
}

fn a_busy_agent_costs_nothing_and_is_reported_slow(t: Transport) {
    // Agent 1 computes for 3.5 stop timeouts in cycle 10.
    let late = ["--late-stop-at", "10", "--late-stop-cycles", "3"];
    let (sum, events, log1) = run_two(t, "busy", "30", &late);
    for key in ["stop_timeouts", "agent_timeouts", "late_stops", "evictions"] {
        assert_eq!(sum[key], 0, "{t:?} {key}: {sum}");
    }
    assert_eq!(sum["slow_stops"], 1, "{t:?}: {sum}");
    assert_eq!(sum["frames"], 30, "{sum}");
    // Every frame reached both agents and was read: nothing skipped.
    assert_eq!(sum["frames_delivered"], 60, "{sum}");
    assert_eq!(sum["frames_read"], 60, "{sum}");
    assert_eq!(
        log1.iter().map(|l| l.cycle).collect::<Vec<_>>(),
        (0..30).collect::<Vec<_>>()
    );
    assert!(log1.iter().all(|l| l.skipped == 0), "{log1:?}");
    // Reported as it happened: at 1× and 2× the stop timeout (3.5× in all).
    let slow: Vec<&Value> = events
        .iter()
        .filter(|e| e["event"] == "agent_slow")
        .collect();
    assert!(slow.len() >= 2, "{t:?}: {slow:?}");
    for e in &slow {
        assert_eq!(
            (e["agent"].as_u64(), e["cycle"].as_u64()),
            (Some(1), Some(10)),
            "{e}"
        );
    }
    assert!(
        slow[0]["waited_s"].as_f64().unwrap() >= STOP_TIMEOUT_S,
        "{:?}",
        slow[0]
    );
    let cycle10 = events
        .iter()
        .find(|e| e["event"] == "cycle" && e["cycle"] == 10)
        .unwrap_or_else(|| panic!("no cycle event for cycle 10: {events:?}"));
    assert_eq!(cycle10["slow_agents"], serde_json::json!([1]), "{cycle10}");
    assert_eq!(
        cycle10["timed_out_agents"],
        serde_json::json!([]),
        "{cycle10}"
    );
    // The pause left no trace in the world.
    let (quick, _, _) = run_two(t, "busy-ref", "30", &[]);
    assert_eq!(quick["slow_stops"], 0, "{quick}");
    assert_eq!(sum["trajectory_hash"], quick["trajectory_hash"], "{t:?}");
}

fn an_agent_killed_while_the_host_waits_for_it_is_evicted_at_once(t: Transport) {
    let mut cfg = TestConfig::with_transport("busykill", 2, t);
    cfg.stop_timeout_s = STOP_TIMEOUT_S;
    let run = HostRun::start(cfg, &[]);
    let events = &run.events;
    let (a0, log0) = run.agent(0, "a0.log", &["--policy", "circle"]);
    // Agent 1 computes for ~200 s in cycle 5: the host waits, reports, and goes on only
    // once the agent is gone.
    let (a1, _) = run.agent(
        1,
        "a1.log",
        &[
            "--policy",
            "circle",
            "--late-stop-at",
            "5",
            "--late-stop-cycles",
            "1000",
        ],
    );
    let slow = events.wait_for("agent_slow", EVENT_DEADLINE);
    assert_eq!(
        (slow["agent"].as_u64(), slow["cycle"].as_u64()),
        (Some(1), Some(5)),
        "{slow}"
    );
    a1.signal(libc::SIGKILL);
    let killed = Instant::now();
    let _ = a1.wait(Duration::from_secs(10));
    let evicted = events.wait_for("agent_evicted", EVENT_DEADLINE);
    eprintln!(
        "{t:?}: agent killed -> evicted after {:.3} s",
        killed.elapsed().as_secs_f64()
    );
    assert_eq!(
        (evicted["agent"].as_u64(), evicted["cycle"].as_u64()),
        (Some(1), Some(5)),
        "{evicted}"
    );
    // The other agent goes on.
    wait_for_cycle_line(&log0, 8, EVENT_DEADLINE);
    run.host.signal(libc::SIGTERM);
    let out = run.host.wait(RUN_DEADLINE);
    assert_eq!(out.code(), Some(0), "stderr:\n{}", out.stderr);
    assert_eq!(a0.wait(Duration::from_secs(10)).code(), Some(0));
    let sum = summary(&run.summary);
    assert_eq!(sum["stop_timeouts"], 0, "{sum}");
    assert_eq!(sum["slow_stops"], 1, "{sum}");
    assert_eq!(sum["evicted_agents"], serde_json::json!([1]), "{sum}");
}

for_live_transports!(
    a_busy_agent_costs_nothing_and_is_reported_slow,
    an_agent_killed_while_the_host_waits_for_it_is_evicted_at_once,
);
