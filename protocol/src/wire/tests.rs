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
