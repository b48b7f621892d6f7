//! The world's unit tests: motion, collisions, eyes, object actions, resets, determinism.

use std::path::Path;

use super::*;
use glam::Vec3;
use vrsync_bridge::{ActionState, Command, Config, SensorHeader};

use crate::geometry::angle_diff_deg;

const CAMS: &str = "[[agent.camera]]\nname = \"left\"\nwidth = 64\nheight = 48\nfov_horizontal_deg = 90.0\nfov_vertical_deg = 73.74\n";

/// A 10 × 10 room, dt 0.1 s, speed 3 m/s, turning 180°/s, eyes 300°/s; a red sphere
/// (id 1, graspable) at (0, 0.4, 3) and a box (id 2) at (-3, 0.5, 0); agents as given.
fn world_with(agents: &[(u32, [f32; 2], f32)], extra: &str) -> World {
    let mut text = String::from("session = \"w\"\n");
    for &(id, _, _) in agents {
        text += &format!("[[agent]]\nid = {id}\n{CAMS}");
    }
    text += "[world]\n";
    text += extra;
    text += "[[world.object]]\nid = 1\nshape = \"sphere\"\nposition = [0.0, 0.4, 3.0]\nradius = 0.4\ncolor = [220, 30, 30]\ngraspable = true\n";
    text += "[[world.object]]\nid = 2\nshape = \"box\"\nposition = [-3.0, 0.5, 0.0]\nsize = [1.0, 1.0, 1.0]\ncolor = [40, 90, 220]\n";
    text += "[[world.goal]]\ncenter = [0.0, 1.5]\nradius = 0.5\nreward = 1.0\n";
    text += "[[world.goal]]\nobject = 1\naction = \"grasp\"\nreward = 5.0\n";
    for &(id, [x, z], h) in agents {
        text += &format!(
            "[[world.agent]]\nid = {id}\nposition = [{x:?}, {z:?}]\nheading_deg = {h:?}\n"
        );
    }
    let config = Config::from_toml_str(&text, Path::new("t.toml")).unwrap();
    World::from_config(&config).unwrap()
}

fn world() -> World {
    world_with(&[(0, [0.0, 0.0], 0.0)], "")
}

fn sensors(w: &mut World, id: u32) -> SensorHeader {
    let mut h = SensorHeader::default();
    w.write_sensors(id, &mut h);
    h
}

fn statuses(h: &SensorHeader) -> Vec<(u32, ActionState)> {
    h.statuses()
        .iter()
        .map(|s| (s.action_id, ActionState::from_u32(s.state).unwrap()))
        .collect()
}

fn close(a: Vec3, b: Vec3) -> bool {
    (a - b).length() < 1e-4
}

use ActionState::{Aborted, Finished, InExecution, Rotating, Walking, WalkingRotating};

#[test]
fn move_walks_speed_times_dt_per_cycle_and_finishes() {
    let mut w = world();
    let mv = Command::Move {
        heading_deg: 0.0,
        distance: 0.75,
    };
    w.apply(0, 1, mv).unwrap();
    w.step(); // 0.3 m
    assert!(close(w.bodies()[0].position, Vec3::new(0.0, 0.0, 0.3)));
    assert_eq!(
        statuses(&sensors(&mut w, 0)),
        [(1, InExecution), (1, Walking)]
    );
    w.step(); // 0.6 m
    let h = sensors(&mut w, 0);
    assert_eq!(statuses(&h), [(1, Walking)]);
    assert!(
        (h.head_motion.velocity[2] - 3.0).abs() < 1e-3,
        "{:?}",
        h.head_motion
    );
    w.step(); // 0.75 m, done
    assert_eq!(statuses(&sensors(&mut w, 0)), [(1, Finished)]);
    assert!(close(w.bodies()[0].position, Vec3::new(0.0, 0.0, 0.75)));
    w.step();
    let h = sensors(&mut w, 0);
    assert!(h.statuses().is_empty());
    assert_eq!(h.head_motion.velocity, [0.0; 3]);
}

