//! Action statuses and collisions reach the agent's code exactly once, whatever frames it
//! skips: late in sync mode (stop timeouts), slow in async mode, stopped (SIGSTOP) for three
//! cycles. The host's `--record` lists every event the world reported (those recorded at
//! cycle `c` go out in frame `c + 1`); `vr-agent --log-events` lists every event the
//! agent's frames handed out.

use std::collections::BTreeMap;
use std::path::Path;
use std::time::{Duration, Instant};

use vrsync_agent_bin::policy::STATUS_WAIT_CYCLES;

use crate::util::{
    CycleLine, EVENT_DEADLINE, Events, Proc, RUN_DEADLINE, TestConfig, Transport,
    WAIT_FOR_STOP_TIMEOUT, bin, cycle_log, record, spawn_host,
};

/// `Finished` and `Aborted`, as the wire encodes them.
const FINAL_STATES: [u64; 2] = [1, 2];

/// What the agent's frames handed out: `(action id, state)` of every final status, and
/// `(action id, collider)` of every collision, each with how often it came.
#[derive(Debug, Default, PartialEq)]
struct Seen {
    finals: BTreeMap<(u64, u64), u32>,
    collisions: BTreeMap<(u64, u64), u32>,
}

/// Every final status and collision agent 0 was to get in the frames up to `last_frame`,
/// and how many final statuses went out in frames the agent did not read. The agent's
/// cycle log `cycles` lists the frames it read and the action ids it sent.
///
/// The world's events are in the record (its cycle `c` goes out in frame `c + 1`). Besides,
/// the host reports `Aborted` for every command it dropped (a batch that came too late):
/// the commands the agent sent that the world never applied (but for those of its last
/// frames: in async mode the run may end before they arrive).
fn reported(record_path: &Path, last_frame: u64, cycles: &[CycleLine]) -> (Seen, usize) {
    let mut seen = Seen::default();
    let mut in_skipped_frames = 0;
    let read: Vec<u64> = cycles.iter().map(|c| c.cycle).collect();
    let mut never_applied: std::collections::BTreeSet<u64> = cycles[..cycles.len() - 3]
        .iter()
        .flat_map(|c| c.action_ids.iter().map(|&id| u64::from(id)))
        .collect();
    for line in record(record_path) {
        let frame = line["cycle"].as_u64().unwrap() + 1;
        if line["agent"] != 0 {
            continue;
        }
        for c in line["commands"].as_array().unwrap() {
            never_applied.remove(&c[1].as_u64().unwrap());
        }
        if frame > last_frame {
            continue;
        }
        for s in line["statuses"].as_array().unwrap() {
            let (id, state) = (s[0].as_u64().unwrap(), s[1].as_u64().unwrap());
            if FINAL_STATES.contains(&state) {
                *seen.finals.entry((id, state)).or_default() += 1;
                if !read.contains(&frame) {
                    in_skipped_frames += 1;
                }
            }
        }
        for c in line["collisions"].as_array().unwrap() {
            let key = (c[0].as_u64().unwrap(), c[1].as_u64().unwrap());
            *seen.collisions.entry(key).or_default() += 1;
        }
    }
    for id in never_applied {
        *seen.finals.entry((id, 2)).or_default() += 1;
    }
    (seen, in_skipped_frames)
}

/// The `--log-events` file: what the frames handed out. Also checks that no sequence
/// number came twice.
fn handed_out(path: &Path) -> Seen {
    let text = std::fs::read_to_string(path).unwrap();
    let mut seen = Seen::default();
    let mut seqs = std::collections::BTreeSet::new();
    for line in text.lines() {
        let f: Vec<&str> = line.split(' ').collect();
        let num = |i: usize| f[i].parse::<u64>().unwrap();
        assert!(seqs.insert(num(4)), "sequence number twice: {line}\n{text}");
        match f[1] {
            "status" if FINAL_STATES.contains(&num(3)) => {
                *seen.finals.entry((num(2), num(3))).or_default() += 1;
            }
            "status" => {}
            "collision" => *seen.collisions.entry((num(2), num(3))).or_default() += 1,
            other => panic!("unknown event kind {other:?} in {line}"),
        }
    }
    seen
}

