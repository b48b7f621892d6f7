//! The lock-step protocol with real processes: every cycle once and in order, stop
//! timeouts, late stops, async mode, protocol mismatch, external agents.

use std::time::Duration;

use serde_json::Value;

use crate::util::{
    self, EVENT_DEADLINE, HostRun, Proc, RUN_DEADLINE, TestConfig, Transport, bin, cycle_log,
    record, summary,
};

fn entries_for(rec: &[Value], agent: u64) -> Vec<&Value> {
    rec.iter().filter(|v| v["agent"] == agent).collect()
}

fn action_ids(entry: &Value) -> Vec<u32> {
    entry["commands"]
        .as_array()
        .expect("commands")
        .iter()
        .map(|c| c[1].as_u64().expect("action id") as u32)
        .collect()
}

fn three_agents_500_cycles_see_every_cycle_once_in_order(t: Transport) {
    let dir = tempfile::tempdir().unwrap();
    let cfg = TestConfig::with_transport("sync500", 3, t);
    let config = cfg.write(dir.path());
    let s = dir.path().join("summary.json");
    let rec = dir.path().join("record.jsonl");
    let log = dir.path().join("agent-{id}.log");
    let out = util::run(
        "vr-sim",
        &[
            "run",
            "--config",
            config.to_str().unwrap(),
            "--frames",
            "500",
            "--spawn-agents",
            "3",
            "--agent-arg=--policy",
            "--agent-arg=circle",
            &format!("--agent-arg=--log-cycles={}", log.display()),
            "--summary-json",
            s.to_str().unwrap(),
            "--record",
            rec.to_str().unwrap(),
            "--quiet",
        ],
        RUN_DEADLINE,
    );
    assert_eq!(out.code(), Some(0), "stderr:\n{}", out.stderr);
    let sum = summary(&s);
    assert_eq!(sum["frames"], 500);
    assert_eq!(sum["agents"], 3);
    assert_eq!(sum["mode"], "sync");
    assert_eq!(sum["transport"], t.as_str());
    assert_eq!(sum["stop_timeouts"], 0);
    assert_eq!(sum["late_stops"], 0);
    // Every agent got and read every frame; nobody left.
    assert_eq!(sum["frames_delivered"], 1500, "{sum}");
    assert_eq!(sum["frames_read"], 1500, "{sum}");
    assert_eq!(sum["frames_undelivered"], 0, "{sum}");
    assert_eq!(sum["evictions"], 0, "{sum}");
    assert_eq!(sum["rejoins"], 0, "{sum}");

    let rec = record(&rec);
    assert_eq!(rec.len(), 1500);
    let mut total_sent = 0;
    for agent in 0..3u64 {
        let lines = cycle_log(&dir.path().join(format!("agent-{agent}.log")));
        let cycles: Vec<u64> = lines.iter().map(|l| l.cycle).collect();
        assert_eq!(cycles, (0..500).collect::<Vec<_>>(), "agent {agent} cycles");
        for l in &lines {
            assert_eq!(
                l.sim_time_ns,
                l.cycle * 100_000_000,
                "sim time of cycle {}",
                l.cycle
            );
            assert_eq!(l.skipped, 0);
            assert_eq!(l.action_ids.len(), 1, "circle sends one command per cycle");
        }
        // The host got every batch, for the cycle the agent answered.
        let host_side = entries_for(&rec, agent);
        assert_eq!(host_side.len(), 500);
        for (entry, l) in host_side.iter().zip(&lines) {
            assert_eq!(entry["cycle"], l.cycle);
            assert_eq!(entry["outcome"], "stopped");
            assert_eq!(
                action_ids(entry),
                l.action_ids,
                "agent {agent} cycle {}",
                l.cycle
            );
        }
        total_sent += lines.len() as u64;
    }
    assert_eq!(sum["commands_applied"], total_sent);
}