#[test]
fn move_turns_towards_its_heading_while_walking() {
    let mut w = world();
    w.apply(
        0,
        1,
        Command::Move {
            heading_deg: 90.0,
            distance: 0.6,
        },
    )
    .unwrap();
    w.step(); // walks east 0.3 m, turns 18° of 90°
    w.step(); // walks 0.6 m: walking done, still turning
    w.step(); // turning only
    let h = sensors(&mut w, 0);
    assert_eq!(
        statuses(&h),
        [
            (1, InExecution),
            (1, WalkingRotating),
            (1, WalkingRotating),
            (1, Rotating)
        ]
    );
    assert!(close(w.bodies()[0].position, Vec3::new(0.6, 0.0, 0.0)));
    assert!((w.bodies()[0].heading_deg - 54.0).abs() < 1e-3);
    assert!((h.head_motion.angular_velocity_deg[1] - 180.0).abs() < 1e-2);
    w.step();
    w.step();
    assert_eq!(
        statuses(&sensors(&mut w, 0)),
        [(1, Rotating), (1, Finished)]
    );
    assert_eq!(w.bodies()[0].heading_deg, 90.0);
}

#[test]
fn turn_rotates_at_turn_speed_both_ways() {
    let mut w = world();
    w.apply(0, 4, Command::Turn { angle_deg: -45.0 }).unwrap();
    w.step();
    w.step();
    w.step();
    assert_eq!(
        statuses(&sensors(&mut w, 0)),
        [
            (4, InExecution),
            (4, Rotating),
            (4, Rotating),
            (4, Finished)
        ]
    );
    assert!((w.bodies()[0].heading_deg - 315.0).abs() < 1e-3);
    assert_eq!(w.bodies()[0].position, Vec3::ZERO);
}

#[test]
fn move_to_walks_a_straight_line_to_the_target() {
    let mut w = world();
    let target = Vec3::new(1.2, 5.0, 1.6); // y is ignored
    w.apply(0, 3, Command::MoveTo { target }).unwrap();
    for _ in 0..10 {
        w.step();
        let p = w.bodies()[0].position;
        assert!((p.x * 1.6 - p.z * 1.2).abs() < 1e-4, "off the line: {p}");
    }
    let s = statuses(&sensors(&mut w, 0));
    assert_eq!(s.last(), Some(&(3, Finished)));
    assert!(close(w.bodies()[0].position, Vec3::new(1.2, 0.0, 1.6)));
    assert!((w.bodies()[0].heading_deg - heading_of(1.2, 1.6)).abs() < 1e-3);
}

#[test]
fn a_new_move_aborts_the_running_one_and_cancel_stops() {
    let mut w = world();
    w.apply(
        0,
        1,
        Command::Move {
            heading_deg: 0.0,
            distance: 2.0,
        },
    )
    .unwrap();
    w.step();
    w.apply(0, 2, Command::Turn { angle_deg: 90.0 }).unwrap();
    w.step();
    w.apply(0, 3, Command::CancelMove).unwrap();
    let before = w.bodies()[0].clone();
    w.step();
    assert_eq!(
        statuses(&sensors(&mut w, 0)),
        [
            (1, InExecution),
            (1, Walking),
            (1, Aborted),
            (2, InExecution),
            (2, Rotating),
            (2, Aborted),
            (3, Finished)
        ]
    );
    assert_eq!(w.bodies()[0].position, before.position);
    assert_eq!(w.bodies()[0].heading_deg, before.heading_deg);
}

