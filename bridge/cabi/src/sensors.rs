//! The `#[repr(C)]` sensor structs both C ABIs declare, with their conversions from and to
//! the wire format.
//!
//! The Rust names are the agent header's (`vrs_pose_t`, …); the host's cbindgen settings
//! rename each to its `vrs_host_` name (`bridge/ffi/cbindgen.toml`, `[export.rename]`),
//! and the host crate re-exports them under those names. Doc comments here are copied
//! into both headers, so they name neither ABI's functions.

#![allow(non_camel_case_types)]

use vrsync_transport::{ActionStatus, Collision, EyePosition, GridPosition, HeadMotion, Pose};

/// Size of a camera name field: up to 16 bytes of UTF-8 and a terminating NUL. (Each
/// header declares its own constant of this value.)
///
/// cbindgen:ignore
pub const CAMERA_NAME_SIZE: usize = vrsync_transport::CAMERA_NAME_LEN + 1;

/// Size of a channel (`[[agent.vector]]`, `[[agent.action]]`) name field: up to 16 bytes of
/// UTF-8 and a terminating NUL, as a camera name ([`c_name`](crate::c_name) writes both).
///
/// cbindgen:ignore
pub const CHANNEL_NAME_SIZE: usize = vrsync_transport::CHANNEL_NAME_LEN + 1;

const _: () = assert!(CHANNEL_NAME_SIZE == CAMERA_NAME_SIZE);

/// Body pose: position in metres, orientation as a unit quaternion `[x, y, z, w]`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct vrs_pose_t {
    /// Position `[x, y, z]` in metres (world frame: x right, y up, z forward).
    pub position: [f32; 3],
    /// Orientation quaternion `[x, y, z, w]` (Unity's `Quaternion` has the same order).
    /// A host that publishes all zeros (a zero-initialised struct) sends the identity.
    pub rotation: [f32; 4],
}

/// The identity pose at the origin.
impl Default for vrs_pose_t {
    fn default() -> Self {
        Self {
            position: [0.0; 3],
            rotation: [0.0, 0.0, 0.0, 1.0],
        }
    }
}

impl From<Pose> for vrs_pose_t {
    fn from(p: Pose) -> Self {
        Self {
            position: p.position,
            rotation: p.rotation,
        }
    }
}

impl From<vrs_pose_t> for Pose {
    /// All zeros, a zero-initialised struct (C `{0}`, C# `default`), has no valid
    /// rotation, and agents would compute NaN headings from it: it becomes the identity.
    fn from(p: vrs_pose_t) -> Self {
        let rotation = if p.rotation == [0.0; 4] {
            [0.0, 0.0, 0.0, 1.0]
        } else {
            p.rotation
        };
        Self {
            position: p.position,
            rotation,
        }
    }
}

/// Grid position sensor (the original `MsgGridPosition`).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct vrs_grid_position_t {
    /// Position in metres.
    pub position: [f32; 3],
    /// Euler rotation in degrees (x, y, z).
    pub rotation_deg: [f32; 3],
}

/// Head motion sensor (the original `MsgHeadMotion`).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct vrs_head_motion_t {
    /// Velocity in metres per second.
    pub velocity: [f32; 3],
    /// Acceleration in metres per second squared.
    pub acceleration: [f32; 3],
    /// Angular velocity in degrees per second.
    pub angular_velocity_deg: [f32; 3],
    /// Angular acceleration in degrees per second squared.
    pub angular_acceleration_deg: [f32; 3],
}

/// Eye position sensor (the original `MsgEyePosition`).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct vrs_eye_position_t {
    /// Eye rotation in degrees: pan left, pan right, tilt.
    pub rotation_deg: [f32; 3],
    /// Change of the eye rotation per cycle, degrees.
    pub rotation_velocity_deg: [f32; 3],
}

/// One action status: the state of the agent's action `action_id`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct vrs_action_status_t {
    /// The action id of the command (the one its send returned or was given).
    pub action_id: u32,
    /// An action state value (`vrs_action_state_t` in `vrsync.h`,
    /// `vrs_host_action_state_t` in `vrsync_host.h`: the same numbers).
    pub state: u32,
}

/// One collision.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct vrs_collision_t {
    /// The action that was running.
    pub action_id: u32,
    /// The object (or wall) that was hit.
    pub collider_id: u32,
}

/// `From` both ways between a C struct and the wire struct with the same fields (and
/// `zeroed` wire-only fields, zero from C): one list of fields per pair.
macro_rules! mirror {
    ($c:ident <=> $wire:ident { $($field:ident),+ } $(zeroed { $($zero:ident),+ })?) => {
        impl From<$wire> for $c {
            fn from(w: $wire) -> Self {
                Self { $($field: w.$field),+ }
            }
        }

        impl From<&$wire> for $c {
            fn from(w: &$wire) -> Self {
                Self::from(*w)
            }
        }

        impl From<$c> for $wire {
            fn from(c: $c) -> Self {
                Self { $($field: c.$field,)+ $($($zero: 0,)+)? }
            }
        }
    };
}

mirror!(vrs_grid_position_t <=> GridPosition { position, rotation_deg });
mirror!(vrs_head_motion_t <=> HeadMotion {
    velocity,
    acceleration,
    angular_velocity_deg,
    angular_acceleration_deg
});
mirror!(vrs_eye_position_t <=> EyePosition { rotation_deg, rotation_velocity_deg });
mirror!(vrs_action_status_t <=> ActionStatus { action_id, state } zeroed { seq });
mirror!(vrs_collision_t <=> Collision { action_id, collider_id } zeroed { seq });

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_zero_rotation_becomes_the_identity_on_the_wire() {
        let zero = vrs_pose_t {
            position: [1.0, 2.0, 3.0],
            rotation: [0.0; 4],
        };
        let wire = Pose::from(zero);
        assert_eq!(wire.rotation, [0.0, 0.0, 0.0, 1.0]);
        assert_eq!(vrs_pose_t::from(wire).position, [1.0, 2.0, 3.0]);
        let status = ActionStatus::from(vrs_action_status_t {
            action_id: 7,
            state: 3,
        });
        assert_eq!(vrs_action_status_t::from(&status).action_id, 7);
    }
}
