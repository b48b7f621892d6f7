//! Unit tests of the original protocol's codec.

use super::*;

#[test]
fn start_sync_and_stop_sync_are_the_bytes_of_the_spec() {
    let mut out = Vec::new();
    push_message(&mut out, field::START_SYNC, &Empty {});
    assert_eq!(out, [3, 0, 0, 0, 0xA2, 0x01, 0x00]);
    assert_eq!(
        decode_frame(&[0xAA, 0x01, 0x00], Dialect::Vrnew),
        Ok(Incoming::Stop)
    );
    assert_eq!(decode_frame(&[], Dialect::Burkhardt), Ok(Incoming::Stop));
}

#[test]
fn version_checks_tell_the_dialect() {
    let vrnew = [0xE2, 0x01, 0x05, 0x0A, 0x03, 0x31, 0x2E, 0x30];
    let burkhardt = [0xEA, 0x01, 0x05, 0x0A, 0x03, 0x31, 0x2E, 0x30];
    assert_eq!(
        version_check_dialect(&vrnew),
        Some((Dialect::Vrnew, "1.0".into()))
    );
    assert_eq!(
        version_check_dialect(&burkhardt),
        Some((Dialect::Burkhardt, "1.0".into()))
    );
    // Field 29 does not exist in vrnew.
    assert_eq!(
        decode_frame(&burkhardt, Dialect::Vrnew),
        Err(FrameDecodeError::UnknownField { field: 29 })
    );
    let mut out = Vec::new();
    push_message(
        &mut out,
        Dialect::Vrnew.version_check_field(),
        &VersionCheck {
            version: Some(VERSION.into()),
        },
    );
    assert_eq!(&out[4..], &vrnew);
}

#[test]
fn scalars_are_written_even_when_zero() {
    let mut out = Vec::new();
    push_message(
        &mut out,
        field::ACTION_STATUS,
        &ActionStatus {
            action_id: Some(0),
            status: Some(0),
        },
    );
    // 32 (field 6), 4 bytes: 08 00 10 00.
    assert_eq!(&out[4..], &[0x32, 0x04, 0x08, 0x00, 0x10, 0x00]);
}

#[test]
fn commands_map_onto_the_catalogue_in_both_dialects() {
    let mut body = Vec::new();
    AgentMovement {
        action_id: Some(77),
        degree: Some(90.0),
        distance: Some(1.5),
    }
    .encode(&mut body)
    .unwrap();
    let mut frame = Vec::new();
    push_field(&mut frame, 1, body.len(), |o| o.extend_from_slice(&body));
    for d in [Dialect::Vrnew, Dialect::Burkhardt] {
        assert_eq!(
            decode_frame(&frame[4..], d),
            Ok(Incoming::Command {
                action_id: 77,
                command: Command::Move {
                    heading_deg: 90.0,
                    distance: 1.5
                }
            })
        );
    }
    let cancel = [0xDA, 0x01, 0x02, 0x08, 0x05]; // field 27 {1: 5}
    assert_eq!(
        decode_frame(&cancel, Dialect::Vrnew),
        Ok(Incoming::Command {
            action_id: 5,
            command: Command::CancelMove
        })
    );
    // In burkhardt, 27 is MoveTo.
    assert!(matches!(
        decode_frame(&cancel, Dialect::Burkhardt),
        Ok(Incoming::Command {
            command: Command::MoveTo { .. },
            ..
        })
    ));
}

#[test]
fn bad_frames_are_refused_whole() {
    // Two messages in one frame.
    let two = [0xA2, 0x01, 0x00, 0xAA, 0x01, 0x00];
    assert!(matches!(
        decode_frame(&two, Dialect::Vrnew),
        Err(FrameDecodeError::SeveralMessages { .. })
    ));
    // Garbage, a varint field, a truncated sub-message.
    assert!(decode_frame(&[0xFF; 12], Dialect::Vrnew).is_err());
    assert!(decode_frame(&[0x08, 0x01], Dialect::Vrnew).is_err());
    assert!(decode_frame(&[0x0A, 0x05, 0x08], Dialect::Vrnew).is_err());
    // An unknown field.
    assert_eq!(
        decode_frame(&[0x8A, 0x02, 0x00], Dialect::Burkhardt),
        Err(FrameDecodeError::UnknownField { field: 33 })
    );
}

#[test]
fn the_reader_skips_oversize_frames_and_refuses_negative_lengths() {
    let mut data = Vec::new();
    data.extend_from_slice(&10i32.to_le_bytes());
    data.extend_from_slice(&[7; 10]);
    data.extend_from_slice(&0i32.to_le_bytes());
    data.extend_from_slice(&2i32.to_le_bytes());
    data.extend_from_slice(&[1, 2]);
    data.extend_from_slice(&(-5i32).to_le_bytes());
    let mut r = FrameReader::new(4);
    let mut src = &data[..];
    assert_eq!(r.read_from(&mut src).unwrap(), FrameProgress::Skipped(10));
    assert_eq!(r.read_from(&mut src).unwrap(), FrameProgress::Frame);
    assert!(r.body().is_empty());
    assert_eq!(r.read_from(&mut src).unwrap(), FrameProgress::Frame);
    assert_eq!(r.body(), &[1, 2]);
    assert!(matches!(
        r.read_from(&mut src),
        Err(FrameReadError::NegativeLength(-5))
    ));
}

#[test]
fn images_decode_with_the_derived_message() {
    let mut out = Vec::new();
    push_images(&mut out, &[1, 2, 3], &[4], Some(&[5, 6]));
    let (fnum, p) = single_field(&out[4..], Dialect::Burkhardt).unwrap();
    assert_eq!(fnum, field::IMAGES);
    let m = Images::decode(p).unwrap();
    assert_eq!(
        (m.left, m.right, m.main),
        (Some(vec![1, 2, 3]), Some(vec![4]), Some(vec![5, 6]))
    );
    assert_eq!(
        i32::from_le_bytes(out[..4].try_into().unwrap()) as usize,
        out.len() - 4
    );
}
