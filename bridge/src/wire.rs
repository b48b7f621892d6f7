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

use core::mem::{align_of, offset_of, size_of};

use glam::{Quat, Vec3};
use iceoryx2::prelude::ZeroCopySend;
use zerocopy::{FromBytes, Immutable, IntoBytes, KnownLayout};

/// Version of the vrsync protocol. Bumped on every incompatible change of the wire types
/// or of the cycle semantics.
pub const PROTOCOL_VERSION: u32 = 2;

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
        let mut name = [0u8; CAMERA_NAME_LEN];
        let n = cam_name.len().min(CAMERA_NAME_LEN);
        name[..n].copy_from_slice(&cam_name.as_bytes()[..n]);
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
        let end = self
            .name
            .iter()
            .position(|&b| b == 0)
            .unwrap_or(CAMERA_NAME_LEN);
        core::str::from_utf8(&self.name[..end]).unwrap_or("")
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
#[type_name("vrsync::SensorHeader/v2")]
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

/// Motor header flag: this batch ends the agent's cycle (the *stop*).
pub const MOTOR_FLAG_STOP: u32 = 1;
/// Motor header flag: [`MotorHeader::ack_cycle`] is valid.
pub const MOTOR_FLAG_ACK: u32 = 2;
/// Motor header flag: the agent leaves the session now (a graceful leave: `Agent::close`
/// or drop). The batch carries no commands; its `cycle` is the newest the agent saw. The
/// host stops waiting for it at once and frees its id for a new connection. (Hosts that
/// predate the flag ignore it and notice the closed connection instead: no protocol
/// version change.)
pub const MOTOR_FLAG_LEAVE: u32 = 4;

/// Header of a motor batch: the iceoryx2 user header of an `agent/<id>/motor` sample whose
/// payload is `[MotorCommand]`.
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
#[type_name("vrsync::MotorHeader/v2")]
pub struct MotorHeader {
    /// [`PROTOCOL_VERSION`] of the writer.
    pub protocol_version: u32,
    /// The sending agent.
    pub agent_id: u32,
    /// The cycle these commands answer (the `cycle` of the sensor frame they were computed from).
    pub cycle: u64,
    /// `MOTOR_FLAG_*` bits.
    pub flags: u32,
    /// Number of commands in the payload.
    pub command_count: u32,
    /// With [`MOTOR_FLAG_ACK`]: the newest cycle whose sensor frame the agent has read. The
    /// host stops repeating the events that frame (or an earlier one) carried, and counts
    /// the frame as read. Valid in any batch, also a late one. A transport that reads every
    /// frame for its agent (one that does not skip) may set it for the agent.
    pub ack_cycle: u64,
}

impl MotorHeader {
    /// Whether this batch carries the stop.
    pub fn is_stop(&self) -> bool {
        self.flags & MOTOR_FLAG_STOP != 0
    }

    /// Whether the agent leaves with this batch ([`MOTOR_FLAG_LEAVE`]).
    pub fn is_leave(&self) -> bool {
        self.flags & MOTOR_FLAG_LEAVE != 0
    }

    /// The acknowledged cycle, if the batch carries one.
    pub fn acknowledged(&self) -> Option<u64> {
        (self.flags & MOTOR_FLAG_ACK != 0).then_some(self.ack_cycle)
    }
}

