//! `vr-sim replay`: records of runs with real agent processes (wander, a leave and a
//! rejoin, rejected commands, async mode) replay to the same trajectory hash without the
//! agents, re-render with other cameras, and an edited, cut or foreign record is refused
//! with the right exit code.

use std::path::{Path, PathBuf};
use std::time::Duration;

use serde_json::Value;

use crate::util::{
    self, EVENT_DEADLINE, HostRun, Output, RUN_DEADLINE, TestConfig, record, record_lines, summary,
    wait_for_cycle_line,
};

/// `vr-sim replay ARGS...`, checked to end within the deadline.
fn replay(args: &[&str]) -> Output {
    let mut all = vec!["replay"];
    all.extend_from_slice(args);
    util::run("vr-sim", &all, RUN_DEADLINE)
}

/// `vr-sim run` of `cfg` with 2 spawned `wander` agents for `frames` cycles, recording to
/// `dir/record.jsonl` and dumping frames every 40 cycles to `dir/frames`; returns the
/// record's path and the run's trajectory hash.
fn recorded_run(
    dir: &Path,
    cfg: &TestConfig,
    frames: u32,
    agent_args: &[&str],
) -> (PathBuf, String) {
    let config = cfg.write(dir);
    let rec = dir.join("record.jsonl");
    let sum = dir.join("summary.json");
    let frames_dir = dir.join("frames");
    let frames = frames.to_string();
    let mut args = vec![
        "run",
        "--config",
        config.to_str().unwrap(),
        "--frames",
        &frames,
        "--spawn-agents",
        "2",
        "--agent-arg=--policy",
        "--agent-arg=wander",
        "--record",
        rec.to_str().unwrap(),
        "--summary-json",
        sum.to_str().unwrap(),
        "--dump-frames",
        frames_dir.to_str().unwrap(),
        "--every",
        "40",
        "--quiet",
    ];
    args.extend_from_slice(agent_args);
    let out = util::run("vr-sim", &args, RUN_DEADLINE);
    assert_eq!(out.code(), Some(0), "stderr:\n{}", out.stderr);
    let hash = summary(&sum)["trajectory_hash"]
        .as_str()
        .unwrap()
        .to_string();
    (rec, hash)
}

/// The PNG files of `dir`, sorted by name.
fn pngs(dir: &Path) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "png"))
        .collect();
    files.sort();
    files
}

/// Width and height of a PNG file.
fn png_size(path: &Path) -> (u32, u32) {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let info = decoder.read_info().unwrap();
    (info.info().width, info.info().height)
}

/// Writes `lines` (JSON values) as a record file.
fn write_record(path: &Path, lines: &[Value]) {
    let text: String = lines.iter().map(|l| format!("{l}\n")).collect();
    std::fs::write(path, text).unwrap();
}

#[test]
fn a_recorded_run_replays_to_its_hash_and_rerenders_with_other_cameras() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = TestConfig::new("replay", 2);
    let (rec, hash) = recorded_run(dir.path(), &cfg, 200, &[]);

    // The record: a header with the config, one line per agent per cycle with the commands'
    // arguments, an end line with the run's hash.
    let lines = record_lines(&rec);
    assert_eq!(lines.len(), 1 + 400 + 1);
    assert_eq!(lines[0]["record"], "header");
    assert_eq!(lines[0]["version"], 2);
    assert_eq!(lines[0]["agents"], serde_json::json!([0, 1]));
    assert!(lines[0]["config"].as_str().unwrap().contains("[[agent]]"));
    assert_eq!(lines[401]["record"], "end");
    assert_eq!(lines[401]["cycles"], 200);
    assert_eq!(lines[401]["trajectory_hash"], hash.as_str());
    let agent_lines = record(&rec);
    let moves = agent_lines
        .iter()
        .flat_map(|l| l["sent"].as_array().unwrap())
        .filter(|s| s["kind"] == "move" && s["distance"].as_f64().is_some())
        .count();
    assert!(moves > 5, "wander moved: {moves} moves");

    // Same cameras: the same hash, and the run's own frames, byte for byte.
    let again = dir.path().join("again");
    let out = replay(&[
        rec.to_str().unwrap(),
        "--dump-frames",
        again.to_str().unwrap(),
        "--every",
        "40",
    ]);
    assert_eq!(out.code(), Some(0), "stderr:\n{}", out.stderr);
    assert!(out.stdout.contains(&hash), "{}", out.stdout);
    let run_frames = pngs(&dir.path().join("frames"));
    assert_eq!(run_frames.len(), 5 * 2 * 2, "{run_frames:?}");
    for f in &run_frames {
        let name = f.file_name().unwrap();
        assert!(
            std::fs::read(f).unwrap() == std::fs::read(again.join(name)).unwrap(),
            "{name:?} differs from the run's"
        );
    }

    // 320x240 cameras: every cycle's poses and the hash as recorded (else exit 1), the
    // same images, larger.
    let big = dir.path().join("big");
    let out = replay(&[
        rec.to_str().unwrap(),
        "--camera-size",
        "320x240",
        "--dump-frames",
        big.to_str().unwrap(),
        "--every",
        "40",
    ]);
    assert_eq!(out.code(), Some(0), "stderr:\n{}", out.stderr);
    assert!(out.stdout.contains(&hash), "{}", out.stdout);
    let big_frames = pngs(&big);
    assert_eq!(
        big_frames.iter().map(|f| f.file_name()).collect::<Vec<_>>(),
        run_frames.iter().map(|f| f.file_name()).collect::<Vec<_>>()
    );
    for f in &big_frames {
        assert_eq!(png_size(f), (320, 240), "{}", f.display());
    }

    // Cameras from another config (agent 1 only): agent 0 keeps the recorded 64-wide ones.
    let mut wide = TestConfig::new("replay-wide", 2);
    wide.width = 200;
    let wide_path = dir.path().join("wide.toml");
    let text = wide
        .toml()
        .replace("[[agent]]\nid = 0\n", "[[agent]]\nid = 7\n");
    std::fs::write(&wide_path, text).unwrap();
    let wide_dir = dir.path().join("wide");
    let map = dir.path().join("map.png");
    let out = replay(&[
        rec.to_str().unwrap(),
        "--config",
        wide_path.to_str().unwrap(),
        "--dump-frames",
        wide_dir.to_str().unwrap(),
        "--every",
        "100",
        "--map",
        map.to_str().unwrap(),
    ]);
    assert_eq!(out.code(), Some(0), "stderr:\n{}", out.stderr);
    assert_eq!(png_size(&wide_dir.join("c000100_a1_left.png")).0, 200);
    assert_eq!(png_size(&wide_dir.join("c000100_a0_left.png")).0, 64);
    assert!(png_size(&map).0 > 0);
}

