//! Faults with real processes: agents and hosts killed with SIGKILL, two hosts for one
//! session, stale shared memory, an oversized config, bad commands, SIGINT/SIGTERM.

use std::time::Duration;

use crate::util::{
    self, EVENT_DEADLINE, Events, HostRun, Proc, RUN_DEADLINE, TestConfig, Transport, bin,
    cycle_log, spawn_host, summary, wait_for_cycle_line,
};

/// Names of iceoryx2 services of `session` that still exist.
fn services_of(session: &str) -> Vec<String> {
    use iceoryx2::prelude::*;
    let prefix = format!("vrsync/{session}/");
    let mut found = Vec::new();
    ipc::Service::list(Config::global_config(), |s| {
        let name = s.static_details.name().to_string();
        if name.starts_with(&prefix) {
            found.push(name);
        }
        CallbackProgression::Continue
    })
    .expect("list services");
    found
}

/// An agent is SIGKILLed mid-run: the host evicts it (long before the stop timeout), the
/// other agent goes on without a gap, and a restarted agent with the same id rejoins.
fn a_killed_agent_is_evicted_and_can_rejoin(t: Transport) {
    let mut cfg = TestConfig::with_transport("evict", 2, t);
    cfg.stop_timeout_s = 30.0; // eviction must not wait for it
    // No --frames: the run goes on (fast: nobody is waited for) until the restarted agent
    // took part, then SIGTERM ends it.
    let run = HostRun::start(cfg, &[]);
    let events = &run.events;
    let (a0, log0) = run.agent(0, "a0.log", &["--policy", "circle"]);
    // Agent 1 leaves after 10 cycles by being killed: it stops answering in cycle 10.
    let (victim, log1) = run.agent(
        1,
        "a1.log",
        &[
            "--policy",
            "circle",
            "--frames",
            "10",
            "--late-stop-at",
            "9",
        ],
    );
    // --late-stop-at 9 makes it sleep 1.5 × stop_timeout before its 10th stop, after it
    // logged cycle 9: kill it then.
    wait_for_cycle_line(&log1, 9, EVENT_DEADLINE);
    victim.signal(libc::SIGKILL);
    let _ = victim.wait(Duration::from_secs(10));
    let evicted = events.wait_for("agent_evicted", EVENT_DEADLINE);
    assert_eq!(evicted["agent"], 1, "{evicted}");
    assert_eq!(evicted["cycle"], 9, "{evicted}");
    // Restart agent 1: it rejoins at the next cycle and takes part from there.
    let (back, log_back) = run.agent(1, "back.log", &["--policy", "circle"]);
    let rejoined = events.wait_for("agent_rejoined", EVENT_DEADLINE);
    assert_eq!(rejoined["agent"], 1, "{rejoined}");
    let rejoined_at = rejoined["cycle"].as_u64().unwrap();
    assert!(rejoined_at > 9, "{rejoined}");
    // The restarted agent took part in a whole cycle: it got the frame of the cycle after
    // its first, so the host completed that first one. (Its log line of the first cycle
    // alone is not enough: SIGTERM can end the run while the host still waits for that
    // cycle's stop, and an interrupted cycle is not counted in `frames`; over zenoh, whose
    // stop takes longer to arrive, that happened in 8 of 40 runs on a loaded machine.)
    wait_for_cycle_line(&log_back, rejoined_at + 1, EVENT_DEADLINE);
    run.host.signal(libc::SIGTERM);
    let out = run.host.wait(RUN_DEADLINE);
    assert_eq!(out.code(), Some(0), "stderr:\n{}", out.stderr);
    assert_eq!(a0.wait(Duration::from_secs(10)).code(), Some(0));
    assert_eq!(back.wait(Duration::from_secs(10)).code(), Some(0));
    let sum = summary(&run.summary);
    let frames = sum["frames"].as_u64().unwrap();
    assert!(frames > rejoined_at, "{sum}");
    assert_eq!(sum["evicted_agents"], serde_json::json!([1]));
    assert_eq!(sum["evictions"], 1, "{sum}");
    assert_eq!(sum["rejoins"], 1, "{sum}");
    // Agent 0 got every frame, agent 1 its first 10 (maybe the one of the cycle it was
    // evicted in) and every one since it rejoined.
    let delivered = sum["frames_delivered"].as_u64().unwrap();
    let read = sum["frames_read"].as_u64().unwrap();
    assert!(
        delivered >= frames + 10 + (frames - rejoined_at),
        "{rejoined_at}: {sum}"
    );
    assert!(read > 0 && read <= delivered, "{sum}");
    for key in [
        "future_stops",
        "commands_overflowed",
        "statuses_dropped",
        "collisions_dropped",
    ] {
        assert_eq!(sum[key], 0, "{key}: {sum}");
    }
    assert_eq!(
        sum["stop_timeouts"], 0,
        "a dead agent is evicted, not waited for"
    );
    // The survivor saw every cycle, without a gap (and maybe the frame of the cycle the
    // signal interrupted).
    let cycles: Vec<u64> = cycle_log(&log0).iter().map(|l| l.cycle).collect();
    let seen = cycles.len() as u64;
    assert!(
        seen == frames || seen == frames + 1,
        "{frames} cycles: {cycles:?}"
    );
    assert_eq!(cycles, (0..seen).collect::<Vec<_>>());
    // The restarted agent's first frame is the cycle it rejoined at.
    assert_eq!(cycle_log(&log_back)[0].cycle, rejoined_at);
}

