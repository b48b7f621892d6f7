//! The types of the agent C ABI: constants, status codes, enums and the `#[repr(C)]`
//! structs that cross the boundary (declared in `include/vrsync.h`).

use std::ffi::c_char;

/// The sensor structs both C ABIs share (`vrsync_cabi::sensors`).
pub use vrsync_cabi::{
    vrs_action_status_t, vrs_collision_t, vrs_eye_position_t, vrs_grid_position_t,
    vrs_head_motion_t, vrs_pose_t,
};
use vrsync_transport::PixelFormat;

// For the doc links only (the header keeps the `[`name`]` text).
#[cfg(doc)]
use super::{
    vrs_agent_collision, vrs_agent_image, vrs_agent_send, vrs_agent_status, vrs_last_error_message,
};

/// Most images (cameras) in one frame.
pub const VRS_MAX_IMAGES: usize = 4;
/// Most action statuses in one frame.
pub const VRS_MAX_STATUSES: usize = 16;
/// Most collisions in one frame.
pub const VRS_MAX_COLLISIONS: usize = 8;
/// Size of [`vrs_image_t::name`]: a camera name of up to 16 bytes and its terminating NUL.
pub const VRS_CAMERA_NAME_SIZE: usize = 17;
/// Most vectors (`[[agent.vector]]`) per agent.
pub const VRS_MAX_VECTORS: usize = 8;
/// Most actions (`[[agent.action]]`) per agent.
pub const VRS_MAX_ACTIONS: usize = 8;
/// Size of a channel name field (`vrs_vector_t::name`, …): a vector or action name of up to
/// 16 bytes and its terminating NUL.
pub const VRS_CHANNEL_NAME_SIZE: usize = 17;

const _: () = {
    assert!(VRS_MAX_IMAGES == vrsync_transport::MAX_CAMERAS);
    assert!(VRS_MAX_STATUSES == vrsync_transport::MAX_STATUSES);
    assert!(VRS_MAX_COLLISIONS == vrsync_transport::MAX_COLLISIONS);
    assert!(VRS_CAMERA_NAME_SIZE == vrsync_cabi::CAMERA_NAME_SIZE);
    assert!(VRS_MAX_VECTORS == vrsync_transport::MAX_VECTORS);
    assert!(VRS_MAX_ACTIONS == vrsync_transport::MAX_ACTIONS);
    assert!(VRS_CHANNEL_NAME_SIZE == vrsync_cabi::CHANNEL_NAME_SIZE);
};

/// Result of a call: 0 is success, positive values are outcomes that are not errors,
/// negative values are errors (details in [`vrs_last_error_message`]).
#[repr(i32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum vrs_status_t {
    /// Success.
    VRS_OK = 0,
    /// No new frame before the timeout (`vrs_agent_wait_start`); poll again.
    VRS_TIMEOUT = 1,
    /// The host closed the session: the run is over (a clean end).
    VRS_SESSION_CLOSED = 2,
    /// A pointer argument is null or an argument is out of its domain (NaN, not UTF-8, …).
    VRS_ERROR_INVALID_ARGUMENT = -1,
    /// The agent handle is null, unknown, or was already disconnected.
    VRS_ERROR_INVALID_HANDLE = -2,
    /// The agent handle belongs to another thread.
    VRS_ERROR_WRONG_THREAD = -3,
    /// The config file could not be read or is invalid.
    VRS_ERROR_CONFIG = -4,
    /// Connecting failed (no host, protocol mismatch, agent id already in use, …).
    VRS_ERROR_CONNECT = -5,
    /// The host is gone without closing the session (its process died, or the link broke).
    VRS_ERROR_HOST_GONE = -6,
    /// The host sent a frame that violates the protocol.
    VRS_ERROR_PROTOCOL = -7,
    /// There is no current frame (before the first wait, or after stop).
    VRS_ERROR_NO_FRAME = -8,
    /// An index is past the end of its table (image, status, collision, vector, action).
    VRS_ERROR_OUT_OF_RANGE = -9,
    /// More commands in this cycle than the config's `max_commands_per_cycle` (a
    /// continuous action takes one entry per 4 values, a discrete one entry).
    VRS_ERROR_QUEUE_FULL = -10,
    /// This cycle was already stopped.
    VRS_ERROR_ALREADY_STOPPED = -11,
    /// The transport failed.
    VRS_ERROR_TRANSPORT = -12,
    /// SIGINT or SIGTERM arrived: the program should end.
    VRS_ERROR_TERMINATED = -13,
    /// No vector or action of that name in this agent's config (the message lists those
    /// it has).
    VRS_ERROR_UNKNOWN_CHANNEL = -14,
    /// A continuous action's value has the wrong number of floats.
    VRS_ERROR_WRONG_LENGTH = -15,
    /// A continuous action's value is outside its bounds, or not finite.
    VRS_ERROR_OUT_OF_BOUNDS = -16,
    /// A discrete action's choice is not below its `n`.
    VRS_ERROR_CHOICE_OUT_OF_RANGE = -17,
    /// A discrete action was given floats (`vrs_agent_act`), or a continuous one a choice
    /// (`vrs_agent_act_discrete`).
    VRS_ERROR_WRONG_ACTION_KIND = -18,
    /// Something not covered above (see the message).
    VRS_ERROR_OTHER = -98,
    /// A bug: the library panicked (see the message).
    VRS_ERROR_PANIC = -99,
}

