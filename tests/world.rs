//! vr-sim's world with real processes: determinism whatever the agents' timing and start
//! order, recordings, the map and frame pictures, the demo's folder, `seek` finding the
//! red object, and `[world]` config errors.

use std::path::{Path, PathBuf};
use std::time::Duration;

use serde_json::Value;

use crate::util::{
    self, EVENT_DEADLINE, Events, Proc, RUN_DEADLINE, bin, record, spawn_host, summary, workspace,
};

fn default_config() -> PathBuf {
    workspace().join("config/default.toml")
}

/// Checks that `path` is a PNG and returns its width and height.
fn png_size(path: &Path) -> (u32, u32) {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert_eq!(
        &bytes[..8],
        b"\x89PNG\r\n\x1a\n",
        "{} is not a PNG",
        path.display()
    );
    let be = |i: usize| u32::from_be_bytes([bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]]);
    (be(16), be(20))
}

/// `vr-sim run` of the default world with 2 spawned wander agents for 300 cycles.
fn spawned_run(dir: &Path, tag: &str, jitter_ms: u32, extra: &[&str]) -> Value {
    let s = dir.join(format!("{tag}.json"));
    let jitter = format!("--agent-arg={jitter_ms}");
    let session = util::session(tag);
    let config = default_config();
    let mut args = vec![
        "run",
        "--config",
        config.to_str().unwrap(),
        "--session",
        &session,
        "--frames",
        "300",
        "--spawn-agents",
        "2",
        "--agent-arg=--jitter-ms",
        &jitter,
        "--summary-json",
        s.to_str().unwrap(),
        "--quiet",
    ];
    args.extend_from_slice(extra);
    let out = util::run("vr-sim", &args, RUN_DEADLINE);
    assert_eq!(out.code(), Some(0), "{tag}: stderr:\n{}", out.stderr);
    summary(&s)
}

#[test]
fn trajectory_hash_does_not_depend_on_agent_timing_or_start_order() {
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("record.jsonl");
    let map = dir.path().join("map.png");
    let frames = dir.path().join("frames");
    let first = spawned_run(
        dir.path(),
        "det-a",
        0,
        &[
            "--record",
            rec.to_str().unwrap(),
            "--map",
            map.to_str().unwrap(),
            "--dump-frames",
            frames.to_str().unwrap(),
            "--every",
            "100",
        ],
    );
    let second = spawned_run(dir.path(), "det-b", 0, &[]);
    let jittered = spawned_run(dir.path(), "det-c", 20, &[]);

    // The agents started by hand, in the opposite order: 1 connects before 0 starts.
    let session = util::session("det-d");
    let text = std::fs::read_to_string(default_config())
        .unwrap()
        .replace("session = \"default\"", &format!("session = {session:?}"));
    let config_path = dir.path().join("reverse.toml");
    std::fs::write(&config_path, text).unwrap();
    let config = config_path.to_str().unwrap();
    let s = dir.path().join("reverse.json");
    let events = Events::in_dir(dir.path());
    let host = spawn_host(
        &config_path,
        &events,
        &["--frames", "300", "--summary-json", s.to_str().unwrap()],
    );
    events.wait_for("waiting_for_agents", EVENT_DEADLINE);
    let one = Proc::spawn(&bin("vr-agent"), &["--config", config, "--id", "1"]);
    events.wait_for_match("agent_connected", |e| e["agent"] == 1, EVENT_DEADLINE);
    let zero = Proc::spawn(&bin("vr-agent"), &["--config", config, "--id", "0"]);
    let out = host.wait(RUN_DEADLINE);
    assert_eq!(out.code(), Some(0), "stderr:\n{}", out.stderr);
    for agent in [zero, one] {
        let out = agent.wait(Duration::from_secs(30));
        assert_eq!(out.code(), Some(0), "agent stderr:\n{}", out.stderr);
    }
    let reversed = summary(&s);

    for (name, sum) in [
        ("second", &second),
        ("jittered", &jittered),
        ("reversed", &reversed),
    ] {
        assert_eq!(sum["frames"], 300, "{name}");
        assert_eq!(sum["stop_timeouts"], 0, "{name}");
        assert_eq!(
            sum["trajectory_hash"], first["trajectory_hash"],
            "{name} run differs from the first"
        );
    }
    assert!(
        first["commands_applied"].as_u64().unwrap() > 10,
        "the agents moved"
    );
    assert!(first["render_us"].as_f64().unwrap() > 0.0);

    // The recording: one line per agent per cycle, with pose, statuses and reward.
    let lines = record(&rec);
    assert_eq!(lines.len(), 600);
    for (i, l) in lines.iter().enumerate() {
        assert_eq!(l["cycle"], (i / 2) as u64);
        assert_eq!(l["agent"], (i % 2) as u64);
        for key in [
            "sim_time_s",
            "position",
            "rotation",
            "commands",
            "statuses",
            "collisions",
            "reward",
        ] {
            assert!(!l[key].is_null(), "line {i} lacks {key}: {l}");
        }
    }
    let moved = |agent: usize| {
        let p0 = &lines[agent]["position"];
        let p1 = &lines[598 + agent]["position"];
        p0 != p1
    };
    assert!(moved(0) && moved(1), "wander agents walk");
    // Wander turns away after a collision: the next cycle carries a new move.
    let mut collisions = 0;
    for (i, l) in lines.iter().enumerate().take(596) {
        if !l["collisions"].as_array().unwrap().is_empty() {
            collisions += 1;
            let next = &lines[i + 2]["commands"];
            assert_eq!(next[0][0], "move", "after the collision {l}: {next}");
        }
    }
    assert!(
        collisions > 0,
        "300 cycles of wandering bump into something"
    );

    // The pictures.
    let (w, h) = png_size(&map);
    assert!(w >= 200 && h >= 200, "map is {w}x{h}");
    let mut names: Vec<String> = std::fs::read_dir(&frames)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(
        names.len(),
        3 * 2 * 2,
        "cycles 0, 100, 200 x 2 agents x 2 cameras: {names:?}"
    );
    assert_eq!(names[0], "c000000_a0_left.png");
    assert_eq!(png_size(&frames.join(&names[0])), (256, 148));
}

