//! Agents written for the original system, against `vr-sim run` over the legacy transport.
//!
//! The client (`legacy/client.rs`) is written from the specification
//! (`shared/reference/legacy-protocol.md`), not from the host's code: its own `MsgObject`
//! structs (both dialects) from the field tables, its own framing, PNG decoding with the
//! `png` crate.
//!
//! **Ports.** The legacy transport cannot bind port 0: agent ports are derived from
//! `local_port` (`local_port + 1 + id`), as the original clients expect. So each test picks
//! a base port from its process id and a counter, checks that the base and every agent
//! port can be bound right now, and starts the host; if the host still fails to bind (a
//! port was taken in between), the run is retried with the next candidate. The host
//! reports which it bound through its `listening` event, so nothing waits on log wording.

mod client;

use std::io::{Read, Write};
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

use crate::util::{self, Events, Proc};
use client::{ABORTED, Client, Dialect, FINISHED, MsgVrnew, ResetMsg, connect, decode_png};

// ----------------------------------------------------------------------------------------
// Host fixture
// ----------------------------------------------------------------------------------------

/// A candidate base port whose environment port and the agent ports `ids` can be bound
/// right now.
fn candidate_base(ids: &[u32]) -> u16 {
    static N: AtomicU32 = AtomicU32::new(0);
    for _ in 0..200 {
        let n = N.fetch_add(1, Ordering::Relaxed);
        let base = (21_000 + (std::process::id().wrapping_mul(7919).wrapping_add(n * 509)) % 38_000)
            as u16;
        let ports = std::iter::once(base).chain(ids.iter().map(|&id| base + 1 + id as u16));
        let held: Result<Vec<_>, _> = ports
            .map(|p| std::net::TcpListener::bind(("127.0.0.1", p)))
            .collect();
        if held.is_ok() {
            return base;
        }
    }
    panic!("no free legacy port range found");
}

/// A running `vr-sim run` serving legacy agents.
struct LegacyRun {
    host: Proc,
    base: u16,
    dir: tempfile::TempDir,
    events: Events,
}