/// Pixel format of an image (the values of the wire format).
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum vrs_pixel_format_t {
    /// 8-bit red, green, blue: 3 bytes per pixel.
    VRS_PIXEL_FORMAT_RGB8 = 0,
    /// 8-bit red, green, blue, alpha: 4 bytes per pixel.
    VRS_PIXEL_FORMAT_RGBA8 = 1,
    /// 8-bit grey: 1 byte per pixel.
    VRS_PIXEL_FORMAT_GRAY8 = 2,
    /// 32-bit float depth in metres, native endian: 4 bytes per pixel.
    VRS_PIXEL_FORMAT_DEPTH32F = 3,
}

impl From<PixelFormat> for vrs_pixel_format_t {
    fn from(f: PixelFormat) -> Self {
        match f {
            PixelFormat::Rgb8 => Self::VRS_PIXEL_FORMAT_RGB8,
            PixelFormat::Rgba8 => Self::VRS_PIXEL_FORMAT_RGBA8,
            PixelFormat::Gray8 => Self::VRS_PIXEL_FORMAT_GRAY8,
            PixelFormat::Depth32f => Self::VRS_PIXEL_FORMAT_DEPTH32F,
        }
    }
}

/// Execution state of an action (the values of the original `MsgActionExecutationStatus`).
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum vrs_action_state_t {
    /// Accepted, not finished yet.
    VRS_ACTION_IN_EXECUTION = 0,
    /// Completed.
    VRS_ACTION_FINISHED = 1,
    /// Cancelled, replaced by a newer action, or impossible.
    VRS_ACTION_ABORTED = 2,
    /// A movement is walking.
    VRS_ACTION_WALKING = 3,
    /// A movement is rotating.
    VRS_ACTION_ROTATING = 4,
    /// A movement is walking and rotating.
    VRS_ACTION_WALKING_ROTATING = 5,
}

/// How the agent's previous cycle ended ([`vrs_frame_t::previous_outcome`]).
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum vrs_outcome_t {
    /// No previous cycle (first frame), or async mode.
    VRS_OUTCOME_NONE = 0,
    /// The stop arrived in time.
    VRS_OUTCOME_STOPPED = 1,
    /// The host's stop timeout ended the cycle before the stop arrived.
    VRS_OUTCOME_TIMED_OUT = 2,
}