#[test]
fn walls_objects_and_agents_stop_a_move_with_a_collision() {
    // Wall: north (+z), from z = 3.5 with radius 0.3 the contact is at z = 4.7.
    let mut w = world_with(&[(0, [2.0, 3.5], 0.0)], "");
    w.apply(
        0,
        7,
        Command::Move {
            heading_deg: 0.0,
            distance: 5.0,
        },
    )
    .unwrap();
    for _ in 0..10 {
        w.step();
    }
    let h = sensors(&mut w, 0);
    assert_eq!(h.collisions().len(), 1);
    assert_eq!(
        (h.collisions()[0].action_id, h.collisions()[0].collider_id),
        (7, WALL_COLLIDER_ID)
    );
    assert_eq!(statuses(&h).last(), Some(&(7, Finished)));
    let z = w.bodies()[0].position.z;
    assert!(z <= 4.7 && z > 4.69, "{z}");

    // Object: the box (id 2) spans x -3.5..-2.5; from x = 0 westwards the contact is at
    // x = -2.2.
    let mut w = world();
    w.apply(
        0,
        8,
        Command::Move {
            heading_deg: 270.0,
            distance: 5.0,
        },
    )
    .unwrap();
    for _ in 0..20 {
        w.step();
    }
    let h = sensors(&mut w, 0);
    assert_eq!(h.collisions()[0].collider_id, 2);
    let x = w.bodies()[0].position.x;
    assert!((-2.2..-2.19).contains(&x), "{x}");

    // Another agent: agent 1 stands 1.5 m east of agent 0.
    let mut w = world_with(&[(0, [0.0, 0.0], 0.0), (1, [1.5, 0.0], 0.0)], "");
    w.apply(
        0,
        9,
        Command::Move {
            heading_deg: 90.0,
            distance: 2.0,
        },
    )
    .unwrap();
    for _ in 0..10 {
        w.step();
    }
    let h = sensors(&mut w, 0);
    assert_eq!(h.collisions()[0].collider_id, AGENT_COLLIDER_BASE + 1);
    assert!(w.bodies()[0].position.x <= 0.9 + 1e-4);
    assert!(sensors(&mut w, 1).collisions().is_empty());
}

#[test]
fn eye_movement_runs_at_eye_speed_and_reports_positions() {
    let mut w = world();
    w.apply(
        0,
        5,
        Command::EyeMovement {
            pan_left_deg: 40.0,
            pan_right_deg: -20.0,
            tilt_deg: -10.0,
        },
    )
    .unwrap();
    w.step(); // 30° per cycle at most
    let h = sensors(&mut w, 0);
    assert_eq!(h.eye.rotation_deg, [30.0, -20.0, -10.0]);
    assert_eq!(h.eye.rotation_velocity_deg, [30.0, -20.0, -10.0]);
    assert_eq!(statuses(&h), [(5, InExecution)]);
    w.step();
    let h = sensors(&mut w, 0);
    assert_eq!(h.eye.rotation_deg, [40.0, -20.0, -10.0]);
    assert_eq!(h.eye.rotation_velocity_deg, [10.0, 0.0, 0.0]);
    assert_eq!(statuses(&h), [(5, Finished)]);
    // A new eye command aborts an unfinished one.
    w.apply(
        0,
        6,
        Command::EyeMovement {
            pan_left_deg: -90.0,
            pan_right_deg: 0.0,
            tilt_deg: 0.0,
        },
    )
    .unwrap();
    w.step();
    w.apply(
        0,
        7,
        Command::EyeMovement {
            pan_left_deg: 0.0,
            pan_right_deg: 0.0,
            tilt_deg: 0.0,
        },
    )
    .unwrap();
    assert_eq!(
        statuses(&sensors(&mut w, 0)),
        [(6, InExecution), (6, Aborted), (7, InExecution)]
    );
}