#[test]
fn seek_walks_to_the_red_object_and_stops_there() {
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("seek.jsonl");
    let session = util::session("seek");
    let out = util::run(
        "vr-sim",
        &[
            "run",
            "--config",
            default_config().to_str().unwrap(),
            "--session",
            &session,
            "--frames",
            "80",
            "--spawn-agents",
            "1",
            "--agent-arg=--policy",
            "--agent-arg=seek",
            "--record",
            rec.to_str().unwrap(),
            "--quiet",
        ],
        RUN_DEADLINE,
    );
    assert_eq!(out.code(), Some(0), "stderr:\n{}", out.stderr);
    // The red sphere of config/default.toml (object 1) stands at x 2.5, z 3.0, radius 0.4;
    // agent 0 starts 6.4 m away at (-2, -2).
    let distance = |l: &Value| {
        let p = &l["position"];
        let (x, z) = (p[0].as_f64().unwrap(), p[2].as_f64().unwrap());
        (x - 2.5).hypot(z - 3.0)
    };
    let lines = record(&rec);
    assert_eq!(lines.len(), 80);
    assert!(distance(&lines[0]) > 6.0);
    let arrived = lines
        .iter()
        .position(|l| distance(l) < 1.4)
        .unwrap_or_else(|| {
            panic!(
                "never came within 1.4 m; last at {:.2} m",
                distance(&lines[79])
            )
        });
    for l in &lines[arrived..] {
        assert!(distance(l) < 1.4, "left the object again: {l}");
    }
    // It used its eyes: the first command tilts them.
    assert_eq!(lines[0]["commands"][0][0], "eye_movement");
}

#[test]
fn demo_writes_map_frames_record_and_summary_into_its_folder() {
    let dir = tempfile::tempdir().unwrap();
    let out_dir = dir.path().join("demo");
    let out = util::run(
        "vr-sim",
        &["demo", "--frames", "40", "--out", out_dir.to_str().unwrap()],
        RUN_DEADLINE,
    );
    assert_eq!(out.code(), Some(0), "stderr:\n{}", out.stderr);
    assert!(
        out.stdout.contains("trajectory hash"),
        "summary table:\n{}",
        out.stdout
    );
    png_size(&out_dir.join("map.png"));
    let frames = std::fs::read_dir(out_dir.join("frames")).unwrap().count();
    assert_eq!(frames, 4 * 2 * 2, "4 moments x 2 agents x 2 eyes");
    assert_eq!(record(&out_dir.join("record.jsonl")).len(), 80);
    assert_eq!(summary(&out_dir.join("summary.json"))["frames"], 40);
}

#[test]
fn a_bad_world_section_is_a_config_error_naming_the_key() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(default_config())
        .unwrap()
        .replace("color = [40, 170, 70]", "colour = [40, 170, 70]");
    let config = dir.path().join("bad.toml");
    std::fs::write(&config, &text).unwrap();
    let out = util::run(
        "vr-sim",
        &["run", "--config", config.to_str().unwrap(), "--frames", "1"],
        Duration::from_secs(30),
    );
    assert_eq!(out.code(), Some(2), "stderr:\n{}", out.stderr);
    assert!(
        out.stderr.contains("world.object[2]") && out.stderr.contains("colour"),
        "stderr:\n{}",
        out.stderr
    );
    // With the line of the unknown key.
    let line = text
        .lines()
        .position(|l| l.starts_with("colour = "))
        .unwrap()
        + 1;
    let at = format!("bad.toml:{line}: invalid");
    assert!(out.stderr.contains(&at), "{at} in:\n{}", out.stderr);
}