#[test]
fn an_edited_command_is_named_at_its_cycle_and_agent() {
    let dir = tempfile::tempdir().unwrap();
    let (rec, _) = recorded_run(dir.path(), &TestConfig::new("replay-edit", 2), 120, &[]);
    let mut lines = record_lines(&rec);
    // The first move of cycle 10 or later, turned by 90°: the body faces and walks
    // elsewhere from that cycle on.
    let (i, cycle, agent) = lines
        .iter()
        .enumerate()
        .find_map(|(i, l)| {
            let moves = l["sent"].as_array()?.iter().any(|s| s["kind"] == "move");
            (moves && l["cycle"].as_u64()? >= 10).then(|| {
                (
                    i,
                    l["cycle"].as_u64().unwrap(),
                    l["agent"].as_u64().unwrap(),
                )
            })
        })
        .expect("a move at cycle 10 or later");
    for s in lines[i]["sent"].as_array_mut().unwrap() {
        if s["kind"] == "move" {
            let h = s["heading_deg"].as_f64().unwrap();
            s["heading_deg"] = serde_json::json!((h + 90.0) % 360.0);
        }
    }
    let edited = dir.path().join("edited.jsonl");
    write_record(&edited, &lines);
    let out = replay(&[edited.to_str().unwrap()]);
    assert_eq!(
        out.code(),
        Some(1),
        "stdout:\n{}\nstderr:\n{}",
        out.stdout,
        out.stderr
    );
    let want = format!("at cycle {cycle}, agent {agent}:");
    assert!(
        out.stderr.contains(&want),
        "want {want:?} in:\n{}",
        out.stderr
    );

    // A command the run applied made invalid: named as rejected in the replay.
    let mut lines = record_lines(&rec);
    for s in lines[i]["sent"].as_array_mut().unwrap() {
        if s["kind"] == "move" {
            s["distance"] = serde_json::json!(1.0e6);
        }
    }
    write_record(&edited, &lines);
    let out = replay(&[edited.to_str().unwrap()]);
    assert_eq!(out.code(), Some(1), "stderr:\n{}", out.stderr);
    assert!(
        out.stderr.contains(&want),
        "want {want:?} in:\n{}",
        out.stderr
    );
    assert!(
        out.stderr
            .contains("was applied in the run and is rejected in the replay"),
        "{}",
        out.stderr
    );

    // Every line as recorded, another hash at the end (e.g. an object moved otherwise).
    let mut lines = record_lines(&rec);
    let last = lines.len() - 1;
    lines[last]["trajectory_hash"] = "0".repeat(64).into();
    write_record(&edited, &lines);
    let out = replay(&[edited.to_str().unwrap()]);
    assert_eq!(out.code(), Some(1), "stderr:\n{}", out.stderr);
    assert!(
        out.stderr
            .contains("matches every agent line but not the trajectory hash"),
        "{}",
        out.stderr
    );
}