/// Runs `frames` cycles of vr-sim with one agent running `policy` with `agent_args`, lets
/// `disturb` upset the agent (given the host's events, the agent and its cycle log), and
/// checks that the
/// agent skipped frames and still got every final status and every collision exactly
/// once. Returns the agent's cycle log.
///
/// `circle` sends a short move (5 cm) every cycle; in [`SLOW_WORLD`] each takes two
/// cycles, ending `Finished` or `Aborted` by the next one: every frame brings a final
/// status, so the frames the agent skips surely carried some (checked).
fn every_event_once(
    cfg: &mut TestConfig,
    frames: u64,
    policy: &str,
    agent_args: &[&str],
    disturb: impl FnOnce(&Events, &Proc, &Path),
) -> Vec<CycleLine> {
    let dir = tempfile::tempdir().unwrap();
    let config_path = cfg.write(dir.path());
    let events = Events::in_dir(dir.path());
    let rec = dir.path().join("record.jsonl");
    let frames_arg = frames.to_string();
    let host = spawn_host(
        &config_path,
        &events,
        &["--frames", &frames_arg, "--record", rec.to_str().unwrap()],
    );
    cfg.follow_host(&events, &config_path);
    let log = dir.path().join("cycles.log");
    let event_log = dir.path().join("events.log");
    let mut args = vec![
        "--config",
        config_path.to_str().unwrap(),
        "--id",
        "0",
        "--policy",
        policy,
        "--log-cycles",
        log.to_str().unwrap(),
        "--log-events",
        event_log.to_str().unwrap(),
    ];
    args.extend_from_slice(agent_args);
    let agent = Proc::spawn(&bin("vr-agent"), &args);
    disturb(&events, &agent, &log);
    let out = host.wait(RUN_DEADLINE);
    assert_eq!(out.code(), Some(0), "host stderr:\n{}", out.stderr);
    let a = agent.wait(Duration::from_secs(30));
    assert_eq!(a.code(), Some(0), "agent stderr:\n{}", a.stderr);

    let cycles = cycle_log(&log);
    let last = cycles.last().unwrap();
    assert!(
        last.skipped > 0,
        "the agent was meant to skip frames: {cycles:?}"
    );
    let (expected, in_skipped_frames) = reported(&rec, last.cycle, &cycles);
    let got = handed_out(&event_log);
    assert!(
        !expected.finals.is_empty(),
        "the world reported no Finished/Aborted status"
    );
    if policy == "circle" {
        assert!(
            in_skipped_frames > 0,
            "no final status went out in a skipped frame: nothing tested"
        );
    }
    assert_eq!(
        got.finals, expected.finals,
        "final statuses handed out (left) vs reported (right), frames up to {}",
        last.cycle
    );
    assert!(
        got.finals.values().all(|&n| n == 1),
        "a final status twice: {got:?}"
    );
    assert_eq!(got.collisions, expected.collisions, "collisions");
    cycles
}

/// Cycles that ended without agent 0 so far (the host's `cycle` events name them).
fn timed_out_cycles(events: &Events) -> usize {
    events
        .of("cycle")
        .iter()
        .filter(|e| e["timed_out_agents"] == serde_json::json!([0]))
        .count()
}

/// Sync mode: the agent, started with `--sigstop-after` `stalls` cycles, stops itself
/// (SIGSTOP) after each of them; each time, once it is stopped and three cycles ended by the
/// stop timeout, it is continued (SIGCONT). Where it stops does not depend on how fast the
/// machine runs the cycles.
fn continue_after_three_cycles(events: &Events, agent: &Proc, stalls: usize) {
    for _ in 0..stalls {
        let deadline = Instant::now() + EVENT_DEADLINE;
        while !agent.is_stopped() {
            assert!(
                Instant::now() < deadline,
                "the agent did not stop itself within {EVENT_DEADLINE:?}"
            );
            // Another process's state: look again shortly.
            std::thread::sleep(Duration::from_millis(5));
        }
        let before = timed_out_cycles(events);
        events.wait_for_match(
            "cycle",
            |_| timed_out_cycles(events) >= before + 3,
            EVENT_DEADLINE,
        );
        agent.signal(libc::SIGCONT);
    }
}

/// A world where a move of `circle` (5 cm at 2.5 cm per cycle) takes two cycles: the move
/// of the last cycle before a stall ends in the first frame the agent skips, whether its
/// last batch arrived or not.
const SLOW_WORLD: &str = "[world]\nmovement_speed = 0.25\n";

