//! Unit tests of the wire types.

use super::layout::layout_hash;

use super::*;

#[test]
fn images_are_packed_in_camera_order_each_aligned() {
    let (descs, total) = image_layout([
        ("left", 3, 2, PixelFormat::Rgb8),
        ("depth", 5, 1, PixelFormat::Depth32f),
    ]);
    assert_eq!(descs[0].name(), "left");
    assert_eq!(
        (descs[0].offset, descs[0].len, descs[0].stride_bytes),
        (0, 18, 9)
    );
    assert_eq!(descs[1].camera, 1);
    assert_eq!(
        (descs[1].offset, descs[1].len, descs[1].stride_bytes),
        (64, 20, 20)
    );
    assert_eq!(total, 84);
    assert_eq!(image_layout([]).1, 0);
}

fn all_commands() -> Vec<Command> {
    vec![
        Command::Move {
            heading_deg: 90.0,
            distance: 2.5,
        },
        Command::Turn { angle_deg: -45.0 },
        Command::MoveTo {
            target: Vec3::new(1.0, 0.0, -2.0),
        },
        Command::CancelMove,
        Command::EyeMovement {
            pan_left_deg: 5.0,
            pan_right_deg: -5.0,
            tilt_deg: 10.0,
        },
        Command::EyeFixation {
            target: Vec3::new(0.5, 1.5, 3.0),
        },
        Command::GraspId { object_id: 7 },
        Command::GraspPos {
            x_px: 10.0,
            y_px: 20.0,
        },
        Command::PointId { object_id: 3 },
        Command::PointPos {
            x_px: 1.0,
            y_px: 2.0,
        },
        Command::InteractId { object_id: 9 },
        Command::InteractPos {
            x_px: 3.0,
            y_px: 4.0,
        },
        Command::GraspRelease,
        Command::EnvironmentReset { reset_type: 1 },
        Command::TrialReset { reset_type: 0 },
    ]
}

#[test]
fn every_command_round_trips_through_the_wire_form() {
    for (i, cmd) in all_commands().into_iter().enumerate() {
        let wire = cmd.encode(i as u32 + 100);
        assert_eq!(wire.action_id, i as u32 + 100);
        assert_eq!(wire.decode(), Ok(cmd), "{}", cmd.name());
        assert_ne!(kind_name(wire.kind), "unknown");
    }
}

/// The wire form of `all_commands()` as the hand-written encoder made it before the
/// catalogue: `(kind, object_id, args)`.
#[test]
fn every_command_keeps_its_wire_form() {
    let want: [(u32, u32, [f32; 4]); 15] = [
        (1, 0, [90.0, 2.5, 0.0, 0.0]),
        (2, 0, [-45.0, 0.0, 0.0, 0.0]),
        (3, 0, [1.0, 0.0, -2.0, 0.0]),
        (4, 0, [0.0; 4]),
        (5, 0, [5.0, -5.0, 10.0, 0.0]),
        (6, 0, [0.5, 1.5, 3.0, 0.0]),
        (7, 7, [0.0; 4]),
        (8, 0, [10.0, 20.0, 0.0, 0.0]),
        (9, 3, [0.0; 4]),
        (10, 0, [1.0, 2.0, 0.0, 0.0]),
        (11, 9, [0.0; 4]),
        (12, 0, [3.0, 4.0, 0.0, 0.0]),
        (13, 0, [0.0; 4]),
        (14, 1, [0.0; 4]),
        (15, 0, [0.0; 4]),
    ];
    for (cmd, (kind, object_id, args)) in all_commands().into_iter().zip(want) {
        let m = cmd.encode(3);
        assert_eq!(
            (m.kind, m.action_id, m.object_id, m.reserved, m.args),
            (kind, 3, object_id, 0, args),
            "{}",
            cmd.name()
        );
    }
}

