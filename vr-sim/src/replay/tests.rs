//! Replays of records made here, without a host: the world is driven the way `run`
//! drives it, and the record is written with the same line types.

use std::path::Path;

use vrsync_bridge::{Command, Config, SensorHeader};

use super::*;
use crate::record::{AgentLine, End, Header, RecordedCommand, Sent};

const CONFIG: &str = "session = \"replay-unit\"\n\
[[agent]]\nid = 0\n[[agent.camera]]\nname = \"left\"\nwidth = 64\nheight = 48\n\
fov_horizontal_deg = 90.0\nfov_vertical_deg = 73.74\n\
[[agent]]\nid = 1\n[[agent.camera]]\nname = \"left\"\nwidth = 64\nheight = 48\n\
fov_horizontal_deg = 90.0\nfov_vertical_deg = 73.74\n\
[world]\n\
[[world.object]]\nid = 1\nshape = \"sphere\"\nposition = [0.0, 0.4, 3.0]\nradius = 0.4\n\
color = [220, 30, 30]\ngraspable = true\n\
[[world.agent]]\nid = 0\nposition = [0.0, 1.8]\nheading_deg = 0.0\n\
[[world.agent]]\nid = 1\nposition = [-3.0, -3.0]\nheading_deg = 90.0\n";

/// One agent's part of a cycle: sensed, and its commands.
type Part = (bool, Vec<(u32, Command)>);

/// The record of a run of [`CONFIG`] with these cycles (agents 0 and 1 each), made as
/// `run` makes it.
fn record_of(cycles: &[[Part; 2]]) -> String {
    let config = Config::from_toml_str(CONFIG, Path::new("unit.toml")).unwrap();
    let mut world = World::from_config(&config).unwrap();
    let line = |v: &dyn erased::Json| v.json() + "\n";
    let mut out = line(&Header::of(&config));
    let mut hasher = blake3::Hasher::new();
    let (mut applied, mut rejected_total) = (0, 0);
    for (cycle, parts) in cycles.iter().enumerate() {
        let cycle = cycle as u64;
        for (id, (sensed, _)) in parts.iter().enumerate() {
            if *sensed {
                world.write_sensors(id as u32, &mut SensorHeader::default());
            }
        }
        let mut per_agent = Vec::new();
        for (id, (_, commands)) in parts.iter().enumerate() {
            let (mut names, mut sent, mut rejected) = (Vec::new(), Vec::new(), 0);
            for &(action, cmd) in commands {
                let result = world.apply(id as u32, action, cmd);
                if result.is_ok() {
                    names.push((cmd.name(), action));
                    applied += 1;
                } else {
                    rejected += 1;
                    rejected_total += 1;
                }
                sent.push(Sent {
                    action,
                    command: RecordedCommand::from(cmd),
                    error: result.err().map(|e| e.to_string()),
                });
            }
            per_agent.push((names, sent, rejected));
        }
        world.step();
        hasher.update(&cycle.to_le_bytes());
        world.hash_into(&mut hasher);
        for (id, (names, sent, rejected)) in per_agent.into_iter().enumerate() {
            let body = &world.bodies()[id];
            let l = AgentLine::of(
                body,
                cycle,
                (cycle + 1) as f64 * 0.1,
                "stopped",
                parts[id].0,
                names,
                rejected,
                &sent,
            );
            out += &line(&l);
        }
    }
    out + &line(&End {
        record: "end".into(),
        cycles: cycles.len() as u64,
        trajectory_hash: hasher.finalize().to_hex().to_string(),
        interrupted: false,
        commands_applied: applied,
        commands_rejected: rejected_total,
    })
}

/// Serialising any line type through one closure.
mod erased {
    pub trait Json {
        fn json(&self) -> String;
    }
    impl<T: serde::Serialize> Json for T {
        fn json(&self) -> String {
            serde_json::to_string(self).unwrap()
        }
    }
}

fn options(record: &Path) -> ReplayOptions {
    ReplayOptions {
        record: record.to_path_buf(),
        config: None,
        camera_size: None,
        dump_frames: None,
        map: None,
        render_threads: 1,
        render_affinity: crate::render::Affinity::Auto,
    }
}

fn write(dir: &Path, text: &str) -> PathBuf {
    let path = dir.join("record.jsonl");
    std::fs::write(&path, text).unwrap();
    path
}

