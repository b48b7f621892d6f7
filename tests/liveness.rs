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

/// Every agent left (gracefully, `vr-agent --frames`): the host pauses — no cycle runs and
/// no frame goes nowhere — until an agent of the id connects again, then goes on.
fn with_nobody_attached_the_host_pauses_until_agents_are_back(t: Transport) {
    let cfg = TestConfig::with_transport("idle", 1, t);
    let run = HostRun::start(cfg, &["--frames", "40"]);
    let events = &run.events;
    let (first, _) = run.agent(0, "first.log", &["--policy", "circle", "--frames", "10"]);
    assert_eq!(first.wait(RUN_DEADLINE).code(), Some(0));
    let left = events.wait_for_match("agent_left", |e| e["graceful"] == true, EVENT_DEADLINE);
    assert_eq!(left["agent"], 0, "{left}");
    // The second `waiting_for_agents` (the first was before cycle 0).
    events.wait_for_match(
        "waiting_for_agents",
        |_| events.of("waiting_for_agents").len() >= 2,
        EVENT_DEADLINE,
    );
    let (again, log) = run.agent(0, "again.log", &["--policy", "circle"]);
    let out = run.host.wait(RUN_DEADLINE);
    assert_eq!(out.code(), Some(0), "{t:?}: stderr:\n{}", out.stderr);
    assert_eq!(again.wait(Duration::from_secs(10)).code(), Some(0));
    let sum = summary(&run.summary);
    assert_eq!(sum["frames"], 40, "{sum}");
    assert_eq!(
        (sum["leaves"].as_u64(), sum["rejoins"].as_u64()),
        (Some(1), Some(1)),
        "{sum}"
    );
    assert_eq!(sum["evictions"], 0, "{sum}");
    assert_eq!(sum["stop_timeouts"], 0, "{sum}");
    // Paused, not racing: no frame was published to nobody (racing, the host would have
    // published ~29; one may go to a TCP socket the agent closed as it left).
    assert!(
        sum["frames_undelivered"].as_u64().unwrap() <= 1,
        "{t:?}: {sum}"
    );
    // The cycles of the first agent, perhaps the one it left in, then the new agent's.
    let cycles: Vec<u64> = cycle_log(&log).iter().map(|l| l.cycle).collect();
    let resumed = cycles[0];
    assert!((10..=11).contains(&resumed), "{cycles:?}");
    assert_eq!(cycles, (resumed..40).collect::<Vec<_>>());
}

/// Nobody comes back: the host gives up after `connect_timeout` with exit 1 and an error
/// naming the session and the wait; the summary is still written.
fn with_nobody_back_in_time_the_host_gives_up(t: Transport) {
    let mut cfg = TestConfig::with_transport("idle-give-up", 1, t);
    cfg.connect_timeout_s = 3.0;
    let session = cfg.session.clone();
    let run = HostRun::start(cfg, &["--frames", "100"]);
    let (agent, _) = run.agent(0, "a0.log", &["--policy", "circle", "--frames", "5"]);
    assert_eq!(agent.wait(RUN_DEADLINE).code(), Some(0));
    let out = run.host.wait(RUN_DEADLINE);
    assert_eq!(out.code(), Some(1), "{t:?}: stderr:\n{}", out.stderr);
    assert!(out.stderr.contains(&session), "{}", out.stderr);
    assert!(out.stderr.contains("gives up"), "{}", out.stderr);
    let sum = summary(&run.summary);
    let frames = sum["frames"].as_u64().unwrap();
    assert!((5..=6).contains(&frames), "{sum}");
    assert!(sum["error"].as_str().unwrap().contains("waited "), "{sum}");
    let error = run.events.wait_for("error", EVENT_DEADLINE);
    assert!(
        error["message"].as_str().unwrap().contains(&session),
        "{error}"
    );
}

for_each_transport!(
    a_busy_agent_costs_nothing_and_is_reported_slow,
    an_agent_killed_while_the_host_waits_for_it_is_evicted_at_once,
    with_nobody_attached_the_host_pauses_until_agents_are_back,
    with_nobody_back_in_time_the_host_gives_up,
);
