//! Wire types: the `#[repr(C)]` structures that cross process boundaries.
//!
//! Every type here is plain old data (no pointers, no padding) so that it can live in
//! shared memory (iceoryx2 [`ZeroCopySend`]) and be viewed as bytes on the TCP path
//! ([`zerocopy`] derives). Sizes and alignments are asserted at compile time, and a
//! [`LAYOUT_HASH`] computed from every field offset is published next to
//! [`PROTOCOL_VERSION`] so that a host and an agent built against different layouts
//! refuse each other at connect instead of misreading memory.
//!
//! Units are part of the names: `_ns` nanoseconds, `_deg` degrees, `_px` pixels.
//! Positions are metres in the world frame (x right, y up, z forward), rotations are
//! unit quaternions `[x, y, z, w]` (the `glam` convention).

use glam::{Quat, Vec3};
use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use zerocopy::{FromBytes, Immutable, IntoBytes, KnownLayout};

/// Version of the vrsync protocol. Bumped on every incompatible change of the wire types
/// or of the cycle semantics (4: the network hello carries the agent's channel layout
/// hash, refused at connect with [`crate::record::reject::CHANNELS`] when it differs;
/// 5: shared-memory agents are woken through the session's wake word, a futex word in
/// shared memory, instead of an iceoryx2 event per agent; 6: the host wakes two sleepers
/// and each woken agent passes the wake-up on to two more, so an agent of version 5
/// would leave the others asleep).
pub const PROTOCOL_VERSION: u32 = 6;

/// Maximum number of cameras (images) per agent and sensor frame.
pub const MAX_CAMERAS: usize = 4;
/// Maximum number of action statuses in one sensor frame, and of statuses the host keeps
/// for an agent until it acknowledges them (see [`SensorHeader::statuses`]).
pub const MAX_STATUSES: usize = 16;
/// Maximum number of collisions in one sensor frame, and of collisions the host keeps for
/// an agent until it acknowledges them.
pub const MAX_COLLISIONS: usize = 8;
/// Maximum length of a camera name in bytes (UTF-8, zero padded).
pub const CAMERA_NAME_LEN: usize = 16;
/// Longest accepted TCP access token (`transport.tcp_token`), bytes: it travels in the
/// TCP hello.
pub const MAX_TOKEN: usize = 256;

/// Body pose: position and orientation in the world frame.
#[repr(C)]
#[derive(
    Debug,
    Clone,
    Copy,
    Default,
    PartialEq,
    ZeroCopySend,
    IntoBytes,
    FromBytes,
    Immutable,
    KnownLayout,
)]
#[type_name("vrsync::Pose/v1")]
pub struct Pose {
    /// Position in metres `[x, y, z]`.
    pub position: [f32; 3],
    /// Orientation as a unit quaternion `[x, y, z, w]`.
    pub rotation: [f32; 4],
}

impl Pose {
    /// The identity pose at `position`.
    pub fn from_glam(position: Vec3, rotation: Quat) -> Self {
        Self {
            position: position.to_array(),
            rotation: rotation.to_array(),
        }
    }

    /// Position as a glam vector.
    pub fn position(&self) -> Vec3 {
        Vec3::from_array(self.position)
    }

    /// Orientation as a glam quaternion.
    pub fn rotation(&self) -> Quat {
        Quat::from_array(self.rotation)
    }
}

/// Grid position sensor (the original `MsgGridPosition`): position and Euler rotation.
#[repr(C)]
#[derive(
    Debug,
    Clone,
    Copy,
    Default,
    PartialEq,
    ZeroCopySend,
    IntoBytes,
    FromBytes,
    Immutable,
    KnownLayout,
)]
#[type_name("vrsync::GridPosition/v1")]
pub struct GridPosition {
    /// Position in metres.
    pub position: [f32; 3],
    /// Euler rotation in degrees (x, y, z).
    pub rotation_deg: [f32; 3],
}

/// Head motion sensor (the original `MsgHeadMotion`): differences per cycle.
#[repr(C)]
#[derive(
    Debug,
    Clone,
    Copy,
    Default,
    PartialEq,
    ZeroCopySend,
    IntoBytes,
    FromBytes,
    Immutable,
    KnownLayout,
)]
#[type_name("vrsync::HeadMotion/v1")]
pub struct HeadMotion {
    /// Velocity in metres per second.
    pub velocity: [f32; 3],
    /// Acceleration in metres per second squared.
    pub acceleration: [f32; 3],
    /// Angular velocity in degrees per second (x, y, z).
    pub angular_velocity_deg: [f32; 3],
    /// Angular acceleration in degrees per second squared (x, y, z).
    pub angular_acceleration_deg: [f32; 3],
}