/// Starts `vr-sim run` with the config `make(base)` and `args` (`{dir}` in an argument
/// stands for the run's directory), retrying with another base port while the host cannot
/// bind its ports (see the module docs).
fn start_host(ids: &[u32], make: impl Fn(u16) -> String, args: &[&str]) -> LegacyRun {
    let mut last_failure = String::new();
    for _ in 0..5 {
        let dir = tempfile::tempdir().unwrap();
        let base = candidate_base(ids);
        let config = dir.path().join("legacy.toml");
        std::fs::write(&config, make(base)).unwrap();
        let events = Events::in_dir(dir.path());
        let d = dir.path().to_str().unwrap();
        let args: Vec<String> = args.iter().map(|a| a.replace("{dir}", d)).collect();
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let mut host = util::spawn_host(&config, &events, &args);
        let deadline = Instant::now() + util::EVENT_DEADLINE;
        loop {
            if !events.of("listening").is_empty() {
                return LegacyRun {
                    host,
                    base,
                    dir,
                    events,
                };
            }
            if host.try_exited() {
                // Most likely a port of the range was taken in between: try the next
                // range; a host that fails for another reason fails every attempt, and
                // the last attempt's output is shown.
                let out = host.wait(Duration::from_secs(10));
                last_failure = out.stderr;
                break;
            }
            assert!(
                Instant::now() < deadline,
                "the host did not start listening"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }
    panic!("the host exited before listening in 5 attempts; the last one:\n{last_failure}");
}

fn config(session: &str, base: u16, legacy: &[u32], shm: &[u32], extra_sync: &str) -> String {
    let mut s = format!(
        "session = {session:?}\nseed = 7\n[sync]\nsync_mode = true\nstop_timeout = 5\n\
         connect_timeout = 60\n{extra_sync}\n[transport]\nkind = \"shm\"\n\
         tcp_listen = \"127.0.0.1:0\"\n[transport.legacy]\nlocal_port = {base}\n"
    );
    let mut ids: Vec<(u32, &str)> = legacy.iter().map(|&i| (i, "legacy")).collect();
    ids.extend(shm.iter().map(|&i| (i, "shm")));
    ids.sort();
    for (id, kind) in ids {
        s += &format!(
            "\n[[agent]]\nid = {id}\ntransport = \"{kind}\"\n[[agent.camera]]\nname = \"left\"\n\
             width = 64\n[[agent.camera]]\nname = \"right\"\nwidth = 64\n"
        );
        if kind == "legacy" {
            s += "[[agent.camera]]\nname = \"main\"\nwidth = 48\n";
        }
    }
    s
}

const RUN_DEADLINE: Duration = Duration::from_secs(240);

// ----------------------------------------------------------------------------------------
// Tests
// ----------------------------------------------------------------------------------------

/// 200 cycles in one dialect: version check, images equal to the frames the host
/// rendered (dumped by `--dump-frames`, the bytes an shm agent reads), the grid position
/// equal to the recorded pose, statuses to a final state for every command, resets over
/// the environment socket, and no stop timeout.
fn two_hundred_cycles(dialect: Dialect) {
    let session = util::session("legacy-200");
    let run = start_host(
        &[0],
        |base| config(&session, base, &[0], &[], ""),
        &[
            "--frames",
            "200",
            "--record",
            "{dir}/record.jsonl",
            "--dump-frames",
            "{dir}/frames",
            "--every",
            "50",
            "--summary-json",
            "{dir}/summary.json",
        ],
    );
    let dir = run.dir.path().to_path_buf();
    let (frames_dir, record, summary) = (
        dir.join("frames"),
        dir.join("record.jsonl"),
        dir.join("summary.json"),
    );
    let host = run.host;
    let mut c = Client::start(run.base, 0, dialect, false);
    let mut kept = Vec::new();
    let mut grids = Vec::new();
    let mut statuses: Vec<(i32, i32)> = Vec::new();
    for n in 0..200u64 {
        let cycle = c.cycle().expect("the host closed before 200 cycles");
        assert_eq!(cycle.number, n, "cycles arrive once and in order");
        statuses.extend(&cycle.statuses);
        let images = cycle.images.expect("images every cycle, before StartSync");
        assert_eq!(images.main.is_some(), dialect == Dialect::Burkhardt);
        if n % 50 == 0 {
            kept.push((n, images));
        }
        grids.push(cycle.grid.expect("a grid position every cycle"));
        match n {
            10 => c.turn(100, 45.0),
            30 => c.movement(101, 90.0, 0.5),
            60 => c.send_env(&MsgVrnew {
                trial_reset: Some(ResetMsg {
                    reset_type: Some(0),
                }),
                ..Default::default()
            }),
            _ => {}
        }
        // vrnew: the unmodified clients' zero-length stop; burkhardt: alternately a real
        // StopSync.
        if dialect == Dialect::Burkhardt && n % 2 == 1 {
            c.stop_sync();
        } else {
            c.stop_zero_length();
        }
    }
    let out = host.wait(RUN_DEADLINE);
    assert_eq!(out.code(), Some(0), "stderr:\n{}", out.stderr);
    // Statuses that arrived after the last cycle.
    while let Some(m) = c.try_next() {
        if let Some(s) = m.status {
            statuses.push((s.action_id.unwrap(), s.status.unwrap()));
        }
    }
    let sum = util::summary(&summary);
    assert_eq!(sum["frames"], 200);
    assert_eq!(sum["stop_timeouts"], 0, "{sum}");

    // Every command acknowledged, then ended Finished or Aborted.
    for id in [100, 101] {
        let mine: Vec<i32> = statuses.iter().filter(|s| s.0 == id).map(|s| s.1).collect();
        assert!(!mine.is_empty(), "no status for action {id}");
        assert!(
            matches!(mine.last(), Some(&FINISHED) | Some(&ABORTED)),
            "action {id}: {mine:?}"
        );
    }
    assert_eq!(statuses.iter().find(|s| s.0 == 100).map(|s| s.1), Some(4)); // Rotating
    assert_eq!(statuses.iter().find(|s| s.0 == 101).map(|s| s.1), Some(3)); // Walking

    // Same pixels as the rendered frame.
    for (n, images) in &kept {
        let mut cams = vec![
            ("left", images.left.as_ref()),
            ("right", images.right.as_ref()),
        ];
        if dialect == Dialect::Burkhardt {
            cams.push(("main", images.main.as_ref()));
        }
        for (cam, png) in cams {
            let got = decode_png(png.expect("image present"));
            let dumped = std::fs::read(frames_dir.join(format!("c{n:06}_a0_{cam}.png"))).unwrap();
            let want = decode_png(&dumped);
            assert_eq!(got.2, png::ColorType::Rgb, "{cam}: 8-bit RGB");
            assert_eq!((got.0, got.1), (want.0, want.1), "cycle {n} {cam} size");
            assert!(got.3 == want.3, "cycle {n} {cam}: pixels differ");
        }
    }

    // The grid position of cycle n is the pose recorded at the end of cycle n - 1.
    let rec = util::record(&record);
    let mut commands = Vec::new();
    for line in &rec {
        let n = line["cycle"].as_u64().unwrap() as usize;
        commands.extend(
            line["commands"]
                .as_array()
                .unwrap()
                .iter()
                .map(|c| c[0].as_str().unwrap().to_string()),
        );
        let Some(g) = grids.get(n + 1) else { continue };
        let p = &line["position"];
        for (i, v) in [g.x, g.y, g.z].into_iter().enumerate() {
            let want = p[i].as_f64().unwrap() as f32;
            assert_eq!(v.unwrap(), want, "cycle {} grid axis {i}", n + 1);
        }
        let heading = line["heading_deg"].as_f64().unwrap() as f32;
        assert_eq!(g.ry.unwrap(), heading, "cycle {} heading", n + 1);
        assert_eq!((g.rx.unwrap(), g.rz.unwrap()), (0.0, 0.0));
    }
    for name in ["turn", "move", "trial_reset"] {
        assert!(
            commands.iter().any(|c| c == name),
            "{name} not applied: {commands:?}"
        );
    }
}

#[test]
fn a_vrnew_client_runs_200_cycles_with_zero_length_stops() {
    two_hundred_cycles(Dialect::Vrnew);
}

#[test]
fn a_burkhardt_client_runs_200_cycles_with_real_stop_syncs() {
    two_hundred_cycles(Dialect::Burkhardt);
}

/// A client whose send blocks until Finished/Aborted before it stops (as the original
/// clients' senders do): each cycle it waits through costs one stop timeout, and the send
/// completes.
#[test]
fn a_client_that_blocks_on_finished_before_stopping_completes() {
    let session = util::session("legacy-block");
    let run = start_host(
        &[0],
        |base| {
            config(&session, base, &[0], &[], "").replace("stop_timeout = 5", "stop_timeout = 0.3")
        },
        &["--frames", "40", "--summary-json", "{dir}/summary.json"],
    );
    let summary = run.dir.path().join("summary.json");
    let mut c = Client::start(run.base, 0, Dialect::Burkhardt, true);
    let first = c.cycle().unwrap();
    assert_eq!(first.number, 0);
    c.movement(7, 0.0, 0.5);
    // Block: no stop until the movement ends.
    let deadline = Instant::now() + Duration::from_secs(60);
    let mut cycles_waited = 0;
    let end = loop {
        assert!(Instant::now() < deadline, "the movement never ended");
        let m = c.next();
        if let Some(s) = m.status
            && s.action_id == Some(7)
            && matches!(s.status, Some(FINISHED) | Some(ABORTED))
        {
            break s.status.unwrap();
        }
        cycles_waited += usize::from(m.start_sync);
    };
    assert_eq!(end, FINISHED);
    assert!(cycles_waited >= 1, "a 0.5 m walk takes cycles");
    // The rest of the cycle that brought Finished, then the stop, and on with stops.
    while let Some(cycle) = c.cycle() {
        c.stop_zero_length();
        if cycle.number >= 39 {
            break;
        }
    }
    let out = run.host.wait(RUN_DEADLINE);
    assert_eq!(out.code(), Some(0), "stderr:\n{}", out.stderr);
    let sum = util::summary(&summary);
    assert_eq!(sum["frames"], 40);
    // Each cycle the client blocked through ended by the stop timeout.
    let timeouts = sum["stop_timeouts"].as_u64().unwrap();
    assert!(timeouts >= 1, "{sum}");
}

/// One legacy agent beside an shm agent, and beside a tcp agent, gives the trajectory of
/// the same world with both agents on shm (agent 0 idle on either transport, agent 1
/// `seek`, which decides from its images, where agent 0 is seen).
#[test]
fn legacy_and_shm_or_tcp_agents_in_one_world_give_the_all_shm_trajectory() {
    let frames = "120";
    // `other`: agent 1's transport; `legacy`: agent 0 is a legacy client (else vr-agent).
    let run_with = |legacy: bool, other: &str| -> serde_json::Value {
        let session = util::session(&format!("legacy-{legacy}-{other}"));
        let legacy_ids: &[u32] = if legacy { &[0] } else { &[] };
        let shm_ids: &[u32] = if legacy { &[1] } else { &[0, 1] };
        let run = start_host(
            &[0],
            |base| {
                config(&session, base, legacy_ids, shm_ids, "").replace(
                    "id = 1\ntransport = \"shm\"",
                    &format!("id = 1\ntransport = \"{other}\""),
                )
            },
            &["--frames", frames, "--summary-json", "{dir}/s.json"],
        );
        let summary = run.dir.path().join("s.json");
        let config_path = run.dir.path().join("legacy.toml");
        if other == "tcp" {
            // The host bound port 0: the agents connect to the port it reports.
            let listening = run.events.of("listening");
            let addr = listening[0]["address"].as_str().unwrap().to_string();
            let text = std::fs::read_to_string(&config_path).unwrap();
            let text = text.replace("127.0.0.1:0", &addr);
            std::fs::write(&config_path, text).unwrap();
        }
        let agent = |id: &str, policy: &str| {
            Proc::spawn(
                &util::bin("vr-agent"),
                &[
                    "--config",
                    config_path.to_str().unwrap(),
                    "--id",
                    id,
                    "--policy",
                    policy,
                ],
            )
        };
        let seek = agent("1", "seek");
        let idle = (!legacy).then(|| agent("0", "idle"));
        if legacy {
            let mut c = Client::start(run.base, 0, Dialect::Vrnew, false);
            while c.cycle().is_some() {
                c.stop_zero_length();
            }
        }
        let out = run.host.wait(RUN_DEADLINE);
        assert_eq!(out.code(), Some(0), "stderr:\n{}", out.stderr);
        drop((seek, idle));
        util::summary(&summary)
    };
    let all_shm = run_with(false, "shm");
    for other in ["shm", "tcp"] {
        let mixed = run_with(true, other);
        assert_eq!(mixed["frames"], 120, "legacy + {other}");
        assert_eq!(mixed["stop_timeouts"], 0, "legacy + {other}: {mixed}");
        assert_eq!(
            mixed["trajectory_hash"], all_shm["trajectory_hash"],
            "legacy + {other}"
        );
    }
}

/// Two legacy agents, two clients (each with its environment and agent connection): each
/// client resets its own trial once, at a different cycle, and each reset is applied to
/// its own agent's body (issue 22: agent 1's reset used to reset agent 0).
#[test]
fn two_legacy_clients_each_reset_their_own_agent() {
    let session = util::session("legacy-two-resets");
    let run = start_host(
        &[0, 1],
        |base| config(&session, base, &[0, 1], &[], ""),
        &[
            "--frames",
            "30",
            "--record",
            "{dir}/record.jsonl",
            "--summary-json",
            "{dir}/summary.json",
        ],
    );
    let (record, summary) = (
        run.dir.path().join("record.jsonl"),
        run.dir.path().join("summary.json"),
    );
    let mut a = Client::start(run.base, 0, Dialect::Vrnew, false);
    let mut b = Client::start(run.base, 1, Dialect::Burkhardt, false);
    let reset = |t| MsgVrnew {
        trial_reset: Some(ResetMsg {
            reset_type: Some(t),
        }),
        ..Default::default()
    };
    for n in 0..30u64 {
        let (ca, cb) = (a.cycle(), b.cycle());
        assert_eq!(ca.map(|c| c.number), Some(n));
        assert_eq!(cb.map(|c| c.number), Some(n));
        match n {
            5 => b.send_env(&reset(0)),
            15 => a.send_env(&reset(0)),
            _ => {}
        }
        a.stop_zero_length();
        b.stop_sync();
    }
    let out = run.host.wait(RUN_DEADLINE);
    assert_eq!(out.code(), Some(0), "stderr:\n{}", out.stderr);
    assert_eq!(util::summary(&summary)["stop_timeouts"], 0);
    // The cycles in which each agent's body applied a trial reset.
    let mut resets: [Vec<u64>; 2] = Default::default();
    for line in util::record(&record) {
        let agent = line["agent"].as_u64().unwrap() as usize;
        for c in line["commands"].as_array().unwrap() {
            if c[0] == "trial_reset" {
                resets[agent].push(line["cycle"].as_u64().unwrap());
            }
        }
    }
    assert_eq!(resets[1].len(), 1, "{resets:?}\n{}", out.stderr);
    assert_eq!(resets[0].len(), 1, "{resets:?}");
    assert!(
        (5..15).contains(&resets[1][0]),
        "agent 1's reset: {resets:?}"
    );
    assert!(
        (15..30).contains(&resets[0][0]),
        "agent 0's reset: {resets:?}"
    );
}

/// The README's legacy config block is a valid config (with the default port and the agent
/// on the legacy transport).
#[test]
fn the_readme_legacy_config_block_parses() {
    let block =
        crate::examples::readme_block("### Running agents written for the original system", "toml");
    let config = vrsync_bridge::Config::from_toml_str(&block, std::path::Path::new("README.md"))
        .unwrap_or_else(|e| panic!("{e}\n{block}"));
    assert_eq!(config.transport.legacy.local_port, 1337);
    assert_eq!(
        config.agents[0].transport,
        vrsync_bridge::TransportKind::Legacy
    );
}

/// Strangers on the legacy ports — garbage instead of a version check on an agent port, a
/// negative length on the environment socket — are refused (and reported as
/// `peer_refused`), and the agent's run goes on without a stop timeout.
#[test]
fn strangers_on_the_legacy_ports_leave_the_run_unaffected() {
    let session = util::session("legacy-hostile");
    let run = start_host(
        &[0],
        |base| config(&session, base, &[0], &[], ""),
        &["--frames", "50", "--summary-json", "{dir}/summary.json"],
    );
    let summary = run.dir.path().join("summary.json");
    let deadline = Instant::now() + Duration::from_secs(30);
    let mut stranger = connect(run.base + 1, deadline);
    Client::frame(&mut stranger, &[0xFF; 16]);
    let mut env_stranger = connect(run.base, deadline);
    env_stranger.write_all(&(-7i32).to_le_bytes()).unwrap();
    // The stranger is refused: the host closes its connection.
    let mut buf = [0u8; 64];
    assert!(matches!(stranger.read(&mut buf), Ok(0) | Err(_)));
    let mut c = Client::start(run.base, 0, Dialect::Vrnew, false);
    let mut cycles = 0;
    while let Some(cycle) = c.cycle() {
        assert_eq!(cycle.number, cycles);
        cycles += 1;
        c.stop_zero_length();
    }
    assert_eq!(cycles, 50);
    let out = run.host.wait(RUN_DEADLINE);
    assert_eq!(out.code(), Some(0), "stderr:\n{}", out.stderr);
    let sum = util::summary(&summary);
    assert_eq!(sum["stop_timeouts"], 0, "{sum}");
    assert!(sum["peers_refused"].as_u64().unwrap() >= 1, "{sum}");
}

/// A legacy agent that never connects: vr-sim names it and the port its program connects
/// to (exit 1).
#[test]
fn a_missing_legacy_agent_is_named_with_its_port() {
    let session = util::session("legacy-missing");
    let run = start_host(
        &[0],
        |base| {
            config(&session, base, &[0], &[], "")
                .replace("connect_timeout = 60", "connect_timeout = 1")
        },
        &["--frames", "5"],
    );
    let port = run.base.to_string();
    let out = run.host.wait(RUN_DEADLINE);
    assert_eq!(out.code(), Some(1), "stderr:\n{}", out.stderr);
    assert!(
        out.stderr.contains("original system's protocol") && out.stderr.contains(&port),
        "stderr:\n{}",
        out.stderr
    );
}