fn a_late_stop_times_out_its_cycle_and_never_completes_the_next(t: Transport) {
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = TestConfig::with_transport("late", 2, t);
    cfg.stop_timeout_s = 0.3;
    cfg.sync_extra = util::WAIT_FOR_STOP_TIMEOUT.into();
    let rec = dir.path().join("record.jsonl");
    let run = HostRun::start_in(
        dir,
        cfg,
        &["--frames", "12", "--record", rec.to_str().unwrap()],
    );
    let events = &run.events;
    let (a0, _log0) = run.agent(0, "a0.log", &["--policy", "circle"]);
    let (a1, log1) = run.agent(1, "a1.log", &["--policy", "circle", "--late-stop-at", "5"]);
    let out = run.host.wait(RUN_DEADLINE);
    assert_eq!(out.code(), Some(0), "stderr:\n{}", out.stderr);
    assert_eq!(a0.wait(Duration::from_secs(10)).code(), Some(0));
    assert_eq!(a1.wait(Duration::from_secs(10)).code(), Some(0));

    // The cycle that timed out names the missing agent.
    let timed_out: Vec<Value> = events
        .of("cycle")
        .into_iter()
        .filter(|e| e["timed_out_agents"] != serde_json::json!([]))
        .collect();
    assert_eq!(timed_out.len(), 1, "{timed_out:?}");
    assert_eq!(timed_out[0]["cycle"], 5, "{timed_out:?}");
    assert_eq!(timed_out[0]["timed_out_agents"], serde_json::json!([1]));

    let sum = summary(&run.summary);
    assert_eq!(sum["frames"], 12);
    assert_eq!(sum["stop_timeouts"], 1);
    assert_eq!(sum["agent_timeouts"], 1);
    assert_eq!(sum["late_stops"], 1);

    let rec = record(&rec);
    let agent1 = cycle_log(&log1);
    assert_eq!(
        agent1.iter().map(|l| l.cycle).collect::<Vec<_>>(),
        (0..12).collect::<Vec<_>>()
    );
    for entry in entries_for(&rec, 1) {
        let cycle = entry["cycle"].as_u64().unwrap();
        let sent = &agent1[cycle as usize].action_ids;
        if cycle == 5 {
            assert_eq!(entry["outcome"], "timed_out");
            assert!(
                action_ids(entry).is_empty(),
                "late commands must not be applied"
            );
        } else {
            assert_eq!(entry["outcome"], "stopped", "cycle {cycle}");
            // Cycle 6 holds exactly what the agent sent for 6: nothing of its late batch.
            assert_eq!(&action_ids(entry), sent, "cycle {cycle}");
        }
    }
    for entry in entries_for(&rec, 0) {
        assert_eq!(entry["outcome"], "stopped");
    }
}

fn async_mode_a_slow_agent_always_reads_the_newest_frame(t: Transport) {
    let mut cfg = TestConfig::with_transport("async", 2, t);
    cfg.sync_mode = false;
    cfg.dt_s = 0.01;
    let run = HostRun::start(cfg, &["--frames", "150"]);
    let (fast, _fast_log) = run.agent(0, "fast.log", &["--policy", "circle"]);
    let (slow, slow_log) = run.agent(1, "slow.log", &["--policy", "circle", "--jitter-ms", "80"]);
    let out = run.host.wait(RUN_DEADLINE);
    assert_eq!(out.code(), Some(0), "stderr:\n{}", out.stderr);
    assert_eq!(fast.wait(Duration::from_secs(10)).code(), Some(0));
    assert_eq!(slow.wait(Duration::from_secs(10)).code(), Some(0));
    let sum = summary(&run.summary);
    assert_eq!(sum["mode"], "async");
    assert_eq!(sum["frames"], 150);

    let slow = cycle_log(&slow_log);
    assert!(!slow.is_empty());
    // Never an older frame after a newer one, and nothing but skips in between: the agent
    // does not work through a backlog (the subscriber keeps only the newest frame).
    for w in slow.windows(2) {
        assert!(w[1].cycle > w[0].cycle, "{:?} then {:?}", w[0], w[1]);
    }
    let last = slow.last().unwrap();
    assert_eq!(
        last.skipped + slow.len() as u64,
        last.cycle + 1 - slow[0].cycle + slow[0].skipped
    );
    assert!(
        last.skipped > 0,
        "a slow agent in async mode must skip frames: {slow:?}"
    );
    assert!((slow.len() as u64) < sum["frames"].as_u64().unwrap());
}

/// `vr-agent` refused a host of protocol 999 (session id `0xdeadbeef`) and said both
/// versions.
fn assert_refused_protocol_999(out: &util::Output) {
    assert_eq!(out.code(), Some(1), "stderr:\n{}", out.stderr);
    assert!(out.stderr.contains("protocol 999"), "{}", out.stderr);
    assert!(out.stderr.contains("00000000deadbeef"), "{}", out.stderr);
    assert!(
        out.stderr.contains(&format!(
            "this agent speaks protocol {}",
            vrsync_bridge::PROTOCOL_VERSION
        )),
        "{}",
        out.stderr
    );
}