/// Motor command kinds ([`vrs_command_t::kind`]); the values of the wire format.
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum vrs_command_kind_t {
    /// Walk `args[0]` degrees heading (world frame) for `args[1]` metres.
    VRS_COMMAND_MOVE = 1,
    /// Turn by `args[0]` degrees (clockwise seen from above, relative).
    VRS_COMMAND_TURN = 2,
    /// Walk straight to the world position `args[0..3]`.
    VRS_COMMAND_MOVE_TO = 3,
    /// Cancel the running movement.
    VRS_COMMAND_CANCEL_MOVE = 4,
    /// Eyes: pan left `args[0]`, pan right `args[1]`, tilt `args[2]` degrees.
    VRS_COMMAND_EYE_MOVEMENT = 5,
    /// Fixate both eyes on the world point `args[0..3]`.
    VRS_COMMAND_EYE_FIXATION = 6,
    /// Grasp the object `object_id`.
    VRS_COMMAND_GRASP_ID = 7,
    /// Grasp what is seen at left-eye pixel (`args[0]`, `args[1]`).
    VRS_COMMAND_GRASP_POS = 8,
    /// Point at the object `object_id`.
    VRS_COMMAND_POINT_ID = 9,
    /// Point at left-eye pixel (`args[0]`, `args[1]`).
    VRS_COMMAND_POINT_POS = 10,
    /// Interact with the object `object_id`.
    VRS_COMMAND_INTERACT_ID = 11,
    /// Interact with what is seen at left-eye pixel (`args[0]`, `args[1]`).
    VRS_COMMAND_INTERACT_POS = 12,
    /// Release the grasped object.
    VRS_COMMAND_GRASP_RELEASE = 13,
    /// Reset the environment (`object_id` = reset type).
    VRS_COMMAND_ENVIRONMENT_RESET = 14,
    /// Reset the trial (`object_id` = reset type).
    VRS_COMMAND_TRIAL_RESET = 15,
}

// Every constant of `vrs_command_kind_t` and `vrs_action_state_t` is checked against the
// protocol's catalogue (`CommandKind::ALL`, `ActionState::ALL`), name and value, through the
// header these enums generate: bridge/ffi/tests/command_catalogue.rs.
const _: () = {
    assert!(vrs_pixel_format_t::VRS_PIXEL_FORMAT_DEPTH32F as u32 == PixelFormat::Depth32f as u32);
};

/// Opaque agent handle (see the module documentation: it is a registry key, not memory).
pub struct vrs_agent_t {
    _private: [u8; 0],
}

/// The scalar sensor data of a frame (everything but images, statuses and collisions,
/// which have their own accessors).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct vrs_frame_t {
    /// Cycle number; the stop answers it.
    pub cycle: u64,
    /// Simulated time at the start of this cycle, in nanoseconds.
    pub sim_time_ns: u64,
    /// The agent this frame is for.
    pub agent_id: u32,
    /// Whether the host runs in sync (lock-step) mode.
    pub sync_mode: bool,
    /// Number of images ([`vrs_agent_image`] indices `0..image_count`).
    pub image_count: u32,
    /// Number of action statuses ([`vrs_agent_status`]).
    pub status_count: u32,
    /// Number of collisions ([`vrs_agent_collision`]).
    pub collision_count: u32,
    /// Body pose.
    pub pose: vrs_pose_t,
    /// Reward received since the previous frame.
    pub reward: f32,
    /// Grid position sensor.
    pub grid: vrs_grid_position_t,
    /// Head motion sensor.
    pub head_motion: vrs_head_motion_t,
    /// Eye position sensor.
    pub eye: vrs_eye_position_t,
    /// How this agent's previous cycle ended.
    pub previous_outcome: vrs_outcome_t,
    /// How many of this agent's commands the host rejected in the previous cycle.
    pub previous_rejected: u32,
    /// Frames this agent never saw because a newer one arrived first (total so far).
    pub frames_skipped: u64,
}

/// One image of the current frame: a view into shared memory, no copy. Rows are
/// `stride` bytes apart, origin top-left.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct vrs_image_t {
    /// First byte of the first row. Valid until the next wait, stop or disconnect.
    pub data: *const u8,
    /// Number of bytes at `data` (`stride * height`).
    pub len: usize,
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Bytes per row.
    pub stride: usize,
    /// Pixel format.
    pub format: vrs_pixel_format_t,
    /// Index of the camera in the agent's camera list.
    pub camera: u32,
    /// Camera name, NUL-terminated (`left`, `right`, …).
    pub name: [c_char; VRS_CAMERA_NAME_SIZE],
}

/// A motor command for [`vrs_agent_send`]: a [`vrs_command_kind_t`] and its arguments
/// (see each kind for the meaning of `object_id` and `args`; unused fields are ignored).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct vrs_command_t {
    /// A `vrs_command_kind_t` value.
    pub kind: u32,
    /// Object id or reset type, for the kinds that take one.
    pub object_id: u32,
    /// Float arguments.
    pub args: [f32; 4],
}