#[test]
fn the_catalogue_lists_every_command_once_in_tag_order() {
    let commands = all_commands();
    assert_eq!(CommandKind::ALL.len(), commands.len());
    for ((k, cmd), tag) in CommandKind::ALL.iter().zip(&commands).zip(1..) {
        assert_eq!((k.tag, cmd.kind(), cmd.name()), (tag, tag, k.name));
        assert_eq!(kind_name(tag), k.name);
        assert_eq!(CommandKind::of(tag), Some(k));
        let debug = format!("{cmd:?}");
        assert_eq!(debug.split([' ', '{']).next(), Some(k.variant), "{debug}");
        // The arguments it uses are checked, the others never read.
        let mut m = cmd.encode(1);
        if k.arg_count > 0 {
            m.args[k.arg_count - 1] = f32::NAN;
            assert!(m.decode().is_err(), "{}", k.name);
        }
        let mut m = cmd.encode(1);
        if let Some(unused) = m.args.get_mut(k.arg_count) {
            *unused = f32::NAN;
        }
        assert_eq!(m.decode(), Ok(*cmd), "{}", k.name);
        let floats = k.params.iter().filter(|p| p.ty == ParamType::F32).count();
        assert_eq!(floats, k.arg_count, "{}", k.name);
    }
    let mut names: Vec<_> = CommandKind::ALL.iter().map(|k| k.name).collect();
    names.sort_unstable();
    names.dedup();
    assert_eq!(names.len(), CommandKind::ALL.len());
    assert_eq!(CommandKind::of(0), None);
    assert_eq!(CommandKind::of(ACTION_KIND), None);
    assert_eq!(kind_name(ACTION_KIND), "unknown");
}

/// `Display` spells each command as the bindings do (the Python classes' `repr`, as they
/// wrote it by hand before).
#[test]
fn every_command_displays_with_the_bindings_names() {
    let want = [
        "Move(heading_deg=90, distance_m=2.5)",
        "Turn(angle_deg=-45)",
        "MoveTo(x=1, y=0, z=-2)",
        "CancelMove()",
        "EyeMovement(pan_left_deg=5, pan_right_deg=-5, tilt_deg=10)",
        "EyeFixation(x=0.5, y=1.5, z=3)",
        "GraspId(object_id=7)",
        "GraspPos(x_px=10, y_px=20)",
        "PointId(object_id=3)",
        "PointPos(x_px=1, y_px=2)",
        "InteractId(object_id=9)",
        "InteractPos(x_px=3, y_px=4)",
        "GraspRelease()",
        "EnvironmentReset(reset_type=1)",
        "TrialReset(reset_type=0)",
    ];
    let got: Vec<String> = all_commands().iter().map(ToString::to_string).collect();
    assert_eq!(got, want);
}

#[test]
fn unknown_kind_and_non_finite_arguments_are_rejected() {
    let bad = MotorCommand {
        kind: 99,
        action_id: 4,
        ..Default::default()
    };
    assert_eq!(
        bad.decode(),
        Err(CommandDecodeError::UnknownKind {
            kind: 99,
            action_id: 4
        })
    );
    let mut nan = Command::Move {
        heading_deg: 0.0,
        distance: 1.0,
    }
    .encode(5);
    nan.args[1] = f32::NAN;
    assert!(matches!(
        nan.decode(),
        Err(CommandDecodeError::NonFinite { index: 1, .. })
    ));
    // Unused argument slots may hold anything: they are never read.
    let mut turn = Command::Turn { angle_deg: 1.0 }.encode(6);
    turn.args[3] = f32::INFINITY;
    assert!(turn.decode().is_ok());
}

#[test]
fn header_tables_are_bounded() {
    let mut h = SensorHeader::default();
    for i in 0..MAX_STATUSES as u32 {
        assert!(h.push_status(i, ActionState::Walking));
    }
    assert!(!h.push_status(99, ActionState::Finished));
    assert_eq!(h.statuses().len(), MAX_STATUSES);
    h.status_count = 1000; // hostile value: views stay in bounds
    assert_eq!(h.statuses().len(), MAX_STATUSES);
    h.image_count = u32::MAX;
    assert_eq!(h.image_descs().len(), MAX_CAMERAS);
}

#[test]
fn layout_hash_is_stable_within_a_build() {
    assert_eq!(LAYOUT_HASH, layout_hash());
    assert_ne!(LAYOUT_HASH, 0);
}