#[test]
fn a_protocol_mismatch_is_refused_at_connect_with_both_versions_shm() {
    use iceoryx2::prelude::*;
    use iceoryx2::service::attribute::{AttributeKey, AttributeValue};

    let dir = tempfile::tempdir().unwrap();
    let mut cfg = TestConfig::new("mismatch", 1);
    cfg.connect_timeout_s = 5.0;
    let config = cfg.write(dir.path());

    // A "host" of another protocol version: the start service with other attributes.
    let node = NodeBuilder::new().create::<ipc::Service>().unwrap();
    let name = ServiceName::new(&format!("vrsync/{}/start", cfg.session)).unwrap();
    let attrs = AttributeSpecifier::new()
        .define(
            &AttributeKey::try_from("vrsync.protocol_version").unwrap(),
            &AttributeValue::try_from("999").unwrap(),
        )
        .unwrap()
        .define(
            &AttributeKey::try_from("vrsync.layout_hash").unwrap(),
            &AttributeValue::try_from("00000000deadbeef").unwrap(),
        )
        .unwrap();
    let _service = node
        .service_builder(&name)
        .event()
        .create_with_attributes(&attrs)
        .unwrap();

    let out = util::run(
        "vr-agent",
        &["--config", config.to_str().unwrap(), "--id", "0"],
        Duration::from_secs(30),
    );
    assert_refused_protocol_999(&out);
}

fn without_spawn_the_host_says_which_agents_it_waits_for(t: Transport) {
    let run = HostRun::start(
        TestConfig::with_transport("external", 2, t),
        &["--frames", "20"],
    );
    let (events, config) = (&run.events, run.config());
    let waiting = events.wait_for("waiting_for_agents", EVENT_DEADLINE);
    assert_eq!(waiting["agents"], serde_json::json!([0, 1]), "{waiting}");
    // Start them in reverse order: the host starts cycle 0 only when both are there.
    let a1 = Proc::spawn(&bin("vr-agent"), &["--config", config, "--id", "1"]);
    let a0 = Proc::spawn(&bin("vr-agent"), &["--config", config, "--id", "0"]);
    let out = run.host.wait(RUN_DEADLINE);
    assert_eq!(out.code(), Some(0), "stderr:\n{}", out.stderr);
    assert_eq!(a0.wait(Duration::from_secs(10)).code(), Some(0));
    assert_eq!(a1.wait(Duration::from_secs(10)).code(), Some(0));
    let sum = summary(&run.summary);
    assert_eq!(sum["frames"], 20);
    assert_eq!(sum["stop_timeouts"], 0);
    // Every agent connected before cycle 0, and cycle 0 came after all of them.
    let kinds: Vec<String> = events
        .read()
        .iter()
        .map(|e| e["event"].as_str().unwrap().to_string())
        .collect();
    let connected = |id: u64| {
        events
            .of("agent_connected")
            .iter()
            .any(|e| e["agent"] == id && e["cycle"].is_null())
    };
    assert!(connected(0) && connected(1), "{kinds:?}");
    let all = kinds.iter().position(|k| k == "all_agents_connected");
    let first_cycle = kinds.iter().position(|k| k == "cycle");
    assert!(all.is_some() && all < first_cycle, "{kinds:?}");
    assert_eq!(
        kinds.last().map(String::as_str),
        Some("finished"),
        "{kinds:?}"
    );
}

fn an_agent_without_a_host_fails_with_a_clear_error(t: Transport) {
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = TestConfig::with_transport("nohost", 1, t);
    cfg.connect_timeout_s = 0.5;
    // A port nobody listens on.
    cfg.tcp_port = util::free_tcp_port();
    let config = cfg.write(dir.path());
    let out = util::run(
        "vr-agent",
        &["--config", config.to_str().unwrap(), "--id", "0"],
        Duration::from_secs(30),
    );
    assert_eq!(out.code(), Some(1), "stderr:\n{}", out.stderr);
    match t {
        Transport::Shm => {
            assert!(out.stderr.contains("no host for session"), "{}", out.stderr);
            assert!(out.stderr.contains(&cfg.session), "{}", out.stderr);
        }
        Transport::Tcp => {
            assert!(out.stderr.contains("no host for session"), "{}", out.stderr);
            assert!(out.stderr.contains(&cfg.session), "{}", out.stderr);
            let addr = format!("at 127.0.0.1:{}", cfg.tcp_port);
            assert!(out.stderr.contains(&addr), "{}", out.stderr);
        }
        Transport::Zenoh => {
            assert!(out.stderr.contains("no host for session"), "{}", out.stderr);
            assert!(out.stderr.contains(&cfg.session), "{}", out.stderr);
            let endpoint = format!("tcp/127.0.0.1:{}", cfg.zenoh_port);
            assert!(out.stderr.contains(&endpoint), "{}", out.stderr);
        }
    }
}