/// The same world over shm, over tcp, and mixed (agent 0 on shm, agent 1 on tcp, one
/// host serving both): the same trajectory.
#[test]
fn the_same_world_over_tcp_or_mixed_transports_gives_the_same_trajectory() {
    let dir = tempfile::tempdir().unwrap();
    let run = |kind: &str| {
        let session = util::session(&format!("world-{kind}"));
        let mut text = std::fs::read_to_string(default_config())
            .unwrap()
            .replace("session = \"default\"", &format!("session = {session:?}"))
            .replace(
                "tcp_listen = \"127.0.0.1:7400\"",
                "tcp_listen = \"127.0.0.1:0\"",
            );
        if kind == "mixed" {
            text = text.replacen("\nid = 1\n", "\nid = 1\ntransport = \"tcp\"\n", 1);
            assert!(text.contains("transport = \"tcp\""));
        } else {
            text = text.replace("kind = \"shm\"", &format!("kind = {kind:?}"));
        }
        let config = dir.path().join(format!("{kind}.toml"));
        std::fs::write(&config, text).unwrap();
        let s = dir.path().join(format!("{kind}.json"));
        let out = util::run(
            "vr-sim",
            &[
                "run",
                "--config",
                config.to_str().unwrap(),
                "--frames",
                "150",
                "--spawn-agents",
                "2",
                "--agent-arg=--policy",
                "--agent-arg=seek",
                "--summary-json",
                s.to_str().unwrap(),
                "--quiet",
            ],
            RUN_DEADLINE,
        );
        assert_eq!(out.code(), Some(0), "{kind}: stderr:\n{}", out.stderr);
        summary(&s)
    };
    let shm = run("shm");
    let tcp = run("tcp");
    let mixed = run("mixed");
    assert_eq!(tcp["transport"], "tcp");
    // seek decides from the images: equal trajectories mean equal pixels arrived.
    assert_eq!(shm["trajectory_hash"], tcp["trajectory_hash"]);
    assert_eq!(shm["trajectory_hash"], mixed["trajectory_hash"]);
    assert_eq!(mixed["frames"], 150);
    assert_eq!(mixed["stop_timeouts"], 0);
}

/// Agents on zenoh beside agents on shared memory (agent 0 on shm, agents 1 and 2 on
/// zenoh over loopback, one host serving all): the all-shm trajectory.
#[test]
fn shm_and_zenoh_agents_in_one_run_give_the_all_shm_trajectory() {
    let dir = tempfile::tempdir().unwrap();
    let run = |kind: &str| {
        let session = util::session(&format!("world-z{kind}"));
        let endpoint = format!("tcp/127.0.0.1:{}", util::free_tcp_port());
        let mut text = std::fs::read_to_string(default_config())
            .unwrap()
            .replace("session = \"default\"", &format!("session = {session:?}"))
            .replace("tcp/127.0.0.1:7447", &endpoint);
        if kind == "mixed" {
            // Agent 0 on shm; agents 1 and 2 (added by --spawn-agents 3) take the
            // default kind: zenoh.
            text = text
                .replacen("\nid = 0\n", "\nid = 0\ntransport = \"shm\"\n", 1)
                .replace("kind = \"shm\"", "kind = \"zenoh\"");
            assert!(text.contains("kind = \"zenoh\""));
        }
        let config = dir.path().join(format!("z{kind}.toml"));
        std::fs::write(&config, text).unwrap();
        let s = dir.path().join(format!("z{kind}.json"));
        let out = util::run(
            "vr-sim",
            &[
                "run",
                "--config",
                config.to_str().unwrap(),
                "--frames",
                "150",
                "--spawn-agents",
                "3",
                "--agent-arg=--policy",
                "--agent-arg=seek",
                "--summary-json",
                s.to_str().unwrap(),
                "--quiet",
            ],
            RUN_DEADLINE,
        );
        assert_eq!(out.code(), Some(0), "{kind}: stderr:\n{}", out.stderr);
        summary(&s)
    };
    let shm = run("shm");
    let mixed = run("mixed");
    // seek decides from the images: equal trajectories mean equal pixels arrived.
    assert_eq!(shm["trajectory_hash"], mixed["trajectory_hash"]);
    assert_eq!(mixed["frames"], 150);
    assert_eq!(mixed["stop_timeouts"], 0);
    assert_eq!(mixed["agents"], 3);
}