/// Wire tags of [`MotorCommand::kind`].
pub mod kind {
    /// Walk `args[0]` degrees heading (world frame, 0..360) for `args[1]` metres.
    pub const MOVE: u32 = 1;
    /// Turn by `args[0]` degrees (clockwise, relative).
    pub const TURN: u32 = 2;
    /// Walk straight to `args[0..3]` (world position).
    pub const MOVE_TO: u32 = 3;
    /// Cancel the running movement.
    pub const CANCEL_MOVE: u32 = 4;
    /// Eye movement: pan left `args[0]`, pan right `args[1]`, tilt `args[2]` degrees.
    pub const EYE_MOVEMENT: u32 = 5;
    /// Fixate both eyes on the world point `args[0..3]`.
    pub const EYE_FIXATION: u32 = 6;
    /// Grasp the object `object_id`.
    pub const GRASP_ID: u32 = 7;
    /// Grasp what is seen at left-eye pixel (`args[0]`, `args[1]`).
    pub const GRASP_POS: u32 = 8;
    /// Point at the object `object_id`.
    pub const POINT_ID: u32 = 9;
    /// Point at left-eye pixel (`args[0]`, `args[1]`).
    pub const POINT_POS: u32 = 10;
    /// Interact with the object `object_id`.
    pub const INTERACT_ID: u32 = 11;
    /// Interact with what is seen at left-eye pixel (`args[0]`, `args[1]`).
    pub const INTERACT_POS: u32 = 12;
    /// Release the grasped object.
    pub const GRASP_RELEASE: u32 = 13;
    /// Reset the environment (`object_id` = reset type).
    pub const ENVIRONMENT_RESET: u32 = 14;
    /// Reset the trial (`object_id` = reset type).
    pub const TRIAL_RESET: u32 = 15;
}

/// One motor command on the wire: a tag, the agent's action id and the arguments.
///
/// Use [`Command`] to build and read it: [`Command::encode`] / [`MotorCommand::decode`].
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
#[type_name("vrsync::MotorCommand/v1")]
pub struct MotorCommand {
    /// One of the [`kind`] tags.
    pub kind: u32,
    /// Action id chosen by the agent; echoed in statuses and collisions.
    pub action_id: u32,
    /// Object id or reset type, for the kinds that take one.
    pub object_id: u32,
    /// Reserved, zero.
    pub reserved: u32,
    /// Float arguments, meaning per kind.
    pub args: [f32; 4],
}

/// A motor command, typed. The catalogue follows the original system's messages.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Command {
    /// Walk towards `heading_deg` (world frame, 0..360) for `distance` metres.
    Move {
        /// Heading in degrees, world frame.
        heading_deg: f32,
        /// Distance in metres.
        distance: f32,
    },
    /// Turn in place by `angle_deg` (positive = clockwise seen from above).
    Turn {
        /// Relative angle in degrees.
        angle_deg: f32,
    },
    /// Walk in a straight line to a world position.
    MoveTo {
        /// Target position in metres.
        target: Vec3,
    },
    /// Cancel the running movement.
    CancelMove,
    /// Move the eyes.
    EyeMovement {
        /// Pan of the left eye, degrees.
        pan_left_deg: f32,
        /// Pan of the right eye, degrees.
        pan_right_deg: f32,
        /// Tilt of both eyes, degrees.
        tilt_deg: f32,
    },
    /// Fixate a world point with both eyes.
    EyeFixation {
        /// Point in metres.
        target: Vec3,
    },
    /// Grasp an object by id.
    GraspId {
        /// Object id.
        object_id: u32,
    },
    /// Grasp what is seen at a left-eye pixel (0/0 = top left).
    GraspPos {
        /// Column in pixels.
        x_px: f32,
        /// Row in pixels.
        y_px: f32,
    },
    /// Point at an object by id.
    PointId {
        /// Object id.
        object_id: u32,
    },
    /// Point at what is seen at a left-eye pixel.
    PointPos {
        /// Column in pixels.
        x_px: f32,
        /// Row in pixels.
        y_px: f32,
    },
    /// Interact with an object by id.
    InteractId {
        /// Object id.
        object_id: u32,
    },
    /// Interact with what is seen at a left-eye pixel.
    InteractPos {
        /// Column in pixels.
        x_px: f32,
        /// Row in pixels.
        y_px: f32,
    },
    /// Release the grasped object.
    GraspRelease,
    /// Reset the environment.
    EnvironmentReset {
        /// Reset type (0 = default).
        reset_type: u32,
    },
    /// Reset the trial.
    TrialReset {
        /// Reset type (0 = default).
        reset_type: u32,
    },
}