#[test]
fn the_demo_runs_and_writes_its_summary() {
    let dir = tempfile::tempdir().unwrap();
    let out_dir = dir.path().join("demo");
    let out = util::run(
        "vr-sim",
        &[
            "demo",
            "--frames",
            "30",
            "--agents",
            "2",
            "--out",
            out_dir.to_str().unwrap(),
        ],
        RUN_DEADLINE,
    );
    assert_eq!(out.code(), Some(0), "stderr:\n{}", out.stderr);
    assert!(out.stdout.contains("trajectory hash"), "{}", out.stdout);
    let sum = summary(&out_dir.join("summary.json"));
    assert_eq!(sum["frames"], 30);
    assert_eq!(sum["agents"], 2);
    assert_eq!(sum["stop_timeouts"], 0);
}

#[test]
fn a_protocol_mismatch_is_refused_at_connect_with_both_versions_tcp() {
    use std::io::{Read, Write};

    let dir = tempfile::tempdir().unwrap();
    let mut cfg = TestConfig::with_transport("mismatch-tcp", 1, Transport::Tcp);
    cfg.connect_timeout_s = 5.0;
    // A "host" of another protocol version: reads the hello, answers a welcome for 999.
    let listener = std::net::TcpListener::bind(("127.0.0.1", 0)).unwrap();
    cfg.tcp_port = listener.local_addr().unwrap().port();
    let config = cfg.write(dir.path());
    let agent = Proc::spawn(
        &bin("vr-agent"),
        &["--config", config.to_str().unwrap(), "--id", "0"],
    );
    let (mut conn, _) = listener.accept().unwrap();
    conn.set_read_timeout(Some(Duration::from_secs(10)))
        .unwrap();
    let mut prefix = [0u8; 8];
    conn.read_exact(&mut prefix).unwrap();
    let len = u32::from_le_bytes(prefix[..4].try_into().unwrap()) as usize;
    let mut hello = vec![0u8; len];
    conn.read_exact(&mut hello).unwrap();
    assert_eq!(&hello[..4], b"VRSY");
    let mut welcome = Vec::new();
    welcome.extend_from_slice(&16u32.to_le_bytes());
    welcome.extend_from_slice(&2u32.to_le_bytes()); // WELCOME
    welcome.extend_from_slice(&999u32.to_le_bytes());
    welcome.extend_from_slice(&0xdead_beefu64.to_le_bytes());
    welcome.extend_from_slice(&1024u32.to_le_bytes());
    conn.write_all(&welcome).unwrap();
    let out = agent.wait(Duration::from_secs(30));
    assert_refused_protocol_999(&out);
}

// The barrier tests, written once, run over both transports (same assertions).
for_each_transport!(
    three_agents_500_cycles_see_every_cycle_once_in_order,
    a_late_stop_times_out_its_cycle_and_never_completes_the_next,
    async_mode_a_slow_agent_always_reads_the_newest_frame,
    without_spawn_the_host_says_which_agents_it_waits_for,
    an_agent_without_a_host_fails_with_a_clear_error,
);

#[test]
fn tcp_port_0_with_spawned_agents_tells_them_the_bound_port() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = TestConfig::with_transport("port0", 2, Transport::Tcp);
    assert_eq!(cfg.tcp_port, 0);
    let config = cfg.write(dir.path());
    let s = dir.path().join("summary.json");
    let out = util::run(
        "vr-sim",
        &[
            "run",
            "--config",
            config.to_str().unwrap(),
            "--frames",
            "20",
            "--spawn-agents",
            "2",
            "--summary-json",
            s.to_str().unwrap(),
            "--quiet",
        ],
        RUN_DEADLINE,
    );
    assert_eq!(out.code(), Some(0), "stderr:\n{}", out.stderr);
    let sum = summary(&s);
    assert_eq!(sum["frames"], 20);
    assert_eq!(sum["transport"], "tcp");
    assert_eq!(sum["stop_timeouts"], 0);
}