/// Eye position sensor (the original `MsgEyePosition`).
#[repr(C)]
#[derive(
    Debug,
    Clone,
    Copy,
    Default,
    PartialEq,
    ZeroCopySend,
    IntoBytes,
    FromBytes,
    Immutable,
    KnownLayout,
)]
#[type_name("vrsync::EyePosition/v1")]
pub struct EyePosition {
    /// Eye rotation in degrees: pan left, pan right, tilt.
    pub rotation_deg: [f32; 3],
    /// Change of the eye rotation per cycle in degrees.
    pub rotation_velocity_deg: [f32; 3],
}

/// Execution state of an action, keyed by the action id the agent chose.
///
/// The numeric values are those of the original `MsgActionExecutationStatus`.
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ActionState {
    /// Accepted, not finished yet.
    InExecution = 0,
    /// Completed.
    Finished = 1,
    /// Cancelled, replaced by a newer action, or impossible.
    Aborted = 2,
    /// A movement is walking.
    Walking = 3,
    /// A movement is rotating.
    Rotating = 4,
    /// A movement is walking and rotating.
    WalkingRotating = 5,
}

impl ActionState {
    /// Every state, in value order: the list the bindings' copies are checked against
    /// (`bridge/ffi/tests/command_catalogue.rs`).
    pub const ALL: [ActionState; 6] = [
        Self::InExecution,
        Self::Finished,
        Self::Aborted,
        Self::Walking,
        Self::Rotating,
        Self::WalkingRotating,
    ];

    /// Decodes the wire value; `None` for unknown values.
    pub fn from_u32(value: u32) -> Option<Self> {
        Some(match value {
            0 => Self::InExecution,
            1 => Self::Finished,
            2 => Self::Aborted,
            3 => Self::Walking,
            4 => Self::Rotating,
            5 => Self::WalkingRotating,
            _ => return None,
        })
    }
}

/// One action status entry of a sensor frame.
#[repr(C)]
#[derive(
    Debug,
    Clone,
    Copy,
    Default,
    PartialEq,
    ZeroCopySend,
    IntoBytes,
    FromBytes,
    Immutable,
    KnownLayout,
)]
#[type_name("vrsync::ActionStatus/v2")]
pub struct ActionStatus {
    /// The action id the agent sent with the command.
    pub action_id: u32,
    /// An [`ActionState`] as `u32`.
    pub state: u32,
    /// Sequence number of the event (one increasing series per agent, statuses and
    /// collisions together), set by the host's bridge when it publishes the frame; what the
    /// simulator writes here is ignored. The agent SDK hands out each number once.
    pub seq: u64,
}

/// One collision entry of a sensor frame.
#[repr(C)]
#[derive(
    Debug,
    Clone,
    Copy,
    Default,
    PartialEq,
    ZeroCopySend,
    IntoBytes,
    FromBytes,
    Immutable,
    KnownLayout,
)]
#[type_name("vrsync::Collision/v2")]
pub struct Collision {
    /// The action that was running when the collision happened.
    pub action_id: u32,
    /// Id of the object (or wall) that was hit.
    pub collider_id: u32,
    /// Sequence number of the event, as [`ActionStatus::seq`].
    pub seq: u64,
}

/// Pixel format of an image.
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum PixelFormat {
    /// 8-bit red, green, blue (3 bytes per pixel). The default.
    #[default]
    Rgb8 = 0,
    /// 8-bit red, green, blue, alpha (4 bytes per pixel).
    Rgba8 = 1,
    /// 8-bit grey (1 byte per pixel).
    Gray8 = 2,
    /// 32-bit float depth in metres, native endian (4 bytes per pixel).
    Depth32f = 3,
}

impl PixelFormat {
    /// Bytes per pixel.
    pub const fn bytes_per_pixel(self) -> usize {
        match self {
            Self::Rgb8 => 3,
            Self::Rgba8 | Self::Depth32f => 4,
            Self::Gray8 => 1,
        }
    }

    /// Decodes the wire value; `None` for unknown values.
    pub fn from_u32(value: u32) -> Option<Self> {
        Some(match value {
            0 => Self::Rgb8,
            1 => Self::Rgba8,
            2 => Self::Gray8,
            3 => Self::Depth32f,
            _ => return None,
        })
    }