/// A [`MotorCommand`] that does not decode to a [`Command`].
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum CommandDecodeError {
    /// The tag is not one of [`kind`].
    #[error("unknown command kind {kind} (action id {action_id})")]
    UnknownKind {
        /// The tag found.
        kind: u32,
        /// The action id of the command.
        action_id: u32,
    },
    /// An argument is NaN or infinite.
    #[error("command kind {kind} (action id {action_id}) has a non-finite argument {index}")]
    NonFinite {
        /// The tag.
        kind: u32,
        /// The action id of the command.
        action_id: u32,
        /// Index of the bad argument.
        index: usize,
    },
}

impl Command {
    /// The wire tag of this command.
    pub fn kind(&self) -> u32 {
        match self {
            Self::Move { .. } => kind::MOVE,
            Self::Turn { .. } => kind::TURN,
            Self::MoveTo { .. } => kind::MOVE_TO,
            Self::CancelMove => kind::CANCEL_MOVE,
            Self::EyeMovement { .. } => kind::EYE_MOVEMENT,
            Self::EyeFixation { .. } => kind::EYE_FIXATION,
            Self::GraspId { .. } => kind::GRASP_ID,
            Self::GraspPos { .. } => kind::GRASP_POS,
            Self::PointId { .. } => kind::POINT_ID,
            Self::PointPos { .. } => kind::POINT_POS,
            Self::InteractId { .. } => kind::INTERACT_ID,
            Self::InteractPos { .. } => kind::INTERACT_POS,
            Self::GraspRelease => kind::GRASP_RELEASE,
            Self::EnvironmentReset { .. } => kind::ENVIRONMENT_RESET,
            Self::TrialReset { .. } => kind::TRIAL_RESET,
        }
    }

    /// A short lowercase name, for logs and recordings.
    pub fn name(&self) -> &'static str {
        kind_name(self.kind())
    }

    /// Encodes this command with the given action id.
    pub fn encode(&self, action_id: u32) -> MotorCommand {
        let mut m = MotorCommand {
            kind: self.kind(),
            action_id,
            ..MotorCommand::default()
        };
        match *self {
            Self::Move {
                heading_deg,
                distance,
            } => m.args[..2].copy_from_slice(&[heading_deg, distance]),
            Self::Turn { angle_deg } => m.args[0] = angle_deg,
            Self::MoveTo { target } | Self::EyeFixation { target } => {
                m.args[..3].copy_from_slice(&target.to_array())
            }
            Self::EyeMovement {
                pan_left_deg,
                pan_right_deg,
                tilt_deg,
            } => m.args[..3].copy_from_slice(&[pan_left_deg, pan_right_deg, tilt_deg]),
            Self::GraspId { object_id }
            | Self::PointId { object_id }
            | Self::InteractId { object_id } => m.object_id = object_id,
            Self::GraspPos { x_px, y_px }
            | Self::PointPos { x_px, y_px }
            | Self::InteractPos { x_px, y_px } => m.args[..2].copy_from_slice(&[x_px, y_px]),
            Self::EnvironmentReset { reset_type } | Self::TrialReset { reset_type } => {
                m.object_id = reset_type
            }
            Self::CancelMove | Self::GraspRelease => {}
        }
        m
    }
}

/// The lowercase name of a wire tag (`"unknown"` for unknown tags).
pub fn kind_name(tag: u32) -> &'static str {
    match tag {
        kind::MOVE => "move",
        kind::TURN => "turn",
        kind::MOVE_TO => "move_to",
        kind::CANCEL_MOVE => "cancel_move",
        kind::EYE_MOVEMENT => "eye_movement",
        kind::EYE_FIXATION => "eye_fixation",
        kind::GRASP_ID => "grasp_id",
        kind::GRASP_POS => "grasp_pos",
        kind::POINT_ID => "point_id",
        kind::POINT_POS => "point_pos",
        kind::INTERACT_ID => "interact_id",
        kind::INTERACT_POS => "interact_pos",
        kind::GRASP_RELEASE => "grasp_release",
        kind::ENVIRONMENT_RESET => "environment_reset",
        kind::TRIAL_RESET => "trial_reset",
        _ => "unknown",
    }
}