#[test]
fn eye_fixation_converges_on_a_near_point_and_keeps_tracking() {
    let mut w = world();
    // 0.5 m ahead at eye height: the left eye turns right, the right eye left.
    w.apply(
        0,
        1,
        Command::EyeFixation {
            target: Vec3::new(0.0, 1.6, 0.5),
        },
    )
    .unwrap();
    w.step();
    let h = sensors(&mut w, 0);
    assert_eq!(statuses(&h), [(1, InExecution), (1, Finished)]);
    let [l, r, t] = h.eye.rotation_deg;
    let expected = (0.0325f32 / 0.5).atan().to_degrees();
    assert!(
        (l - expected).abs() < 1e-3 && (r + expected).abs() < 1e-3,
        "{l} {r}"
    );
    assert!(t.abs() < 1e-3);
    // The body turns 90° right: the eyes keep the point, now 90° to the left.
    w.apply(0, 2, Command::Turn { angle_deg: 90.0 }).unwrap();
    for _ in 0..5 {
        w.step();
    }
    let h = sensors(&mut w, 0);
    assert!(
        h.eye.rotation_deg[0] < -80.0 && h.eye.rotation_deg[1] < -80.0,
        "{:?}",
        h.eye
    );
    assert!(!statuses(&h).iter().any(|s| s.0 == 1), "reported once");
}

#[test]
fn grasp_carry_release_and_rewards() {
    // From the origin the sphere at z = 3 is 3 - 0.4 - 0.3 = 2.3 m away: out of reach;
    // from z = 1.5 it is 0.8 m away: within the 1 m reach.
    let mut w = world_with(&[(0, [0.0, 0.0], 0.0)], "");
    w.apply(0, 1, Command::GraspId { object_id: 1 }).unwrap();
    assert_eq!(statuses(&sensors(&mut w, 0)), [(1, Aborted)]); // 3 - 0.7 = 2.3 m gap
    w.apply(
        0,
        2,
        Command::Move {
            heading_deg: 0.0,
            distance: 1.5,
        },
    )
    .unwrap();
    for _ in 0..5 {
        w.step();
    }
    let h = sensors(&mut w, 0);
    assert_eq!(h.reward, 1.0, "entered the region around (0, 1.5)");
    w.apply(0, 3, Command::GraspId { object_id: 1 }).unwrap();
    assert_eq!(w.bodies()[0].held, Some(1));
    let h = sensors(&mut w, 0);
    assert_eq!(statuses(&h), [(3, Finished)]);
    assert_eq!(h.reward, 5.0);
    // Hands full; box 2 is not graspable anyway.
    w.apply(0, 4, Command::GraspId { object_id: 1 }).unwrap();
    assert_eq!(statuses(&sensors(&mut w, 0)), [(4, Aborted)]);
    // The held object moves with the body and no longer blocks.
    w.apply(
        0,
        5,
        Command::Move {
            heading_deg: 0.0,
            distance: 1.0,
        },
    )
    .unwrap();
    for _ in 0..4 {
        w.step();
    }
    let h = sensors(&mut w, 0);
    assert!(h.collisions().is_empty());
    let body = w.bodies()[0].position;
    let ball = w.objects()[0].position;
    assert!(
        (ball.z - body.z - 0.75).abs() < 1e-4 && ball.y > 0.5,
        "{ball} {body}"
    );
    w.apply(0, 6, Command::GraspRelease).unwrap();
    assert_eq!(w.objects()[0].position.y, 0.4);
    assert_eq!(w.objects()[0].held_by, None);
    w.apply(0, 7, Command::GraspRelease).unwrap();
    assert_eq!(statuses(&sensors(&mut w, 0)), [(6, Finished), (7, Aborted)]);
    // Passing through the region pays once; coming back pays again; staying does not.
    w.apply(0, 8, Command::MoveTo { target: Vec3::ZERO })
        .unwrap();
    for _ in 0..10 {
        w.step();
    }
    assert_eq!(sensors(&mut w, 0).reward, 1.0);
    w.apply(
        0,
        9,
        Command::MoveTo {
            target: Vec3::new(0.0, 0.0, 1.5),
        },
    )
    .unwrap();
    for _ in 0..10 {
        w.step();
    }
    assert_eq!(sensors(&mut w, 0).reward, 1.0);
    w.apply(0, 10, Command::Turn { angle_deg: 90.0 }).unwrap();
    for _ in 0..10 {
        w.step();
    }
    assert_eq!(sensors(&mut w, 0).reward, 0.0);
}