/// Agent 0 looks down at the sphere, grasps it by image position (centre of its 64×48
/// left image) and points at a pixel outside that image (rejected); agent 1 turns.
fn pixel_run() -> Vec<[Part; 2]> {
    let tilt = Command::EyeMovement {
        pan_left_deg: 0.0,
        pan_right_deg: 0.0,
        tilt_deg: -45.0,
    };
    let turn = Command::Turn { angle_deg: 30.0 };
    let mut cycles = vec![
        [(true, vec![(1, tilt)]), (true, vec![(1, turn)])],
        [(true, vec![]), (true, vec![])],
        [(true, vec![]), (true, vec![])],
        [
            (
                true,
                vec![
                    (
                        2,
                        Command::GraspPos {
                            x_px: 32.0,
                            y_px: 24.0,
                        },
                    ),
                    (
                        3,
                        Command::PointPos {
                            x_px: 100.0,
                            y_px: 10.0,
                        },
                    ),
                ],
            ),
            (true, vec![]),
        ],
    ];
    for _ in 0..4 {
        cycles.push([(true, vec![]), (true, vec![])]);
    }
    cycles
}

#[test]
fn image_position_commands_replay_whatever_the_cameras_render() {
    let dir = tempfile::tempdir().unwrap();
    let text = record_of(&pixel_run());
    // The grasp by pixel worked in the "run", the point outside 64x48 was rejected.
    let grasped: serde_json::Value = serde_json::from_str(text.lines().nth(7).unwrap()).unwrap();
    assert_eq!(grasped["cycle"], 3);
    assert_eq!(grasped["held"], 1, "{grasped}");
    assert_eq!(grasped["rejected"], 1, "{grasped}");
    let record = write(dir.path(), &text);
    let same = replay(&options(&record)).unwrap();
    assert_eq!((same.cycles, same.agents), (8, 2));
    assert_eq!((same.commands_applied, same.commands_rejected), (3, 1));
    // 640x480 renders: pixel (100, 10) would be inside, (32, 24) elsewhere; the world
    // still resolves them with the recorded 64x48 camera.
    let frames = dir.path().join("frames");
    let big = replay(&ReplayOptions {
        camera_size: Some((640, 480)),
        dump_frames: Some((frames.clone(), 4)),
        ..options(&record)
    })
    .unwrap();
    assert_eq!(big.trajectory_hash, same.trajectory_hash);
    assert_eq!(big.frames_written, 2 * 2);
    let png = std::fs::read(frames.join("c000004_a0_left.png")).unwrap();
    let be = |i: usize| u32::from_be_bytes([png[i], png[i + 1], png[i + 2], png[i + 3]]);
    assert_eq!((be(16), be(20)), (640, 480));
}

#[test]
fn sensor_hand_overs_happen_only_where_the_run_wrote_a_frame() {
    let dir = tempfile::tempdir().unwrap();
    let mut cycles = pixel_run();
    // Agent 1 is away in cycles 1..=5: its statuses pile up, then are handed over.
    for c in &mut cycles[1..=5] {
        c[1].0 = false;
    }
    let text = record_of(&cycles);
    let record = write(dir.path(), &text);
    replay(&options(&record)).unwrap();
    // Claim that agent 1 got a frame in cycle 2: its statuses of cycles 0-1 are gone
    // there in the replay, not in the record.
    let mut lines: Vec<serde_json::Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let i = 1 + 2 * 2 + 1;
    assert_eq!(
        (&lines[i]["cycle"], &lines[i]["agent"]),
        (&2.into(), &1.into())
    );
    lines[i]["sensed"] = true.into();
    let edited: String = lines.iter().map(|l| format!("{l}\n")).collect();
    let record = write(dir.path(), &edited);
    let err = replay(&options(&record)).unwrap_err();
    match err.downcast_ref::<ReplayDivergedError>() {
        Some(ReplayDivergedError::Cycle {
            cycle: 2,
            agent: 1,
            what,
            ..
        }) => assert!(what.contains("`statuses`"), "{what}"),
        _ => panic!("{err:#}"),
    }
}

#[test]
fn an_unknown_command_kind_in_a_line_is_malformed() {
    let dir = tempfile::tempdir().unwrap();
    let text = record_of(&pixel_run()).replace("\"kind\":\"turn\"", "\"kind\":\"fly\"");
    let record = write(dir.path(), &text);
    let err = replay(&options(&record)).unwrap_err();
    match err.downcast_ref::<RecordReadError>() {
        Some(RecordReadError::Malformed {
            line: 3, reason, ..
        }) => {
            assert!(reason.contains("fly"), "{reason}")
        }
        _ => panic!("{err:#}"),
    }
}