/// The host is SIGKILLed: a waiting agent's wait_start reports "host gone" (vr-agent exits
/// 1 with a clear message); a new host for the same session starts cleanly afterwards.
fn a_killed_host_is_noticed_and_a_new_host_starts(t: Transport) {
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = TestConfig::with_transport("deadhost", 1, t);
    let config_path = cfg.write(dir.path());
    let config = config_path.to_str().unwrap();
    let events = Events::in_dir(dir.path());
    let host = spawn_host(&config_path, &events, &[]);
    cfg.follow_host(&events, &config_path);
    let log = dir.path().join("a0.log");
    let agent = Proc::spawn(
        &bin("vr-agent"),
        &[
            "--config",
            config,
            "--id",
            "0",
            "--policy",
            "idle",
            "--log-cycles",
            log.to_str().unwrap(),
        ],
    );
    events.wait_for("all_agents_connected", EVENT_DEADLINE);
    wait_for_cycle_line(&log, 0, EVENT_DEADLINE);
    host.signal(libc::SIGKILL);
    let _ = host.wait(Duration::from_secs(10));
    let out = agent.wait(Duration::from_secs(10));
    assert_eq!(out.code(), Some(1), "stderr:\n{}", out.stderr);
    assert!(out.stderr.contains("host is gone"), "{}", out.stderr);

    // A new host with the same session cleans what the dead one left and runs.
    let s = dir.path().join("summary.json");
    let out = util::run(
        "vr-sim",
        &[
            "run",
            "--config",
            config,
            "--frames",
            "5",
            "--spawn-agents",
            "1",
            "--summary-json",
            s.to_str().unwrap(),
            "--quiet",
        ],
        RUN_DEADLINE,
    );
    assert_eq!(out.code(), Some(0), "stderr:\n{}", out.stderr);
    assert_eq!(summary(&s)["frames"], 5);
}

/// A SIGKILLed host cannot remove its wake word (its page in /dev/shm); the next host of
/// any session does, not only one of its own: sessions are often one-off.
#[test]
fn a_killed_hosts_wake_word_is_removed_by_another_sessions_host() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = TestConfig::new("sweptword", 1);
    let config_path = cfg.write(dir.path());
    let events = Events::in_dir(dir.path());
    let host = spawn_host(&config_path, &events, &[]);
    events.wait_for("waiting_for_agents", EVENT_DEADLINE);
    let page =
        std::path::Path::new("/dev/shm").join(vrsync_bridge::shm::wake_word_name(&cfg.session));
    assert!(
        page.exists(),
        "{} missing while its host runs",
        page.display()
    );
    host.signal(libc::SIGKILL);
    let _ = host.wait(Duration::from_secs(10));
    // (The page is not checked for here: a host of a test running beside this one may
    // already have swept it.)

    let other_dir = tempfile::tempdir().unwrap();
    let other = TestConfig::new("sweeper", 1).write(other_dir.path());
    let out = util::run(
        "vr-sim",
        &[
            "run",
            "--config",
            other.to_str().unwrap(),
            "--frames",
            "2",
            "--spawn-agents",
            "1",
            "--quiet",
        ],
        RUN_DEADLINE,
    );
    assert_eq!(out.code(), Some(0), "stderr:\n{}", out.stderr);
    assert!(
        !page.exists(),
        "{} outlived its killed host",
        page.display()
    );
}