fn a_stopped_agent_gets_every_event_once(t: Transport) {
    let mut cfg = TestConfig::with_transport("ev-sigstop", 1, t);
    cfg.stop_timeout_s = 0.3;
    cfg.sync_extra = WAIT_FOR_STOP_TIMEOUT.into();
    cfg.extra = SLOW_WORLD.into();
    // After a stall at `at`, frames `at + 1` and `at + 2` carry the final statuses of the
    // moves sent before it (a move takes two cycles); the test needs the agent to skip one
    // of them. Over shm and TCP every stall does (the agent reads the newest frame); over
    // zenoh the frames sent during the stall reach the agent one by one after SIGCONT (see
    // `wander_keeps_its_command_rate_after_a_stall`), so it may read both: four stalls.
    let args = ["--sigstop-after", "30,45,60,75"];
    every_event_once(&mut cfg, 100, "circle", &args, |events, agent, _| {
        continue_after_three_cycles(events, agent, 4);
    });
}

fn a_late_agent_gets_every_event_once(t: Transport) {
    let mut cfg = TestConfig::with_transport("ev-late", 1, t);
    cfg.stop_timeout_s = 0.3;
    cfg.sync_extra = WAIT_FOR_STOP_TIMEOUT.into();
    cfg.extra = SLOW_WORLD.into();
    // Late by three cycles at cycle 20: its batch comes too late, and the frames of the two
    // cycles after are skipped.
    let args = ["--late-stop-at", "20", "--late-stop-cycles", "3"];
    every_event_once(&mut cfg, 60, "circle", &args, |_, _, _| {});
}

fn a_slow_async_agent_gets_every_event_once(t: Transport) {
    let mut cfg = TestConfig::with_transport("ev-async", 1, t);
    cfg.sync_mode = false;
    cfg.dt_s = 0.02;
    cfg.extra = SLOW_WORLD.into();
    // 0..=60 ms of "compute" per frame against a frame every 20 ms: most are skipped.
    let args = ["--jitter-ms", "60"];
    every_event_once(&mut cfg, 200, "circle", &args, |_, _, _| {});
}

/// After 3-cycle stalls, `wander` goes on at its rate: it never falls back to waiting
/// [`STATUS_WAIT_CYCLES`] cycles for a status it missed (its actions last well under that
/// in this world, so a gap that long means a lost status). Four stalls, so that some
/// action surely finishes while the agent is stopped.
fn wander_keeps_its_command_rate_after_a_stall(t: Transport) {
    let mut cfg = TestConfig::with_transport("ev-rate", 1, t);
    cfg.stop_timeout_s = 0.3;
    cfg.sync_extra = WAIT_FOR_STOP_TIMEOUT.into();
    let stalls = [30, 53, 76, 99];
    let args = ["--sigstop-after", "30,53,76,99"];
    let cycles = every_event_once(&mut cfg, 160, "wander", &args, |events, agent, _| {
        continue_after_three_cycles(events, agent, stalls.len());
    });
    let sent: Vec<u64> = cycles
        .iter()
        .filter(|c| !c.action_ids.is_empty())
        .map(|c| c.cycle)
        .collect();
    let skipped: Vec<u64> = cycles
        .windows(2)
        .filter(|w| w[1].skipped > w[0].skipped)
        .map(|w| w[1].cycle)
        .collect();
    // The stalls made the agent skip frames (the case the test is about). Not every stall
    // does over zenoh: the frames published while the agent was stopped wait in its
    // socket and reach its subscriber one by one after SIGCONT, and an agent that reads
    // each as it comes skips none (a clean-clone CI run saw skips after 3 of the 4).
    let needed = if t == Transport::Zenoh {
        1
    } else {
        stalls.len()
    };
    assert!(skipped.len() >= needed, "{cycles:?}");
    let gaps: Vec<u64> = sent.windows(2).map(|w| w[1] - w[0]).collect();
    assert!(
        gaps.iter().all(|&g| g < STATUS_WAIT_CYCLES),
        "commands at {sent:?}, frames skipped before {skipped:?}"
    );
}

for_each_transport!(
    a_stopped_agent_gets_every_event_once,
    a_late_agent_gets_every_event_once,
    a_slow_async_agent_gets_every_event_once,
    wander_keeps_its_command_rate_after_a_stall,
);