    /// The config spelling (`rgb8`, `rgba8`, `gray8`, `depth32f`).
    pub const fn as_str(self) -> &'static str {
        match self {
            Self::Rgb8 => "rgb8",
            Self::Rgba8 => "rgba8",
            Self::Gray8 => "gray8",
            Self::Depth32f => "depth32f",
        }
    }
}

/// Alignment of every image in a sensor frame's payload, in bytes.
pub const IMAGE_ALIGN: usize = 64;

/// The image table for `cameras`, given as `(name, width_px, height_px, format)` in
/// camera order (at most [`MAX_CAMERAS`] are used), and the total payload size in bytes.
/// Images are packed in camera order, rows without padding, each image starting at a
/// multiple of [`IMAGE_ALIGN`].
pub fn image_layout<'a>(
    cameras: impl IntoIterator<Item = (&'a str, u32, u32, PixelFormat)>,
) -> ([ImageDesc; MAX_CAMERAS], usize) {
    let mut descs = [ImageDesc::default(); MAX_CAMERAS];
    let mut offset = 0usize;
    let mut count = 0;
    for (i, (d, (cam_name, width_px, height_px, format))) in
        descs.iter_mut().zip(cameras).enumerate()
    {
        let name = channels::padded_name(cam_name);
        let stride = width_px as usize * format.bytes_per_pixel();
        let len = stride * height_px as usize;
        *d = ImageDesc {
            name,
            camera: i as u32,
            format: format as u32,
            width_px,
            height_px,
            stride_bytes: stride as u32,
            reserved: 0,
            offset: offset as u64,
            len: len as u64,
        };
        offset = (offset + len).next_multiple_of(IMAGE_ALIGN);
        count = i + 1;
    }
    let total = match count {
        0 => 0,
        n => (descs[n - 1].offset + descs[n - 1].len) as usize,
    };
    (descs, total)
}

/// Where one image lies in the payload of a sensor frame.
///
/// Images are row-major, origin top-left, `stride_bytes` bytes per row.
#[repr(C)]
#[derive(
    Debug,
    Clone,
    Copy,
    Default,
    PartialEq,
    ZeroCopySend,
    IntoBytes,
    FromBytes,
    Immutable,
    KnownLayout,
)]
#[type_name("vrsync::ImageDesc/v1")]
pub struct ImageDesc {
    /// Camera name, UTF-8, zero padded.
    pub name: [u8; CAMERA_NAME_LEN],
    /// Index of the camera in the agent's camera list.
    pub camera: u32,
    /// A [`PixelFormat`] as `u32`.
    pub format: u32,
    /// Width in pixels.
    pub width_px: u32,
    /// Height in pixels.
    pub height_px: u32,
    /// Bytes per row.
    pub stride_bytes: u32,
    /// Reserved, zero.
    pub reserved: u32,
    /// Byte offset of the first row in the payload.
    pub offset: u64,
    /// Length in bytes (`stride_bytes * height_px`).
    pub len: u64,
}

impl ImageDesc {
    /// The camera name as a string (up to the first zero byte; invalid UTF-8 gives `""`).
    pub fn name(&self) -> &str {
        channels::padded_str(&self.name)
    }

    /// The pixel format, `None` if the value is unknown.
    pub fn pixel_format(&self) -> Option<PixelFormat> {
        PixelFormat::from_u32(self.format)
    }
}

/// Sensor header flag: the host runs in sync (lock-step) mode.
pub const SENSOR_FLAG_SYNC_MODE: u32 = 1;

/// Outcome of the agent's previous cycle, as reported in [`SensorHeader::previous_outcome`].
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum WireOutcome {
    /// No previous cycle (first frame) or async mode.
    None = 0,
    /// The agent's stop arrived in time.
    Stopped = 1,
    /// The cycle ended by timeout before the agent's stop arrived.
    TimedOut = 2,
}