#[test]
fn two_live_hosts_for_one_session_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = TestConfig::new("twohosts", 1);
    let config = cfg.write(dir.path());
    let config = config.to_str().unwrap();
    let events = Events::in_dir(dir.path());
    let first = Proc::spawn(
        &bin("vr-sim"),
        &[
            "run",
            "--config",
            config,
            "--events",
            events.arg(),
            "--quiet",
        ],
    );
    events.wait_for("waiting_for_agents", EVENT_DEADLINE);
    let out = util::run(
        "vr-sim",
        &["run", "--config", config, "--quiet"],
        Duration::from_secs(30),
    );
    assert_eq!(out.code(), Some(1), "stderr:\n{}", out.stderr);
    assert!(out.stderr.contains("already hosted"), "{}", out.stderr);
    assert!(out.stderr.contains(&cfg.session), "{}", out.stderr);
    first.signal(libc::SIGTERM);
    let _ = first.wait(Duration::from_secs(30));
}

#[test]
fn a_config_that_does_not_fit_dev_shm_is_refused_with_the_numbers() {
    let dir = tempfile::tempdir().unwrap();
    let mut text = String::from("session = \"budget\"\n");
    for id in 0..250 {
        text += &format!("[[agent]]\nid = {id}\n");
        for c in 0..4 {
            text += &format!(
                "[[agent.camera]]\nname = \"c{c}\"\nwidth = 8192\nheight = 8192\nformat = \"rgba8\"\n"
            );
        }
    }
    let path = dir.path().join("huge.toml");
    std::fs::write(&path, &text).unwrap();
    let out = util::run(
        "vr-sim",
        &["run", "--config", path.to_str().unwrap(), "--quiet"],
        Duration::from_secs(60),
    );
    assert_eq!(out.code(), Some(2), "stderr:\n{}", out.stderr);
    assert!(out.stderr.contains("huge.toml:"), "{}", out.stderr);
    assert!(out.stderr.contains("agent.camera"), "{}", out.stderr);
    assert!(out.stderr.contains("MB of shared memory"), "{}", out.stderr);
    assert!(out.stderr.contains("/dev/shm"), "{}", out.stderr);
}

/// Invalid commands are rejected and counted, and the world is untouched: the trajectory
/// equals that of the same run without them.
fn bad_commands_are_rejected_and_leave_the_world_untouched(t: Transport) {
    let dir = tempfile::tempdir().unwrap();
    let mut hashes = Vec::new();
    for bad in [false, true] {
        let cfg = TestConfig::with_transport("badcmd", 1, t);
        let config = cfg.write(dir.path());
        let s = dir.path().join(format!("s{bad}.json"));
        let events = Events::in_dir(dir.path());
        let mut args = vec![
            "run".to_string(),
            "--config".into(),
            config.display().to_string(),
            "--frames".into(),
            "40".into(),
            "--spawn-agents".into(),
            "1".into(),
            "--agent-arg=--policy".into(),
            "--agent-arg=circle".into(),
            "--summary-json".into(),
            s.display().to_string(),
            "--events".into(),
            events.arg().into(),
            "--quiet".into(),
        ];
        if bad {
            args.push("--agent-arg=--bad-commands".into());
        }
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let out = util::run("vr-sim", &args, RUN_DEADLINE);
        assert_eq!(out.code(), Some(0), "stderr:\n{}", out.stderr);
        let sum = summary(&s);
        assert_eq!(sum["commands_applied"], 40);
        assert_eq!(sum["commands_rejected"], if bad { 160 } else { 0 });
        // Reported once per agent and kind, not once per command.
        let reported: Vec<String> = events
            .of("command_rejected")
            .iter()
            .map(|e| e["kind"].as_str().unwrap().to_string())
            .collect();
        let expected: &[&str] = if bad {
            &["move", "grasp_id", "unknown"]
        } else {
            &[]
        };
        assert_eq!(
            reported, expected,
            "move (NaN, then out of range), grasp_id, unknown"
        );
        hashes.push(sum["trajectory_hash"].as_str().unwrap().to_string());
    }
    assert_eq!(hashes[0], hashes[1]);
}