#[test]
fn point_and_interact_by_image_position_use_the_left_eye_ray() {
    // 1.2 m south of the sphere, facing it: the sphere covers the image centre.
    let mut w = world_with(&[(0, [0.0, 1.8], 0.0)], "");
    w.apply(
        0,
        1,
        Command::EyeMovement {
            pan_left_deg: 0.0,
            pan_right_deg: 0.0,
            tilt_deg: -45.0,
        },
    )
    .unwrap();
    w.step();
    w.step();
    sensors(&mut w, 0);
    w.apply(
        0,
        2,
        Command::GraspPos {
            x_px: 32.0,
            y_px: 24.0,
        },
    )
    .unwrap();
    assert_eq!(w.bodies()[0].held, Some(1));
    w.apply(0, 3, Command::GraspRelease).unwrap();
    // The top-left pixel sees a wall: nothing to point at.
    w.apply(
        0,
        4,
        Command::PointPos {
            x_px: 0.0,
            y_px: 0.0,
        },
    )
    .unwrap();
    w.apply(
        0,
        5,
        Command::InteractPos {
            x_px: 32.0,
            y_px: 24.0,
        },
    )
    .unwrap();
    assert_eq!(
        statuses(&sensors(&mut w, 0)),
        [(2, Finished), (3, Finished), (4, Aborted), (5, Finished)]
    );
    // Outside the 64 × 48 image: rejected.
    let before = w.bodies().to_vec();
    assert!(
        w.apply(
            0,
            6,
            Command::PointPos {
                x_px: 64.0,
                y_px: 0.0
            }
        )
        .is_err()
    );
    assert!(
        w.apply(
            0,
            6,
            Command::GraspPos {
                x_px: -0.5,
                y_px: 0.0
            }
        )
        .is_err()
    );
    assert_eq!(w.bodies(), &before[..]);
}

#[test]
fn resets_restore_the_start() {
    let mut w = world_with(&[(0, [0.0, 0.0], 0.0), (1, [2.0, 0.0], 90.0)], "");
    w.apply(
        0,
        1,
        Command::Move {
            heading_deg: 0.0,
            distance: 1.5,
        },
    )
    .unwrap();
    w.apply(
        1,
        1,
        Command::Move {
            heading_deg: 180.0,
            distance: 3.0,
        },
    )
    .unwrap();
    for _ in 0..5 {
        w.step();
    }
    w.apply(0, 2, Command::GraspId { object_id: 1 }).unwrap();
    w.apply(
        1,
        2,
        Command::EyeMovement {
            pan_left_deg: 10.0,
            pan_right_deg: 10.0,
            tilt_deg: 0.0,
        },
    )
    .unwrap();
    w.step();
    sensors(&mut w, 0);
    sensors(&mut w, 1);
    // Trial reset: agent 0 only, its object back in place.
    w.apply(0, 3, Command::TrialReset { reset_type: 0 })
        .unwrap();
    assert_eq!(w.bodies()[0].position, Vec3::ZERO);
    assert_eq!(w.objects()[0].position, Vec3::new(0.0, 0.4, 3.0));
    assert_ne!(w.bodies()[1].position, Vec3::new(2.0, 0.0, 0.0));
    assert_eq!(statuses(&sensors(&mut w, 0)), [(3, Finished)]);
    // Environment reset: everyone, running actions aborted.
    w.apply(
        1,
        4,
        Command::Move {
            heading_deg: 0.0,
            distance: 3.0,
        },
    )
    .unwrap();
    w.apply(0, 4, Command::EnvironmentReset { reset_type: 0 })
        .unwrap();
    assert_eq!(w.bodies()[1].position, Vec3::new(2.0, 0.0, 0.0));
    assert_eq!(w.bodies()[1].heading_deg, 90.0);
    assert_eq!(w.bodies()[1].eyes, Eyes::default());
    assert_eq!(
        statuses(&sensors(&mut w, 1)),
        [(1, Aborted), (4, InExecution), (4, Aborted)]
    );
    assert!(
        w.apply(0, 5, Command::EnvironmentReset { reset_type: 3 })
            .is_err()
    );
}

