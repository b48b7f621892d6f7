//! The wire layout's compile-time checks and its hash ([`LAYOUT_HASH`]).

use core::mem::{align_of, offset_of, size_of};

use super::*;

// Compile-time layout checks: a change here is a protocol change.
const _: () = {
    assert!(size_of::<Pose>() == 28 && align_of::<Pose>() == 4);
    assert!(size_of::<GridPosition>() == 24);
    assert!(size_of::<HeadMotion>() == 48);
    assert!(size_of::<EyePosition>() == 24);
    assert!(size_of::<ActionStatus>() == 16 && align_of::<ActionStatus>() == 8);
    assert!(size_of::<Collision>() == 16 && align_of::<Collision>() == 8);
    assert!(size_of::<ImageDesc>() == 56 && align_of::<ImageDesc>() == 8);
    assert!(size_of::<SensorHeader>() == 1304 && align_of::<SensorHeader>() == 8);
    assert!(size_of::<VectorDesc>() == 32 && align_of::<VectorDesc>() == 8);
    assert!(size_of::<ActionDesc>() == 32 && align_of::<ActionDesc>() == 8);
    assert!(size_of::<MotorHeader>() == 32 && align_of::<MotorHeader>() == 8);
    assert!(size_of::<MotorCommand>() == 32 && align_of::<MotorCommand>() == 4);
};

const fn fnv1a(mut hash: u64, value: u64) -> u64 {
    let mut i = 0;
    while i < 8 {
        hash ^= (value >> (i * 8)) & 0xff;
        hash = hash.wrapping_mul(0x0000_0100_0000_01b3);
        i += 1;
    }
    hash
}

pub(super) const fn layout_hash() -> u64 {
    let items: [usize; 61] = [
        size_of::<SensorHeader>(),
        offset_of!(SensorHeader, protocol_version),
        offset_of!(SensorHeader, agent_id),
        offset_of!(SensorHeader, cycle),
        offset_of!(SensorHeader, sim_time_ns),
        offset_of!(SensorHeader, flags),
        offset_of!(SensorHeader, image_count),
        offset_of!(SensorHeader, pose),
        offset_of!(SensorHeader, reward),
        offset_of!(SensorHeader, grid),
        offset_of!(SensorHeader, head_motion),
        offset_of!(SensorHeader, eye),
        offset_of!(SensorHeader, status_count),
        offset_of!(SensorHeader, collision_count),
        offset_of!(SensorHeader, statuses),
        offset_of!(SensorHeader, collisions),
        offset_of!(SensorHeader, images),
        offset_of!(SensorHeader, previous_outcome),
        offset_of!(SensorHeader, previous_rejected),
        offset_of!(SensorHeader, vector_count),
        offset_of!(SensorHeader, action_count),
        offset_of!(SensorHeader, vectors),
        offset_of!(SensorHeader, actions),
        size_of::<VectorDesc>(),
        offset_of!(VectorDesc, offset),
        offset_of!(VectorDesc, len),
        size_of::<ActionDesc>(),
        offset_of!(ActionDesc, len),
        offset_of!(ActionDesc, n),
        offset_of!(ActionDesc, bounds_hash),
        size_of::<ImageDesc>(),
        offset_of!(ImageDesc, camera),
        offset_of!(ImageDesc, format),
        offset_of!(ImageDesc, width_px),
        offset_of!(ImageDesc, stride_bytes),
        offset_of!(ImageDesc, offset),
        offset_of!(ImageDesc, len),
        size_of::<MotorHeader>(),
        offset_of!(MotorHeader, agent_id),
        offset_of!(MotorHeader, cycle),
        offset_of!(MotorHeader, flags),
        offset_of!(MotorHeader, command_count),
        offset_of!(MotorHeader, ack_cycle),
        size_of::<ActionStatus>(),
        offset_of!(ActionStatus, state),
        offset_of!(ActionStatus, seq),
        size_of::<Collision>(),
        offset_of!(Collision, collider_id),
        offset_of!(Collision, seq),
        size_of::<MotorCommand>(),
        offset_of!(MotorCommand, kind),
        offset_of!(MotorCommand, action_id),
        offset_of!(MotorCommand, object_id),
        offset_of!(MotorCommand, args),
        MAX_CAMERAS,
        MAX_STATUSES,
        MAX_COLLISIONS,
        CAMERA_NAME_LEN,
        MAX_VECTORS,
        MAX_ACTIONS,
        CHANNEL_NAME_LEN,
    ];
    let mut hash = 0xcbf2_9ce4_8422_2325_u64;
    let mut i = 0;
    while i < items.len() {
        hash = fnv1a(hash, items[i] as u64);
        i += 1;
    }
    hash
}

/// Hash of the wire layout (every size and field offset above). Published as a service
/// attribute and compared by agents at connect.
pub const LAYOUT_HASH: u64 = layout_hash();