/// SIGINT and SIGTERM end the host's loop after the current cycle: the summary is still
/// printed and written, the agent leaves cleanly, and no service of the session remains.
fn a_signal_ends_the_run_cleanly(t: Transport, sig: i32) {
    let run = HostRun::start(TestConfig::with_transport("signal", 1, t), &[]);
    let events = &run.events;
    let agent = Proc::spawn(&bin("vr-agent"), &["--config", run.config(), "--id", "0"]);
    events.wait_for("all_agents_connected", EVENT_DEADLINE);
    run.host.signal(sig);
    let out = run.host.wait(Duration::from_secs(30));
    assert_eq!(out.code(), Some(0), "stderr:\n{}", out.stderr);
    assert!(out.stdout.contains("(interrupted)"), "{}", out.stdout);
    assert_eq!(summary(&run.summary)["interrupted"], true);
    let finished = events.wait_for("finished", EVENT_DEADLINE);
    assert_eq!(finished["interrupted"], true, "{finished}");
    assert_eq!(agent.wait(Duration::from_secs(10)).code(), Some(0));
    if t == Transport::Shm {
        assert_eq!(services_of(&run.cfg.session), Vec::<String>::new());
    }
}

/// SIGTERM on an agent ends its loop: it exits 0 and leaves gracefully (not evicted), and
/// the host goes on without it.
fn sigterm_on_an_agent(t: Transport) {
    let mut cfg = TestConfig::with_transport("agentsig", 2, t);
    cfg.stop_timeout_s = 30.0;
    let run = HostRun::start(cfg, &[]);
    let events = &run.events;
    let a0 = Proc::spawn(&bin("vr-agent"), &["--config", run.config(), "--id", "0"]);
    let (a1, log1) = run.agent(1, "a1.log", &[]);
    events.wait_for("all_agents_connected", EVENT_DEADLINE);
    // Only an agent that took part is "lost" when it leaves.
    wait_for_cycle_line(&log1, 0, EVENT_DEADLINE);
    a1.signal(libc::SIGTERM);
    let out = a1.wait(Duration::from_secs(10));
    assert_eq!(out.code(), Some(0), "stderr:\n{}", out.stderr);
    let left = events.wait_for_match("agent_left", |e| e["graceful"] == true, EVENT_DEADLINE);
    assert_eq!(left["agent"], 1, "{left}");
    run.host.signal(libc::SIGTERM);
    let out = run.host.wait(Duration::from_secs(30));
    assert_eq!(out.code(), Some(0), "stderr:\n{}", out.stderr);
    assert_eq!(a0.wait(Duration::from_secs(10)).code(), Some(0));
    let sum = summary(&run.summary);
    assert_eq!(sum["evicted_agents"], serde_json::json!([]), "{sum}");
    assert_eq!(sum["leaves"], 1, "{sum}");
    assert_eq!(sum["stop_timeouts"], 0);
    assert!(events.of("agent_evicted").is_empty(), "{:?}", events.read());
}