impl MotorCommand {
    /// Decodes the typed command. Unknown tags and non-finite arguments are errors;
    /// range checks belong to the simulator, which knows its world.
    ///
    /// # Errors
    /// [`CommandDecodeError`] naming the tag, the action id and what is wrong.
    pub fn decode(&self) -> Result<Command, CommandDecodeError> {
        let used = match self.kind {
            kind::MOVE | kind::GRASP_POS | kind::POINT_POS | kind::INTERACT_POS => 2,
            kind::TURN => 1,
            kind::MOVE_TO | kind::EYE_MOVEMENT | kind::EYE_FIXATION => 3,
            kind::CANCEL_MOVE
            | kind::GRASP_ID
            | kind::POINT_ID
            | kind::INTERACT_ID
            | kind::GRASP_RELEASE
            | kind::ENVIRONMENT_RESET
            | kind::TRIAL_RESET => 0,
            other => {
                return Err(CommandDecodeError::UnknownKind {
                    kind: other,
                    action_id: self.action_id,
                });
            }
        };
        if let Some(index) = self.args[..used].iter().position(|a| !a.is_finite()) {
            return Err(CommandDecodeError::NonFinite {
                kind: self.kind,
                action_id: self.action_id,
                index,
            });
        }
        let a = self.args;
        Ok(match self.kind {
            kind::MOVE => Command::Move {
                heading_deg: a[0],
                distance: a[1],
            },
            kind::TURN => Command::Turn { angle_deg: a[0] },
            kind::MOVE_TO => Command::MoveTo {
                target: Vec3::new(a[0], a[1], a[2]),
            },
            kind::CANCEL_MOVE => Command::CancelMove,
            kind::EYE_MOVEMENT => Command::EyeMovement {
                pan_left_deg: a[0],
                pan_right_deg: a[1],
                tilt_deg: a[2],
            },
            kind::EYE_FIXATION => Command::EyeFixation {
                target: Vec3::new(a[0], a[1], a[2]),
            },
            kind::GRASP_ID => Command::GraspId {
                object_id: self.object_id,
            },
            kind::GRASP_POS => Command::GraspPos {
                x_px: a[0],
                y_px: a[1],
            },
            kind::POINT_ID => Command::PointId {
                object_id: self.object_id,
            },
            kind::POINT_POS => Command::PointPos {
                x_px: a[0],
                y_px: a[1],
            },
            kind::INTERACT_ID => Command::InteractId {
                object_id: self.object_id,
            },
            kind::INTERACT_POS => Command::InteractPos {
                x_px: a[0],
                y_px: a[1],
            },
            kind::GRASP_RELEASE => Command::GraspRelease,
            kind::ENVIRONMENT_RESET => Command::EnvironmentReset {
                reset_type: self.object_id,
            },
            // The only tag left after the check above.
            _ => Command::TrialReset {
                reset_type: self.object_id,
            },
        })
    }
}

// Compile-time layout checks: a change here is a protocol change.
const _: () = {
    assert!(size_of::<Pose>() == 28 && align_of::<Pose>() == 4);
    assert!(size_of::<GridPosition>() == 24);
    assert!(size_of::<HeadMotion>() == 48);
    assert!(size_of::<EyePosition>() == 24);
    assert!(size_of::<ActionStatus>() == 16 && align_of::<ActionStatus>() == 8);
    assert!(size_of::<Collision>() == 16 && align_of::<Collision>() == 8);
    assert!(size_of::<ImageDesc>() == 56 && align_of::<ImageDesc>() == 8);
    assert!(size_of::<SensorHeader>() == 784 && align_of::<SensorHeader>() == 8);
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

const fn layout_hash() -> u64 {
    let items: [usize; 47] = [
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

#[cfg(test)]
mod tests {
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
}