/// The fixed-size header of a sensor frame: everything but the images.
///
/// In shared memory this is the iceoryx2 user header of the `agent/<id>/sensors` sample,
/// whose payload is the images described by `images[..image_count]`.
#[repr(C)]
#[derive(
    Debug,
    Clone,
    Copy,
    Default,
    PartialEq,
    ZeroCopySend,
    IntoBytes,
    FromBytes,
    Immutable,
    KnownLayout,
)]
#[type_name("vrsync::SensorHeader/v3")]
pub struct SensorHeader {
    /// [`PROTOCOL_VERSION`] of the writer.
    pub protocol_version: u32,
    /// The agent this frame is for.
    pub agent_id: u32,
    /// Cycle number `f`; the agent's stop must carry it.
    pub cycle: u64,
    /// Simulated time at the start of this cycle, in nanoseconds.
    pub sim_time_ns: u64,
    /// `SENSOR_FLAG_*` bits.
    pub flags: u32,
    /// Number of valid entries in `images`.
    pub image_count: u32,
    /// Body pose of the agent.
    pub pose: Pose,
    /// Reward received since the previous frame.
    pub reward: f32,
    /// Grid position sensor.
    pub grid: GridPosition,
    /// Head motion sensor.
    pub head_motion: HeadMotion,
    /// Eye position sensor.
    pub eye: EyePosition,
    /// Number of valid entries in `statuses`.
    pub status_count: u32,
    /// Number of valid entries in `collisions`.
    pub collision_count: u32,
    /// Action statuses: in the frame the simulator loans, those since the previous frame;
    /// in the frame an agent receives, every status it has not acknowledged yet (see
    /// [`SensorHeader::statuses`]), ascending `seq`.
    pub statuses: [ActionStatus; MAX_STATUSES],
    /// Collisions, like `statuses`.
    pub collisions: [Collision; MAX_COLLISIONS],
    /// Image table.
    pub images: [ImageDesc; MAX_CAMERAS],
    /// A [`WireOutcome`] as `u32`: how this agent's previous cycle ended.
    pub previous_outcome: u32,
    /// Number of this agent's commands the host rejected in the previous cycle.
    pub previous_rejected: u32,
    /// Number of valid entries in `vectors`.
    pub vector_count: u32,
    /// Number of valid entries in `actions`.
    pub action_count: u32,
    /// Vector table: the `[[agent.vector]]` channels in the payload after the images.
    pub vectors: [VectorDesc; MAX_VECTORS],
    /// Action table: the `[[agent.action]]` channels the host expects from the agent.
    pub actions: [ActionDesc; MAX_ACTIONS],
}

impl SensorHeader {
    /// Valid action statuses.
    ///
    /// Written by the simulator: the statuses since the previous frame. As published: the
    /// host's bridge adds the statuses the agent has not acknowledged yet, so a status
    /// arrives in every frame until the agent's batch acknowledges a frame that carried it
    /// ([`MotorHeader::ack_cycle`]); an agent that skips frames misses none. Agents see
    /// repeats here: the agent SDK's frame hands out each event once.
    pub fn statuses(&self) -> &[ActionStatus] {
        &self.statuses[..(self.status_count as usize).min(MAX_STATUSES)]
    }

    /// Valid collisions (repeated until acknowledged, like [`SensorHeader::statuses`]).
    pub fn collisions(&self) -> &[Collision] {
        &self.collisions[..(self.collision_count as usize).min(MAX_COLLISIONS)]
    }

    /// Valid image descriptions.
    pub fn image_descs(&self) -> &[ImageDesc] {
        &self.images[..(self.image_count as usize).min(MAX_CAMERAS)]
    }

    /// Appends an action status; returns `false` (and drops it) when the table is full.
    pub fn push_status(&mut self, action_id: u32, state: ActionState) -> bool {
        let n = self.status_count as usize;
        if n >= MAX_STATUSES {
            return false;
        }
        self.statuses[n] = ActionStatus {
            action_id,
            state: state as u32,
            seq: 0,
        };
        self.status_count += 1;
        true
    }

    /// Appends a collision; returns `false` (and drops it) when the table is full.
    pub fn push_collision(&mut self, action_id: u32, collider_id: u32) -> bool {
        let n = self.collision_count as usize;
        if n >= MAX_COLLISIONS {
            return false;
        }
        self.collisions[n] = Collision {
            action_id,
            collider_id,
            seq: 0,
        };
        self.collision_count += 1;
        true
    }

    /// Whether the host runs in sync mode.
    pub fn sync_mode(&self) -> bool {
        self.flags & SENSOR_FLAG_SYNC_MODE != 0
    }
}

#[macro_use]
mod catalogue;
mod channels;
mod commands;
mod layout;
mod motor;

pub use channels::*;
pub use commands::*;
pub use layout::LAYOUT_HASH;
pub use motor::*;

#[cfg(test)]
mod tests;