/// `on_agent_lost = "abort"`: a killed agent ends the run with an error naming it (exit 1),
/// and the summary is not claimed.
fn on_agent_lost_abort_ends_the_run(t: Transport) {
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = TestConfig::with_transport("abort", 2, t);
    cfg.stop_timeout_s = 30.0;
    cfg.sync_extra = "on_agent_lost = \"abort\"\n".into();
    let config_path = cfg.write(dir.path());
    let config = config_path.to_str().unwrap();
    let events = Events::in_dir(dir.path());
    let host = spawn_host(&config_path, &events, &[]);
    cfg.follow_host(&events, &config_path);
    let log1 = dir.path().join("a1.log");
    let a0 = Proc::spawn(&bin("vr-agent"), &["--config", config, "--id", "0"]);
    let a1 = Proc::spawn(
        &bin("vr-agent"),
        &[
            "--config",
            config,
            "--id",
            "1",
            "--log-cycles",
            log1.to_str().unwrap(),
        ],
    );
    wait_for_cycle_line(&log1, 0, EVENT_DEADLINE);
    a1.signal(libc::SIGKILL);
    let _ = a1.wait(Duration::from_secs(10));
    let out = host.wait(Duration::from_secs(30));
    assert_eq!(out.code(), Some(1), "stderr:\n{}", out.stderr);
    assert!(out.stderr.contains("agent 1 was lost"), "{}", out.stderr);
    assert!(out.stderr.contains("abort"), "{}", out.stderr);
    let error = events.wait_for("error", EVENT_DEADLINE);
    assert!(
        error["message"]
            .as_str()
            .unwrap()
            .contains("agent 1 was lost"),
        "{error}"
    );
    let evicted = events.wait_for("agent_evicted", EVENT_DEADLINE);
    assert_eq!(evicted["agent"], 1, "{evicted}");
    assert_eq!(a0.wait(Duration::from_secs(10)).code(), Some(0));
}

/// `on_agent_lost = "wait"`: the simulation pauses until the agent is back, then goes on;
/// nobody is left behind.
fn on_agent_lost_wait_pauses_until_the_agent_is_back(t: Transport) {
    let mut cfg = TestConfig::with_transport("waitlost", 2, t);
    cfg.stop_timeout_s = 30.0;
    cfg.sync_extra = "on_agent_lost = \"wait\"\n".into();
    let run = HostRun::start(cfg, &[]);
    let events = &run.events;
    let (a0, _log0) = run.agent(0, "a0.log", &[]);
    let (a1, log1) = run.agent(1, "a1.log", &[]);
    wait_for_cycle_line(&log1, 0, EVENT_DEADLINE);
    a1.signal(libc::SIGKILL);
    let _ = a1.wait(Duration::from_secs(10));
    let evicted = events.wait_for("agent_evicted", EVENT_DEADLINE);
    assert_eq!(evicted["agent"], 1, "{evicted}");
    let paused_at = evicted["cycle"].as_u64().unwrap();
    let back = Proc::spawn(&bin("vr-agent"), &["--config", run.config(), "--id", "1"]);
    let rejoined = events.wait_for("agent_rejoined", EVENT_DEADLINE);
    assert_eq!(rejoined["agent"], 1, "{rejoined}");
    // Nobody was left behind: the host paused, so agent 1 is back at the very next cycle.
    assert_eq!(
        rejoined["cycle"].as_u64().unwrap(),
        paused_at + 1,
        "{rejoined}"
    );
    run.host.signal(libc::SIGTERM);
    let out = run.host.wait(Duration::from_secs(30));
    assert_eq!(out.code(), Some(0), "stderr:\n{}", out.stderr);
    assert_eq!(a0.wait(Duration::from_secs(10)).code(), Some(0));
    assert_eq!(back.wait(Duration::from_secs(10)).code(), Some(0));
    assert_eq!(
        summary(&run.summary)["evicted_agents"],
        serde_json::json!([1])
    );
}

fn sigint(t: Transport) {
    a_signal_ends_the_run_cleanly(t, libc::SIGINT);
}

fn sigterm(t: Transport) {
    a_signal_ends_the_run_cleanly(t, libc::SIGTERM);
}

for_each_transport!(
    a_killed_agent_is_evicted_and_can_rejoin,
    a_killed_host_is_noticed_and_a_new_host_starts,
    bad_commands_are_rejected_and_leave_the_world_untouched,
    sigint,
    sigterm,
    sigterm_on_an_agent,
    on_agent_lost_abort_ends_the_run,
    on_agent_lost_wait_pauses_until_the_agent_is_back,
);