#[test]
fn a_cut_malformed_or_old_record_is_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    let (rec, _) = recorded_run(dir.path(), &TestConfig::new("replay-bad", 2), 30, &[]);
    let text = std::fs::read_to_string(&rec).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let bad = dir.path().join("bad.jsonl");
    let check = |content: String, want: &str| {
        std::fs::write(&bad, content).unwrap();
        let out = replay(&[bad.to_str().unwrap()]);
        assert_eq!(out.code(), Some(2), "{want}: stderr:\n{}", out.stderr);
        assert!(
            out.stderr.contains(want),
            "want {want:?} in:\n{}",
            out.stderr
        );
    };
    // Killed run: no end line.
    check(
        lines[..lines.len() - 1].join("\n") + "\n",
        "truncated: no end line after 30 cycles",
    );
    // Cut in the middle of a line.
    let cut = text[..text.len() / 2].rfind('\n').unwrap() + 10;
    check(text[..cut].to_string(), "is cut off");
    // A line that is not JSON.
    let mut garbled: Vec<&str> = lines.clone();
    garbled[5] = "{not json";
    check(
        garbled.join("\n") + "\n",
        "bad.jsonl:6: not a vr-sim record line",
    );
    // A cycle missing an agent's line.
    let mut missing: Vec<&str> = lines.clone();
    missing.remove(4);
    check(missing.join("\n") + "\n", "every cycle has one per agent");
    // A record of vr-sim before format version 2: agent lines only.
    check(
        lines[1..lines.len() - 1].join("\n") + "\n",
        "a record of format version 1",
    );
    // Something after the end line.
    check(
        text.clone() + "{}\n",
        &format!("bad.jsonl:{}: ", lines.len() + 1),
    );
    // Not a record at all.
    check("[1, 2, 3]\n".into(), "the first line is not a header");
    let out = replay(&[dir.path().join("none.jsonl").to_str().unwrap()]);
    assert_eq!(out.code(), Some(2), "stderr:\n{}", out.stderr);
    assert!(
        out.stderr.contains("cannot read the record"),
        "{}",
        out.stderr
    );
}

/// Agent 1 leaves after 15 cycles and comes back while agent 0, which also sends four
/// invalid commands every cycle, goes on; the run ends by SIGTERM. The replay applies the
/// sensor hand-overs only where the run wrote a frame, and the same rejections.
#[test]
fn a_leave_a_rejoin_and_rejected_commands_replay() {
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("record.jsonl");
    let mut cfg = TestConfig::new("replay-rejoin", 2);
    cfg.stop_timeout_s = 30.0;
    let run = HostRun::start_in(dir, cfg, &["--record", rec.to_str().unwrap()]);
    let events = &run.events;
    let (a0, _) = run.agent(0, "a0.log", &["--policy", "wander", "--bad-commands"]);
    let (first, _) = run.agent(1, "a1.log", &["--policy", "wander", "--frames", "15"]);
    assert_eq!(first.wait(EVENT_DEADLINE).code(), Some(0));
    events.wait_for_match("agent_left", |e| e["agent"] == 1, EVENT_DEADLINE);
    let (back, log_back) = run.agent(1, "back.log", &["--policy", "wander"]);
    let rejoined = events.wait_for_match("agent_rejoined", |e| e["agent"] == 1, EVENT_DEADLINE);
    let rejoined_at = rejoined["cycle"].as_u64().unwrap();
    wait_for_cycle_line(&log_back, rejoined_at + 30, EVENT_DEADLINE);
    run.host.signal(libc::SIGTERM);
    let out = run.host.wait(RUN_DEADLINE);
    assert_eq!(out.code(), Some(0), "stderr:\n{}", out.stderr);
    assert_eq!(a0.wait(Duration::from_secs(10)).code(), Some(0));
    assert_eq!(back.wait(Duration::from_secs(10)).code(), Some(0));
    let sum = summary(&run.summary);
    assert!(sum["commands_rejected"].as_u64().unwrap() > 0, "{sum}");

    let lines = record(&rec);
    let agent1: Vec<&Value> = lines.iter().filter(|l| l["agent"] == 1).collect();
    let away = agent1.iter().filter(|l| l["sensed"] == false).count();
    assert!(away > 0, "agent 1 was away for some cycles");
    assert_eq!(agent1.last().unwrap()["sensed"], true);
    let undecoded = lines
        .iter()
        .flat_map(|l| l["sent"].as_array().unwrap().iter())
        .filter(|s| s["kind"] == "undecoded")
        .count();
    assert!(undecoded > 0, "--bad-commands sends an unknown kind");
    let end = record_lines(&rec).pop().unwrap();
    assert_eq!(end["interrupted"], true, "{end}");
    assert_eq!(end["trajectory_hash"], sum["trajectory_hash"]);

    let out = replay(&[rec.to_str().unwrap()]);
    assert_eq!(out.code(), Some(0), "stderr:\n{}", out.stderr);
    assert!(
        out.stdout
            .contains(sum["trajectory_hash"].as_str().unwrap()),
        "{}",
        out.stdout
    );
}

/// Async mode: commands applied as they arrived, cycle by cycle, replay the same.
#[test]
fn an_async_run_replays() {
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = TestConfig::new("replay-async", 2);
    cfg.sync_mode = false;
    cfg.dt_s = 0.01;
    let (rec, hash) = recorded_run(dir.path(), &cfg, 150, &[]);
    let lines = record(&rec);
    assert!(lines.iter().all(|l| l["outcome"] == "async"));
    let out = replay(&[rec.to_str().unwrap()]);
    assert_eq!(out.code(), Some(0), "stderr:\n{}", out.stderr);
    assert!(out.stdout.contains(&hash), "{}", out.stdout);
}