#[test]
fn bad_commands_are_rejected_and_leave_the_world_untouched() {
    let mut w = world();
    w.apply(
        0,
        1,
        Command::Move {
            heading_deg: 0.0,
            distance: 1.0,
        },
    )
    .unwrap();
    let before = (w.bodies().to_vec(), w.objects().to_vec());
    let bad = [
        Command::Move {
            heading_deg: 0.0,
            distance: -1.0,
        },
        Command::Move {
            heading_deg: 0.0,
            distance: 1e9,
        },
        Command::Turn { angle_deg: 1e9 },
        Command::MoveTo {
            target: Vec3::new(9.0, 0.0, 0.0),
        },
        Command::EyeMovement {
            pan_left_deg: 136.0,
            pan_right_deg: 0.0,
            tilt_deg: 0.0,
        },
        Command::EyeMovement {
            pan_left_deg: 0.0,
            pan_right_deg: 0.0,
            tilt_deg: -91.0,
        },
        Command::EyeFixation {
            target: Vec3::new(0.0, 9.0, 0.0),
        },
        Command::GraspId { object_id: 77 },
        Command::PointId { object_id: 0 },
        Command::InteractId { object_id: 1000 },
        Command::TrialReset { reset_type: 1 },
    ];
    for c in bad {
        assert!(w.apply(0, 2, c).is_err(), "{c:?} accepted");
    }
    assert!(w.apply(9, 2, Command::CancelMove).is_err());
    assert_eq!((w.bodies().to_vec(), w.objects().to_vec()), before);
}

#[test]
fn same_commands_same_hash() {
    let run = || {
        let mut w = world_with(&[(0, [0.0, 0.0], 0.0), (1, [2.0, -2.0], 300.0)], "");
        let mut h = blake3::Hasher::new();
        for cycle in 0..50u32 {
            let heading = (cycle * 37 % 360) as f32;
            w.apply(
                cycle % 2,
                cycle,
                Command::Move {
                    heading_deg: heading,
                    distance: 1.0,
                },
            )
            .unwrap();
            w.step();
            w.hash_into(&mut h);
            sensors(&mut w, 0);
            sensors(&mut w, 1);
        }
        h.finalize()
    };
    assert_eq!(run(), run());
}

#[test]
fn agents_without_a_start_get_free_places_facing_the_centre() {
    let text = format!(
        "[[agent]]\nid = 0\n{CAMS}[[agent]]\nid = 1\n[[agent]]\nid = 2\n[world]\n[[world.object]]\nid = 1\nshape = \"box\"\nposition = [0.0, 0.5, 2.5]\nsize = [1.0, 1.0, 1.0]\ncolor = [1, 2, 3]\n"
    );
    let config = Config::from_toml_str(&text, Path::new("t.toml")).unwrap();
    let w = World::from_config(&config).unwrap();
    for (i, b) in w.bodies().iter().enumerate() {
        assert!(w.collider_at(Some(i), b.position).is_none(), "{b:?}");
        let to_centre = heading_of(-b.position.x, -b.position.z);
        assert!(angle_diff_deg(b.heading_deg, to_centre).abs() < 1e-3);
    }
    // An explicit start inside the box is a config error naming the key.
    let text = "[[agent]]\nid = 0\n[world]\n[[world.object]]\nid = 1\nshape = \"box\"\nposition = [0.0, 0.5, 0.0]\nsize = [1.0, 1.0, 1.0]\ncolor = [1, 2, 3]\n[[world.agent]]\nid = 0\nposition = [0.2, 0.0]\n";
    let config = Config::from_toml_str(text, Path::new("t.toml")).unwrap();
    let e = World::from_config(&config).unwrap_err().to_string();
    assert!(
        e.contains("world.agent[0].position") && e.contains("object 1"),
        "{e}"
    );
}
