//! The C ABI of the agent SDK: what `include/vrsync.h` declares (generated from this file
//! by cbindgen; `tests::header_is_up_to_date` fails when the two drift apart).
//!
//! Conventions:
//! - Every name starts with `vrs_`; types end in `_t`; the agent is an opaque
//!   `vrs_agent_t*` handle.
//! - Every fallible function returns a [`vrs_status_t`]: `VRS_OK` (0), a positive
//!   non-error outcome (`VRS_TIMEOUT`, `VRS_SESSION_CLOSED`), or a negative error. The text
//!   of the last status of the calling thread is in [`vrs_last_error_message`].
//! - Each `extern "C"` function is a thin wrapper over a Rust `*_impl` function returning a
//!   `Result`; panics are caught at the boundary and reported as `VRS_ERROR_PANIC`.
//!
//! # Handles
//! A `vrs_agent_t*` is **not a pointer to memory**: it carries a number from a counter
//! that is never reused, and the agents live in a registry keyed by that number. The
//! library never dereferences a handle, so a null handle, a handle that was already
//! disconnected (double free) or a made-up value is a `VRS_ERROR_INVALID_HANDLE` with a
//! message, never a crash, and a stale handle can never alias a newer agent. (A magic /
//! tombstone scheme would have to read freed memory to detect a double free.)
//!
//! # Threads
//! The shared-memory ports behind an agent are not thread-safe (iceoryx2 `ipc` ports are
//! neither `Send` nor `Sync`), so an agent belongs to the thread that connected it: the
//! registry is per thread, and a call with the handle from another thread returns
//! `VRS_ERROR_WRONG_THREAD`. Different threads may each run their own agents. An agent
//! still connected when its thread exits is disconnected then.
//!
//! # Frames
//! [`vrs_agent_wait_start`] makes the received frame the agent's *current frame*. Its
//! scalar fields are copied into a [`vrs_frame_t`]; images are read with
//! [`vrs_agent_image`], whose `data` pointers point straight into shared memory (no copy).
//! They stay valid until the next [`vrs_agent_wait_start`] (whatever it returns),
//! [`vrs_agent_stop`] or [`vrs_agent_disconnect`] of that agent.

#![allow(non_camel_case_types)]

use std::cell::RefCell;
use std::collections::{BTreeMap, HashMap};
use std::ffi::{CStr, CString, c_char};
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::thread::ThreadId;
use std::time::Duration;

use vrsync_bridge::{Command, PixelFormat};
use vrsync_bridge::{Config, ConfigLoadError};

use crate::agent::{
    Agent, AgentBuilder, AgentConnectError, Frame, SendError, SignalHandling, StopError,
    WaitStartError,
};

// ---------------------------------------------------------------------------------------
// Constants and types of the ABI
// ---------------------------------------------------------------------------------------

/// Most images (cameras) in one frame.
pub const VRS_MAX_IMAGES: usize = 4;
/// Most action statuses in one frame.
pub const VRS_MAX_STATUSES: usize = 16;
/// Most collisions in one frame.
pub const VRS_MAX_COLLISIONS: usize = 8;
/// Size of [`vrs_image_t::name`]: a camera name of up to 16 bytes and its terminating NUL.
pub const VRS_CAMERA_NAME_SIZE: usize = 17;

const _: () = {
    assert!(VRS_MAX_IMAGES == vrsync_bridge::MAX_CAMERAS);
    assert!(VRS_MAX_STATUSES == vrsync_bridge::MAX_STATUSES);
    assert!(VRS_MAX_COLLISIONS == vrsync_bridge::MAX_COLLISIONS);
    assert!(VRS_CAMERA_NAME_SIZE == vrsync_bridge::CAMERA_NAME_LEN + 1);
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
    /// The host process died without closing the session.
    VRS_ERROR_HOST_GONE = -6,
    /// The host sent a frame that violates the protocol.
    VRS_ERROR_PROTOCOL = -7,
    /// There is no current frame (before the first wait, or after stop).
    VRS_ERROR_NO_FRAME = -8,
    /// An index is past the end of its table (image, status, collision).
    VRS_ERROR_OUT_OF_RANGE = -9,
    /// More commands in this cycle than the config's `max_commands_per_cycle`.
    VRS_ERROR_QUEUE_FULL = -10,
    /// This cycle was already stopped.
    VRS_ERROR_ALREADY_STOPPED = -11,
    /// The transport failed.
    VRS_ERROR_TRANSPORT = -12,
    /// SIGINT or SIGTERM arrived: the program should end.
    VRS_ERROR_TERMINATED = -13,
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

const _: () = {
    assert!(vrs_command_kind_t::VRS_COMMAND_MOVE as u32 == vrsync_bridge::command_kind::MOVE);
    assert!(
        vrs_command_kind_t::VRS_COMMAND_TRIAL_RESET as u32
            == vrsync_bridge::command_kind::TRIAL_RESET
    );
    assert!(vrs_pixel_format_t::VRS_PIXEL_FORMAT_DEPTH32F as u32 == PixelFormat::Depth32f as u32);
};

/// Opaque agent handle (see the module documentation: it is a registry key, not memory).
pub struct vrs_agent_t {
    _private: [u8; 0],
}

/// Body pose: position in metres, orientation as a unit quaternion `[x, y, z, w]`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct vrs_pose_t {
    /// Position `[x, y, z]` in metres (world frame: x right, y up, z forward).
    pub position: [f32; 3],
    /// Orientation quaternion `[x, y, z, w]`.
    pub rotation: [f32; 4],
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

/// One action status: the state of the action the agent sent with `action_id`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct vrs_action_status_t {
    /// The action id returned when the command was queued.
    pub action_id: u32,
    /// A `vrs_action_state_t` value.
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

// ---------------------------------------------------------------------------------------
// Errors
// ---------------------------------------------------------------------------------------

/// Everything a C ABI call can fail with; each maps to one [`vrs_status_t`].
#[derive(Debug, thiserror::Error)]
enum FfiError {
    #[error("{0} must not be null")]
    Null(&'static str),
    #[error("invalid argument: {0}")]
    InvalidArgument(String),
    #[error("invalid agent handle: null")]
    NullHandle,
    #[error("invalid agent handle {0:#x}: not an agent, or already disconnected (double free?)")]
    UnknownHandle(usize),
    #[error(
        "agent handle {0:#x} belongs to another thread: use an agent only on the thread that \
         connected it"
    )]
    WrongThread(usize),
    #[error("the calling thread is exiting; its agents are already disconnected")]
    ThreadExiting,
    #[error(transparent)]
    Config(#[from] ConfigLoadError),
    #[error(transparent)]
    Connect(#[from] AgentConnectError),
    #[error(transparent)]
    Wait(#[from] WaitStartError),
    #[error(transparent)]
    Send(#[from] SendError),
    #[error(transparent)]
    Stop(#[from] StopError),
    #[error(
        "no current frame: call vrs_agent_wait_start first (a frame ends at the next wait, \
         at stop and at disconnect)"
    )]
    NoFrame,
    #[error("{what} index {index} is out of range (the frame has {count})")]
    OutOfRange {
        what: &'static str,
        index: usize,
        count: usize,
    },
    #[error("the current frame has no camera named {0:?}")]
    NoSuchCamera(String),
    #[error("logging is already initialised in this process")]
    LoggingAlreadySet,
    #[error("panic in the vrsync library: {0}")]
    Panic(String),
}

impl FfiError {
    // The wildcard arms keep new variants of the SDK's (non-exhaustive) error enums from
    // breaking the build; they map to VRS_ERROR_OTHER with their message.
    #[allow(unreachable_patterns)]
    fn status(&self) -> vrs_status_t {
        use vrs_status_t::*;
        match self {
            Self::Null(_)
            | Self::InvalidArgument(_)
            | Self::NoSuchCamera(_)
            | Self::LoggingAlreadySet => VRS_ERROR_INVALID_ARGUMENT,
            Self::NullHandle | Self::UnknownHandle(_) | Self::ThreadExiting => {
                VRS_ERROR_INVALID_HANDLE
            }
            Self::WrongThread(_) => VRS_ERROR_WRONG_THREAD,
            Self::Config(_) => VRS_ERROR_CONFIG,
            Self::Connect(_) => VRS_ERROR_CONNECT,
            Self::Wait(e) => match e {
                WaitStartError::Timeout { .. } => VRS_TIMEOUT,
                WaitStartError::HostClosed => VRS_SESSION_CLOSED,
                WaitStartError::HostGone { .. } => VRS_ERROR_HOST_GONE,
                WaitStartError::BadFrame { .. } => VRS_ERROR_PROTOCOL,
                WaitStartError::Receive(_) | WaitStartError::TooManyFramesHeld { .. } => {
                    VRS_ERROR_TRANSPORT
                }
                WaitStartError::Terminated => VRS_ERROR_TERMINATED,
                _ => VRS_ERROR_OTHER,
            },
            Self::Send(e) => match e {
                SendError::QueueFull { .. } => VRS_ERROR_QUEUE_FULL,
                _ => VRS_ERROR_OTHER,
            },
            Self::Stop(e) => match e {
                StopError::NoFrame => VRS_ERROR_NO_FRAME,
                StopError::AlreadyStopped { .. } => VRS_ERROR_ALREADY_STOPPED,
                StopError::HostClosed => VRS_SESSION_CLOSED,
                StopError::Transport(_) => VRS_ERROR_TRANSPORT,
                _ => VRS_ERROR_OTHER,
            },
            Self::NoFrame => VRS_ERROR_NO_FRAME,
            Self::OutOfRange { .. } => VRS_ERROR_OUT_OF_RANGE,
            Self::Panic(_) => VRS_ERROR_PANIC,
        }
    }
}

/// The error and its sources, `: `-separated (what `{:#}` prints with anyhow).
fn chain(e: &dyn std::error::Error) -> String {
    let mut s = e.to_string();
    let mut source = e.source();
    while let Some(inner) = source {
        let text = inner.to_string();
        // `#[error(transparent)]` repeats the source's text; say it once.
        if !s.ends_with(&text) {
            s.push_str(": ");
            s.push_str(&text);
        }
        source = inner.source();
    }
    s
}

thread_local! {
    static LAST_ERROR: RefCell<CString> = RefCell::new(CString::default());
}

fn set_last_error(message: &str) {
    // A message cannot hold NUL bytes in C; cut at the first one.
    let message = message.split('\0').next().unwrap_or_default();
    let c = CString::new(message).unwrap_or_default();
    let _ = LAST_ERROR.try_with(|cell| {
        if let Ok(mut slot) = cell.try_borrow_mut() {
            *slot = c;
        }
    });
}

fn panic_message(payload: Box<dyn std::any::Any + Send>) -> String {
    if let Some(s) = payload.downcast_ref::<&str>() {
        (*s).to_owned()
    } else if let Some(s) = payload.downcast_ref::<String>() {
        s.clone()
    } else {
        "unknown panic payload".to_owned()
    }
}

/// The boundary: runs `f`, catches panics, records the message, returns the status.
fn boundary(f: impl FnOnce() -> Result<(), FfiError>) -> vrs_status_t {
    let result = catch_unwind(AssertUnwindSafe(f))
        .unwrap_or_else(|payload| Err(FfiError::Panic(panic_message(payload))));
    match result {
        Ok(()) => {
            set_last_error("");
            vrs_status_t::VRS_OK
        }
        Err(e) => {
            set_last_error(&chain(&e));
            e.status()
        }
    }
}

// ---------------------------------------------------------------------------------------
// The handle registry
// ---------------------------------------------------------------------------------------

/// One connected agent and its current frame.
struct AgentState {
    handle: usize,
    // Declared before `agent`: the frame's sample is released before the ports.
    frame: Option<Frame>,
    agent: Agent,
}

impl Drop for AgentState {
    fn drop(&mut self) {
        owners().remove(&self.handle);
    }
}

/// The next handle value; never reused, never 0.
static NEXT_HANDLE: AtomicUsize = AtomicUsize::new(1);

/// Which thread owns each live handle (the agents themselves live in `AGENTS`).
static OWNERS: Mutex<BTreeMap<usize, ThreadId>> = Mutex::new(BTreeMap::new());

fn owners() -> std::sync::MutexGuard<'static, BTreeMap<usize, ThreadId>> {
    // The map stays consistent even if a holder panicked: every operation is one call.
    OWNERS
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}

thread_local! {
    static AGENTS: RefCell<HashMap<usize, AgentState>> = RefCell::new(HashMap::new());
}

fn handle_key(handle: *const vrs_agent_t) -> usize {
    handle.addr()
}

fn unknown_handle(key: usize) -> FfiError {
    match owners().get(&key) {
        Some(owner) if *owner != std::thread::current().id() => FfiError::WrongThread(key),
        _ => FfiError::UnknownHandle(key),
    }
}

/// Runs `f` on the agent behind `handle`.
fn with_agent<R>(
    handle: *const vrs_agent_t,
    f: impl FnOnce(&mut AgentState) -> Result<R, FfiError>,
) -> Result<R, FfiError> {
    let key = handle_key(handle);
    if key == 0 {
        return Err(FfiError::NullHandle);
    }
    AGENTS
        .try_with(|agents| {
            let mut agents = agents.borrow_mut();
            match agents.get_mut(&key) {
                Some(state) => f(state),
                None => Err(unknown_handle(key)),
            }
        })
        .unwrap_or(Err(FfiError::ThreadExiting))
}

fn register(state_of: impl FnOnce(usize) -> AgentState) -> Result<usize, FfiError> {
    let key = NEXT_HANDLE.fetch_add(1, Ordering::Relaxed);
    let state = state_of(key);
    owners().insert(key, std::thread::current().id());
    AGENTS
        .try_with(|agents| {
            agents.borrow_mut().insert(key, state);
        })
        .map_err(|_| FfiError::ThreadExiting)?;
    Ok(key)
}

// ---------------------------------------------------------------------------------------
// Helpers
// ---------------------------------------------------------------------------------------

/// Writes `value` through `out` when `out` is not null.
///
/// # Safety
/// `out` is null or valid for writing a `T`.
unsafe fn write_opt<T>(out: *mut T, value: T) {
    if !out.is_null() {
        // SAFETY: non-null and, by the caller's contract, valid for writes.
        unsafe { out.write(value) }
    }
}

/// Writes `value` through `out`, which must not be null.
///
/// # Safety
/// `out` is null or valid for writing a `T`.
unsafe fn write_required<T>(out: *mut T, what: &'static str, value: T) -> Result<(), FfiError> {
    if out.is_null() {
        return Err(FfiError::Null(what));
    }
    // SAFETY: non-null and, by the caller's contract, valid for writes.
    unsafe { out.write(value) };
    Ok(())
}

/// Reads a C string argument as UTF-8.
///
/// # Safety
/// `s` is null or a valid NUL-terminated string.
unsafe fn str_arg<'a>(s: *const c_char, what: &'static str) -> Result<&'a str, FfiError> {
    if s.is_null() {
        return Err(FfiError::Null(what));
    }
    // SAFETY: non-null and NUL-terminated by the caller's contract.
    let c = unsafe { CStr::from_ptr(s) };
    c.to_str()
        .map_err(|e| FfiError::InvalidArgument(format!("{what} is not UTF-8: {e}")))
}

/// A timeout in milliseconds; negative means none.
fn timeout_arg(timeout_ms: i64) -> Option<Duration> {
    u64::try_from(timeout_ms).ok().map(Duration::from_millis)
}

fn frame_info(frame: &Frame, frames_skipped: u64) -> vrs_frame_t {
    let h = frame.header();
    let outcome = match h.previous_outcome {
        1 => vrs_outcome_t::VRS_OUTCOME_STOPPED,
        2 => vrs_outcome_t::VRS_OUTCOME_TIMED_OUT,
        _ => vrs_outcome_t::VRS_OUTCOME_NONE,
    };
    vrs_frame_t {
        cycle: h.cycle,
        sim_time_ns: h.sim_time_ns,
        agent_id: h.agent_id,
        sync_mode: h.sync_mode(),
        image_count: frame.image_count() as u32,
        status_count: frame.statuses().len() as u32,
        collision_count: frame.collisions().len() as u32,
        pose: vrs_pose_t {
            position: h.pose.position,
            rotation: h.pose.rotation,
        },
        reward: h.reward,
        grid: vrs_grid_position_t {
            position: h.grid.position,
            rotation_deg: h.grid.rotation_deg,
        },
        head_motion: vrs_head_motion_t {
            velocity: h.head_motion.velocity,
            acceleration: h.head_motion.acceleration,
            angular_velocity_deg: h.head_motion.angular_velocity_deg,
            angular_acceleration_deg: h.head_motion.angular_acceleration_deg,
        },
        eye: vrs_eye_position_t {
            rotation_deg: h.eye.rotation_deg,
            rotation_velocity_deg: h.eye.rotation_velocity_deg,
        },
        previous_outcome: outcome,
        previous_rejected: h.previous_rejected,
        frames_skipped,
    }
}

fn image_info(frame: &Frame, index: usize) -> Result<vrs_image_t, FfiError> {
    let count = frame.image_count();
    let image = frame.image(index).ok_or(FfiError::OutOfRange {
        what: "image",
        index,
        count,
    })?;
    let mut name = [0 as c_char; VRS_CAMERA_NAME_SIZE];
    for (dst, &src) in name.iter_mut().zip(image.name().as_bytes()) {
        *dst = src as c_char;
    }
    let data = image.data();
    Ok(vrs_image_t {
        data: data.as_ptr(),
        len: data.len(),
        width: image.width(),
        height: image.height(),
        stride: image.stride(),
        format: image.format().into(),
        camera: image.desc().camera,
        name,
    })
}

fn current_frame(state: &AgentState) -> Result<&Frame, FfiError> {
    state.frame.as_ref().ok_or(FfiError::NoFrame)
}

fn command_from(c: &vrs_command_t) -> Result<Command, FfiError> {
    let wire = vrsync_bridge::MotorCommand {
        kind: c.kind,
        object_id: c.object_id,
        args: c.args,
        ..Default::default()
    };
    wire.decode()
        .map_err(|e| FfiError::InvalidArgument(e.to_string()))
}

/// Checks the arguments the way the host will (unknown kinds, NaN and ∞ are refused here,
/// where the caller can still see which call was wrong).
fn checked(command: Command) -> Result<Command, FfiError> {
    command
        .encode(0)
        .decode()
        .map_err(|e| FfiError::InvalidArgument(format!("{}: {e}", command.name())))
}

// ---------------------------------------------------------------------------------------
// Implementations
// ---------------------------------------------------------------------------------------

fn connect_impl(
    config_path: *const c_char,
    agent_id: u32,
    timeout_ms: i64,
    out_agent: *mut *mut vrs_agent_t,
) -> Result<(), FfiError> {
    if out_agent.is_null() {
        return Err(FfiError::Null("out_agent"));
    }
    // SAFETY: checked non-null; valid for writes by the caller's contract. Cleared first
    // so that a failed connect leaves NULL behind.
    unsafe { out_agent.write(std::ptr::null_mut()) };
    // SAFETY: a C string by the caller's contract.
    let path = unsafe { str_arg(config_path, "config_path") }?;
    let config = Config::load(path)?;
    // The C ABI keeps its documented behaviour: SIGINT/SIGTERM end waits with
    // VRS_ERROR_TERMINATED.
    let mut builder = AgentBuilder::new(&config, agent_id).signal_handling(SignalHandling::Install);
    if let Some(t) = timeout_arg(timeout_ms) {
        builder = builder.connect_timeout(t);
    }
    let agent = builder.connect()?;
    let key = register(|handle| AgentState {
        handle,
        frame: None,
        agent,
    })?;
    // SAFETY: as above. The handle is a registry key, never dereferenced.
    unsafe { out_agent.write(std::ptr::without_provenance_mut(key)) };
    Ok(())
}

fn disconnect_impl(agent: *mut vrs_agent_t) -> Result<(), FfiError> {
    let key = handle_key(agent);
    if key == 0 {
        return Err(FfiError::NullHandle);
    }
    let state = AGENTS
        .try_with(|agents| agents.borrow_mut().remove(&key))
        .map_err(|_| FfiError::ThreadExiting)?;
    match state {
        // Dropped outside the registry borrow.
        Some(state) => {
            drop(state);
            Ok(())
        }
        None => Err(unknown_handle(key)),
    }
}

fn wait_start_impl(
    agent: *mut vrs_agent_t,
    timeout_ms: i64,
    out_frame: *mut vrs_frame_t,
) -> Result<(), FfiError> {
    with_agent(agent, |st| {
        // The previous frame ends here, whatever this wait returns.
        st.frame = None;
        // Polling with short timeouts is fine on both transports: `Agent::wait_start`
        // checks the host's liveness every HOST_LIVENESS_PERIOD across calls, and a
        // zero-timeout wait still takes a frame that has already arrived.
        let frame = st.agent.wait_start(timeout_arg(timeout_ms))?;
        // SAFETY: null or writable by the caller's contract.
        unsafe { write_opt(out_frame, frame_info(&frame, st.agent.frames_skipped())) };
        st.frame = Some(frame);
        Ok(())
    })
}

fn frame_impl(agent: *mut vrs_agent_t, out_frame: *mut vrs_frame_t) -> Result<(), FfiError> {
    with_agent(agent, |st| {
        let info = frame_info(current_frame(st)?, st.agent.frames_skipped());
        // SAFETY: null or writable by the caller's contract.
        unsafe { write_required(out_frame, "out_frame", info) }
    })
}

fn image_impl(
    agent: *mut vrs_agent_t,
    index: usize,
    out_image: *mut vrs_image_t,
) -> Result<(), FfiError> {
    with_agent(agent, |st| {
        let info = image_info(current_frame(st)?, index)?;
        // SAFETY: null or writable by the caller's contract.
        unsafe { write_required(out_image, "out_image", info) }
    })
}

fn image_by_name_impl(
    agent: *mut vrs_agent_t,
    name: *const c_char,
    out_image: *mut vrs_image_t,
) -> Result<(), FfiError> {
    with_agent(agent, |st| {
        // SAFETY: a C string by the caller's contract.
        let name = unsafe { str_arg(name, "name") }?;
        let frame = current_frame(st)?;
        let index = (0..frame.image_count())
            .find(|&i| frame.image(i).is_some_and(|img| img.name() == name))
            .ok_or_else(|| FfiError::NoSuchCamera(name.to_owned()))?;
        let info = image_info(frame, index)?;
        // SAFETY: null or writable by the caller's contract.
        unsafe { write_required(out_image, "out_image", info) }
    })
}

fn status_impl(
    agent: *mut vrs_agent_t,
    index: usize,
    out_status: *mut vrs_action_status_t,
) -> Result<(), FfiError> {
    with_agent(agent, |st| {
        let statuses = current_frame(st)?.statuses();
        let s = statuses.get(index).ok_or(FfiError::OutOfRange {
            what: "status",
            index,
            count: statuses.len(),
        })?;
        let value = vrs_action_status_t {
            action_id: s.action_id,
            state: s.state,
        };
        // SAFETY: null or writable by the caller's contract.
        unsafe { write_required(out_status, "out_status", value) }
    })
}

fn collision_impl(
    agent: *mut vrs_agent_t,
    index: usize,
    out_collision: *mut vrs_collision_t,
) -> Result<(), FfiError> {
    with_agent(agent, |st| {
        let collisions = current_frame(st)?.collisions();
        let c = collisions.get(index).ok_or(FfiError::OutOfRange {
            what: "collision",
            index,
            count: collisions.len(),
        })?;
        let value = vrs_collision_t {
            action_id: c.action_id,
            collider_id: c.collider_id,
        };
        // SAFETY: null or writable by the caller's contract.
        unsafe { write_required(out_collision, "out_collision", value) }
    })
}

fn action_state_impl(
    agent: *mut vrs_agent_t,
    action_id: u32,
    out_state: *mut u32,
    out_known: *mut bool,
) -> Result<(), FfiError> {
    with_agent(agent, |st| {
        let state = st.agent.action_state(action_id);
        // SAFETY: null or writable by the caller's contract.
        unsafe {
            write_required(out_known, "out_known", state.is_some())?;
            write_required(out_state, "out_state", state.map_or(0, |s| s as u32))
        }
    })
}

fn send_impl(
    agent: *mut vrs_agent_t,
    command: Result<Command, FfiError>,
    out_action_id: *mut u32,
) -> Result<(), FfiError> {
    with_agent(agent, |st| {
        let id = st.agent.send(checked(command?)?)?;
        // SAFETY: null or writable by the caller's contract.
        unsafe { write_opt(out_action_id, id) };
        Ok(())
    })
}

fn send_with_id_impl(
    agent: *mut vrs_agent_t,
    action_id: u32,
    command: *const vrs_command_t,
) -> Result<(), FfiError> {
    if command.is_null() {
        return Err(FfiError::Null("command"));
    }
    // SAFETY: non-null; a readable vrs_command_t by the caller's contract. Every bit
    // pattern of its fields is valid.
    let command = command_from(unsafe { &*command })?;
    with_agent(agent, |st| Ok(st.agent.send_with_id(action_id, command)?))
}

fn stop_impl(agent: *mut vrs_agent_t) -> Result<(), FfiError> {
    with_agent(agent, |st| {
        // The frame ends at stop: release the shared memory before the host needs it.
        st.frame = None;
        Ok(st.agent.stop()?)
    })
}

fn agent_id_impl(agent: *mut vrs_agent_t, out_id: *mut u32) -> Result<(), FfiError> {
    with_agent(agent, |st| {
        let id = st.agent.id();
        // SAFETY: null or writable by the caller's contract.
        unsafe { write_required(out_id, "out_id", id) }
    })
}

fn init_logging_impl(filter: *const c_char) -> Result<(), FfiError> {
    use tracing_subscriber::EnvFilter;
    let filter = if filter.is_null() {
        EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("warn"))
    } else {
        // SAFETY: a C string by the caller's contract.
        let text = unsafe { str_arg(filter, "filter") }?;
        EnvFilter::try_new(text)
            .map_err(|e| FfiError::InvalidArgument(format!("bad log filter {text:?}: {e}")))?
    };
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(crate::log::ansi_on_stderr())
        .try_init()
        .map_err(|_| FfiError::LoggingAlreadySet)
}

// ---------------------------------------------------------------------------------------
// The exported functions
// ---------------------------------------------------------------------------------------

/// The version of this library (`"MAJOR.MINOR.PATCH"`), a static string.
///
/// # Safety
/// Always safe to call; do not free the result.
#[unsafe(no_mangle)]
pub extern "C" fn vrs_version() -> *const c_char {
    static VERSION: &CStr =
        match CStr::from_bytes_with_nul(concat!(env!("CARGO_PKG_VERSION"), "\0").as_bytes()) {
            Ok(v) => v,
            Err(_) => c"unknown",
        };
    VERSION.as_ptr()
}

/// The vrsync wire protocol version this library speaks (a host must speak the same).
///
/// # Safety
/// Always safe to call.
#[unsafe(no_mangle)]
pub extern "C" fn vrs_protocol_version() -> u32 {
    vrsync_bridge::PROTOCOL_VERSION
}

/// The message of the last call made on this thread: why it failed or timed out, or an
/// empty string after a success. Never NULL.
///
/// # Safety
/// Always safe to call. The string belongs to the library and stays valid until the next
/// `vrs_` call on this thread; copy it to keep it. Do not free it.
#[unsafe(no_mangle)]
pub extern "C" fn vrs_last_error_message() -> *const c_char {
    LAST_ERROR
        .try_with(|cell| match cell.try_borrow() {
            // The CString's buffer stays where it is until the next call replaces it.
            Ok(s) => s.as_ptr(),
            Err(_) => c"".as_ptr(),
        })
        .unwrap_or(c"".as_ptr())
}

/// The name of a status code (`"VRS_TIMEOUT"`, …), or `"VRS_UNKNOWN_STATUS"`. A static
/// string.
///
/// # Safety
/// Always safe to call; do not free the result.
#[unsafe(no_mangle)]
pub extern "C" fn vrs_status_name(status: i32) -> *const c_char {
    use vrs_status_t::*;
    let all = [
        (VRS_OK, c"VRS_OK"),
        (VRS_TIMEOUT, c"VRS_TIMEOUT"),
        (VRS_SESSION_CLOSED, c"VRS_SESSION_CLOSED"),
        (VRS_ERROR_INVALID_ARGUMENT, c"VRS_ERROR_INVALID_ARGUMENT"),
        (VRS_ERROR_INVALID_HANDLE, c"VRS_ERROR_INVALID_HANDLE"),
        (VRS_ERROR_WRONG_THREAD, c"VRS_ERROR_WRONG_THREAD"),
        (VRS_ERROR_CONFIG, c"VRS_ERROR_CONFIG"),
        (VRS_ERROR_CONNECT, c"VRS_ERROR_CONNECT"),
        (VRS_ERROR_HOST_GONE, c"VRS_ERROR_HOST_GONE"),
        (VRS_ERROR_PROTOCOL, c"VRS_ERROR_PROTOCOL"),
        (VRS_ERROR_NO_FRAME, c"VRS_ERROR_NO_FRAME"),
        (VRS_ERROR_OUT_OF_RANGE, c"VRS_ERROR_OUT_OF_RANGE"),
        (VRS_ERROR_QUEUE_FULL, c"VRS_ERROR_QUEUE_FULL"),
        (VRS_ERROR_ALREADY_STOPPED, c"VRS_ERROR_ALREADY_STOPPED"),
        (VRS_ERROR_TRANSPORT, c"VRS_ERROR_TRANSPORT"),
        (VRS_ERROR_TERMINATED, c"VRS_ERROR_TERMINATED"),
        (VRS_ERROR_OTHER, c"VRS_ERROR_OTHER"),
        (VRS_ERROR_PANIC, c"VRS_ERROR_PANIC"),
    ];
    all.iter()
        .find(|(s, _)| *s as i32 == status)
        .map_or(c"VRS_UNKNOWN_STATUS", |(_, name)| name)
        .as_ptr()
}

/// Sends the library's log (and iceoryx2's) to stderr. `filter` is a `RUST_LOG`-style
/// filter such as `"info"` or `"vrsync_agent=debug"`; NULL uses the `RUST_LOG`
/// environment variable, or `"warn"`. Without this call the library logs nothing. Lines
/// carry ANSI colours only when stderr is a terminal and `NO_COLOR` is unset or empty.
///
/// # Errors
/// `VRS_ERROR_INVALID_ARGUMENT` for a bad filter or when logging was already set up.
///
/// # Safety
/// `filter` is NULL or a valid NUL-terminated string.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_init_logging(filter: *const c_char) -> vrs_status_t {
    boundary(|| init_logging_impl(filter))
}

/// Connects agent `agent_id` to the session described by the config file at
/// `config_path` (the file the host uses; the session name and transport are read from
/// it), waiting up to `timeout_ms` for the host to appear (negative: the config's
/// `connect_timeout`). On success `*out_agent` is the new handle; on failure it is NULL.
/// Release the handle with [`vrs_agent_disconnect`].
///
/// # Errors
/// `VRS_ERROR_CONFIG` (unreadable or invalid config), `VRS_ERROR_CONNECT` (no host within
/// the timeout, protocol mismatch, id in use), `VRS_ERROR_INVALID_ARGUMENT`.
///
/// # Safety
/// `config_path` is NULL or a valid NUL-terminated UTF-8 string; `out_agent` is NULL or
/// valid for writing a pointer.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_connect(
    config_path: *const c_char,
    agent_id: u32,
    timeout_ms: i64,
    out_agent: *mut *mut vrs_agent_t,
) -> vrs_status_t {
    boundary(|| connect_impl(config_path, agent_id, timeout_ms, out_agent))
}

/// Disconnects and releases the agent, leaving the session gracefully: the host is told at
/// once (it stops waiting for this agent, counts a leave, not a timeout or an eviction, and
/// a new connection of the same id takes part from the next cycle). The handle is invalid
/// afterwards: using it again, including a second disconnect, returns
/// `VRS_ERROR_INVALID_HANDLE`.
///
/// # Safety
/// Any value may be passed: the handle is looked up, never dereferenced.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_disconnect(agent: *mut vrs_agent_t) -> vrs_status_t {
    boundary(|| disconnect_impl(agent))
}

/// Waits until the host signals *start* with a new frame, up to `timeout_ms` milliseconds
/// (0: just check, for a polling loop; negative: no limit, a dead host is still detected).
/// On `VRS_OK` the frame becomes the current frame and its scalar fields are written to
/// `*out_frame` (if not NULL). The previous frame ends when this is called, whatever it
/// returns. (Over the TCP transport a timeout below 1 ms currently waits up to 1 ms.)
///
/// # Errors
/// `VRS_TIMEOUT` (no new frame yet), `VRS_SESSION_CLOSED` (the run is over),
/// `VRS_ERROR_HOST_GONE`, `VRS_ERROR_PROTOCOL`, `VRS_ERROR_TERMINATED`, handle errors.
///
/// # Safety
/// `out_frame` is NULL or valid for writing a `vrs_frame_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_wait_start(
    agent: *mut vrs_agent_t,
    timeout_ms: i64,
    out_frame: *mut vrs_frame_t,
) -> vrs_status_t {
    boundary(|| wait_start_impl(agent, timeout_ms, out_frame))
}

/// Writes the scalar fields of the current frame to `*out_frame`.
///
/// # Errors
/// `VRS_ERROR_NO_FRAME`, `VRS_ERROR_INVALID_ARGUMENT` (NULL `out_frame`), handle errors.
///
/// # Safety
/// `out_frame` is NULL or valid for writing a `vrs_frame_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_frame(
    agent: *mut vrs_agent_t,
    out_frame: *mut vrs_frame_t,
) -> vrs_status_t {
    boundary(|| frame_impl(agent, out_frame))
}

/// Describes image `index` (`0..image_count`) of the current frame. `out_image->data`
/// points into shared memory and stays valid until the next wait, stop or disconnect.
///
/// # Errors
/// `VRS_ERROR_OUT_OF_RANGE`, `VRS_ERROR_NO_FRAME`, `VRS_ERROR_INVALID_ARGUMENT`, handle
/// errors.
///
/// # Safety
/// `out_image` is NULL or valid for writing a `vrs_image_t`. Do not write through
/// `out_image->data`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_image(
    agent: *mut vrs_agent_t,
    index: usize,
    out_image: *mut vrs_image_t,
) -> vrs_status_t {
    boundary(|| image_impl(agent, index, out_image))
}

/// Like [`vrs_agent_image`], for the camera called `name` (`"left"`, `"right"`, …).
///
/// # Errors
/// `VRS_ERROR_INVALID_ARGUMENT` (no such camera, NULL pointers), `VRS_ERROR_NO_FRAME`,
/// handle errors.
///
/// # Safety
/// `name` is NULL or a valid NUL-terminated string; `out_image` is NULL or valid for
/// writing a `vrs_image_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_image_by_name(
    agent: *mut vrs_agent_t,
    name: *const c_char,
    out_image: *mut vrs_image_t,
) -> vrs_status_t {
    boundary(|| image_by_name_impl(agent, name, out_image))
}

/// Action status `index` (`0..status_count`) of the current frame, keyed by the action ids
/// the sends returned: the statuses this frame brings, each exactly once — also those of
/// frames the agent skipped (the host repeats a status until the agent's stop acknowledges
/// a frame that carried it). The latest status of any action: [`vrs_agent_action_state`].
///
/// # Errors
/// `VRS_ERROR_OUT_OF_RANGE`, `VRS_ERROR_NO_FRAME`, `VRS_ERROR_INVALID_ARGUMENT`, handle
/// errors.
///
/// # Safety
/// `out_status` is NULL or valid for writing a `vrs_action_status_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_status(
    agent: *mut vrs_agent_t,
    index: usize,
    out_status: *mut vrs_action_status_t,
) -> vrs_status_t {
    boundary(|| status_impl(agent, index, out_status))
}

/// Collision `index` (`0..collision_count`) of the current frame: each collision exactly
/// once, as [`vrs_agent_status`].
///
/// # Errors
/// `VRS_ERROR_OUT_OF_RANGE`, `VRS_ERROR_NO_FRAME`, `VRS_ERROR_INVALID_ARGUMENT`, handle
/// errors.
///
/// # Safety
/// `out_collision` is NULL or valid for writing a `vrs_collision_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_collision(
    agent: *mut vrs_agent_t,
    index: usize,
    out_collision: *mut vrs_collision_t,
) -> vrs_status_t {
    boundary(|| collision_impl(agent, index, out_collision))
}

/// The latest status of action `action_id` that a frame brought, like the original
/// client's status map: `*out_known` is whether there is one, `*out_state` the
/// `vrs_action_state_t` value (0 when unknown). The agent remembers the latest 1024
/// actions (`ACTION_STATES_CAPACITY` of the Rust SDK). Needs no current frame.
///
/// # Errors
/// `VRS_ERROR_INVALID_ARGUMENT` (NULL `out_state` or `out_known`), handle errors.
///
/// # Safety
/// `out_state` is NULL or valid for writing a `uint32_t`; `out_known` is NULL or valid for
/// writing a `bool`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_action_state(
    agent: *mut vrs_agent_t,
    action_id: u32,
    out_state: *mut u32,
    out_known: *mut bool,
) -> vrs_status_t {
    boundary(|| action_state_impl(agent, action_id, out_state, out_known))
}

/// This agent's id.
///
/// # Errors
/// `VRS_ERROR_INVALID_ARGUMENT` (NULL `out_id`), handle errors.
///
/// # Safety
/// `out_id` is NULL or valid for writing a `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_id(agent: *mut vrs_agent_t, out_id: *mut u32) -> vrs_status_t {
    boundary(|| agent_id_impl(agent, out_id))
}

/// Queues a command of any kind with a fresh action id, written to `*out_action_id` if
/// not NULL. Commands go out with the next [`vrs_agent_stop`].
///
/// # Errors
/// `VRS_ERROR_INVALID_ARGUMENT` (unknown kind, NaN or infinite argument, NULL command),
/// `VRS_ERROR_QUEUE_FULL`, handle errors.
///
/// # Safety
/// `command` is NULL or points to a readable `vrs_command_t`; `out_action_id` is NULL or
/// valid for writing a `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_send(
    agent: *mut vrs_agent_t,
    command: *const vrs_command_t,
    out_action_id: *mut u32,
) -> vrs_status_t {
    boundary(|| {
        let command = if command.is_null() {
            Err(FfiError::Null("command"))
        } else {
            // SAFETY: non-null and readable by the caller's contract; any bit pattern is
            // a valid vrs_command_t.
            command_from(unsafe { &*command })
        };
        send_impl(agent, command, out_action_id)
    })
}

/// Queues a command with an action id of the caller's choice (statuses and collisions
/// quote it).
///
/// # Errors
/// As [`vrs_agent_send`].
///
/// # Safety
/// `command` is NULL or points to a readable `vrs_command_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_send_with_id(
    agent: *mut vrs_agent_t,
    action_id: u32,
    command: *const vrs_command_t,
) -> vrs_status_t {
    boundary(|| send_with_id_impl(agent, action_id, command))
}

/// Walk towards `heading_deg` (world frame, 0..360) for `distance_m` metres (the
/// original `sendAgentMovement(degree, distance)`).
///
/// Queues the command with a fresh action id, written to `*out_action_id` if not NULL; it
/// goes out with the next [`vrs_agent_stop`].
///
/// # Errors
/// `VRS_ERROR_INVALID_ARGUMENT` (NaN or infinite argument), `VRS_ERROR_QUEUE_FULL`, handle
/// errors.
///
/// # Safety
/// `out_action_id` is NULL or valid for writing a `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_send_move(
    agent: *mut vrs_agent_t,
    heading_deg: f32,
    distance_m: f32,
    out_action_id: *mut u32,
) -> vrs_status_t {
    boundary(|| {
        send_impl(
            agent,
            Ok(Command::Move {
                heading_deg,
                distance: distance_m,
            }),
            out_action_id,
        )
    })
}

/// Turn in place by `angle_deg` degrees (positive: clockwise seen from above; the original
/// `sendAgentTurn(degree)`).
///
/// Queues the command with a fresh action id, written to `*out_action_id` if not NULL; it
/// goes out with the next [`vrs_agent_stop`].
///
/// # Errors
/// `VRS_ERROR_INVALID_ARGUMENT` (NaN or infinite argument), `VRS_ERROR_QUEUE_FULL`, handle
/// errors.
///
/// # Safety
/// `out_action_id` is NULL or valid for writing a `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_send_turn(
    agent: *mut vrs_agent_t,
    angle_deg: f32,
    out_action_id: *mut u32,
) -> vrs_status_t {
    boundary(|| send_impl(agent, Ok(Command::Turn { angle_deg }), out_action_id))
}

/// Walk in a straight line to the world position (`x`, `y`, `z`) in metres.
///
/// Queues the command with a fresh action id, written to `*out_action_id` if not NULL; it
/// goes out with the next [`vrs_agent_stop`].
///
/// # Errors
/// `VRS_ERROR_INVALID_ARGUMENT` (NaN or infinite argument), `VRS_ERROR_QUEUE_FULL`, handle
/// errors.
///
/// # Safety
/// `out_action_id` is NULL or valid for writing a `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_send_move_to(
    agent: *mut vrs_agent_t,
    x: f32,
    y: f32,
    z: f32,
    out_action_id: *mut u32,
) -> vrs_status_t {
    boundary(|| {
        send_impl(
            agent,
            Ok(Command::MoveTo {
                target: glam::Vec3::new(x, y, z),
            }),
            out_action_id,
        )
    })
}

/// Cancel the running movement.
///
/// Queues the command with a fresh action id, written to `*out_action_id` if not NULL; it
/// goes out with the next [`vrs_agent_stop`].
///
/// # Errors
/// `VRS_ERROR_INVALID_ARGUMENT` (NaN or infinite argument), `VRS_ERROR_QUEUE_FULL`, handle
/// errors.
///
/// # Safety
/// `out_action_id` is NULL or valid for writing a `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_send_cancel_move(
    agent: *mut vrs_agent_t,
    out_action_id: *mut u32,
) -> vrs_status_t {
    boundary(|| send_impl(agent, Ok(Command::CancelMove), out_action_id))
}

/// Move the eyes: pan of the left and right eye and tilt of both, in degrees.
///
/// Queues the command with a fresh action id, written to `*out_action_id` if not NULL; it
/// goes out with the next [`vrs_agent_stop`].
///
/// # Errors
/// `VRS_ERROR_INVALID_ARGUMENT` (NaN or infinite argument), `VRS_ERROR_QUEUE_FULL`, handle
/// errors.
///
/// # Safety
/// `out_action_id` is NULL or valid for writing a `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_send_eye_movement(
    agent: *mut vrs_agent_t,
    pan_left_deg: f32,
    pan_right_deg: f32,
    tilt_deg: f32,
    out_action_id: *mut u32,
) -> vrs_status_t {
    boundary(|| {
        send_impl(
            agent,
            Ok(Command::EyeMovement {
                pan_left_deg,
                pan_right_deg,
                tilt_deg,
            }),
            out_action_id,
        )
    })
}

/// Fixate both eyes on the world point (`x`, `y`, `z`) in metres.
///
/// Queues the command with a fresh action id, written to `*out_action_id` if not NULL; it
/// goes out with the next [`vrs_agent_stop`].
///
/// # Errors
/// `VRS_ERROR_INVALID_ARGUMENT` (NaN or infinite argument), `VRS_ERROR_QUEUE_FULL`, handle
/// errors.
///
/// # Safety
/// `out_action_id` is NULL or valid for writing a `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_send_eye_fixation(
    agent: *mut vrs_agent_t,
    x: f32,
    y: f32,
    z: f32,
    out_action_id: *mut u32,
) -> vrs_status_t {
    boundary(|| {
        send_impl(
            agent,
            Ok(Command::EyeFixation {
                target: glam::Vec3::new(x, y, z),
            }),
            out_action_id,
        )
    })
}

/// Grasp the object `object_id`.
///
/// Queues the command with a fresh action id, written to `*out_action_id` if not NULL; it
/// goes out with the next [`vrs_agent_stop`].
///
/// # Errors
/// `VRS_ERROR_INVALID_ARGUMENT` (NaN or infinite argument), `VRS_ERROR_QUEUE_FULL`, handle
/// errors.
///
/// # Safety
/// `out_action_id` is NULL or valid for writing a `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_send_grasp_id(
    agent: *mut vrs_agent_t,
    object_id: u32,
    out_action_id: *mut u32,
) -> vrs_status_t {
    boundary(|| send_impl(agent, Ok(Command::GraspId { object_id }), out_action_id))
}

/// Grasp what is seen at left-eye pixel (`x_px`, `y_px`), 0/0 = top left.
///
/// Queues the command with a fresh action id, written to `*out_action_id` if not NULL; it
/// goes out with the next [`vrs_agent_stop`].
///
/// # Errors
/// `VRS_ERROR_INVALID_ARGUMENT` (NaN or infinite argument), `VRS_ERROR_QUEUE_FULL`, handle
/// errors.
///
/// # Safety
/// `out_action_id` is NULL or valid for writing a `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_send_grasp_pos(
    agent: *mut vrs_agent_t,
    x_px: f32,
    y_px: f32,
    out_action_id: *mut u32,
) -> vrs_status_t {
    boundary(|| send_impl(agent, Ok(Command::GraspPos { x_px, y_px }), out_action_id))
}

/// Point at the object `object_id`.
///
/// Queues the command with a fresh action id, written to `*out_action_id` if not NULL; it
/// goes out with the next [`vrs_agent_stop`].
///
/// # Errors
/// `VRS_ERROR_INVALID_ARGUMENT` (NaN or infinite argument), `VRS_ERROR_QUEUE_FULL`, handle
/// errors.
///
/// # Safety
/// `out_action_id` is NULL or valid for writing a `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_send_point_id(
    agent: *mut vrs_agent_t,
    object_id: u32,
    out_action_id: *mut u32,
) -> vrs_status_t {
    boundary(|| send_impl(agent, Ok(Command::PointId { object_id }), out_action_id))
}

/// Point at what is seen at left-eye pixel (`x_px`, `y_px`).
///
/// Queues the command with a fresh action id, written to `*out_action_id` if not NULL; it
/// goes out with the next [`vrs_agent_stop`].
///
/// # Errors
/// `VRS_ERROR_INVALID_ARGUMENT` (NaN or infinite argument), `VRS_ERROR_QUEUE_FULL`, handle
/// errors.
///
/// # Safety
/// `out_action_id` is NULL or valid for writing a `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_send_point_pos(
    agent: *mut vrs_agent_t,
    x_px: f32,
    y_px: f32,
    out_action_id: *mut u32,
) -> vrs_status_t {
    boundary(|| send_impl(agent, Ok(Command::PointPos { x_px, y_px }), out_action_id))
}

/// Interact with the object `object_id`.
///
/// Queues the command with a fresh action id, written to `*out_action_id` if not NULL; it
/// goes out with the next [`vrs_agent_stop`].
///
/// # Errors
/// `VRS_ERROR_INVALID_ARGUMENT` (NaN or infinite argument), `VRS_ERROR_QUEUE_FULL`, handle
/// errors.
///
/// # Safety
/// `out_action_id` is NULL or valid for writing a `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_send_interact_id(
    agent: *mut vrs_agent_t,
    object_id: u32,
    out_action_id: *mut u32,
) -> vrs_status_t {
    boundary(|| send_impl(agent, Ok(Command::InteractId { object_id }), out_action_id))
}

/// Interact with what is seen at left-eye pixel (`x_px`, `y_px`).
///
/// Queues the command with a fresh action id, written to `*out_action_id` if not NULL; it
/// goes out with the next [`vrs_agent_stop`].
///
/// # Errors
/// `VRS_ERROR_INVALID_ARGUMENT` (NaN or infinite argument), `VRS_ERROR_QUEUE_FULL`, handle
/// errors.
///
/// # Safety
/// `out_action_id` is NULL or valid for writing a `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_send_interact_pos(
    agent: *mut vrs_agent_t,
    x_px: f32,
    y_px: f32,
    out_action_id: *mut u32,
) -> vrs_status_t {
    boundary(|| {
        send_impl(
            agent,
            Ok(Command::InteractPos { x_px, y_px }),
            out_action_id,
        )
    })
}

/// Release the grasped object.
///
/// Queues the command with a fresh action id, written to `*out_action_id` if not NULL; it
/// goes out with the next [`vrs_agent_stop`].
///
/// # Errors
/// `VRS_ERROR_INVALID_ARGUMENT` (NaN or infinite argument), `VRS_ERROR_QUEUE_FULL`, handle
/// errors.
///
/// # Safety
/// `out_action_id` is NULL or valid for writing a `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_send_grasp_release(
    agent: *mut vrs_agent_t,
    out_action_id: *mut u32,
) -> vrs_status_t {
    boundary(|| send_impl(agent, Ok(Command::GraspRelease), out_action_id))
}

/// Reset the environment (`reset_type` 0 = default).
///
/// Queues the command with a fresh action id, written to `*out_action_id` if not NULL; it
/// goes out with the next [`vrs_agent_stop`].
///
/// # Errors
/// `VRS_ERROR_INVALID_ARGUMENT` (NaN or infinite argument), `VRS_ERROR_QUEUE_FULL`, handle
/// errors.
///
/// # Safety
/// `out_action_id` is NULL or valid for writing a `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_send_environment_reset(
    agent: *mut vrs_agent_t,
    reset_type: u32,
    out_action_id: *mut u32,
) -> vrs_status_t {
    boundary(|| {
        send_impl(
            agent,
            Ok(Command::EnvironmentReset { reset_type }),
            out_action_id,
        )
    })
}

/// Reset the trial (`reset_type` 0 = default).
///
/// Queues the command with a fresh action id, written to `*out_action_id` if not NULL; it
/// goes out with the next [`vrs_agent_stop`].
///
/// # Errors
/// `VRS_ERROR_INVALID_ARGUMENT` (NaN or infinite argument), `VRS_ERROR_QUEUE_FULL`, handle
/// errors.
///
/// # Safety
/// `out_action_id` is NULL or valid for writing a `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_send_trial_reset(
    agent: *mut vrs_agent_t,
    reset_type: u32,
    out_action_id: *mut u32,
) -> vrs_status_t {
    boundary(|| send_impl(agent, Ok(Command::TrialReset { reset_type }), out_action_id))
}

/// Ends this agent's cycle: sends the queued commands with the *stop* for the cycle of
/// the newest frame, and ends the current frame (its image pointers become invalid).
///
/// # Errors
/// `VRS_SESSION_CLOSED` (the host already ended the run: not an error),
/// `VRS_ERROR_NO_FRAME` (no frame received yet), `VRS_ERROR_ALREADY_STOPPED`,
/// `VRS_ERROR_TRANSPORT`, handle errors.
///
/// # Safety
/// Any handle value may be passed (it is looked up, never dereferenced).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_stop(agent: *mut vrs_agent_t) -> vrs_status_t {
    boundary(|| stop_impl(agent))
}

#[cfg(test)]
mod tests {
    use std::ffi::CStr;
    use std::path::{Path, PathBuf};
    use std::ptr;
    use std::sync::atomic::AtomicU32;

    use vrsync_bridge::Host;

    use super::vrs_status_t::*;
    use super::*;

    fn last_error() -> String {
        // SAFETY: the library returns a valid C string, never NULL.
        unsafe { CStr::from_ptr(vrs_last_error_message()) }
            .to_string_lossy()
            .into_owned()
    }

    fn session(tag: &str) -> String {
        static N: AtomicU32 = AtomicU32::new(0);
        format!(
            "ffi{}-{}-{tag}",
            std::process::id(),
            N.fetch_add(1, Ordering::Relaxed)
        )
    }

    /// A one-agent config (two 8×4 cameras) in `dir`.
    fn write_config(dir: &Path, tag: &str) -> PathBuf {
        let toml = format!(
            "session = {:?}\n[sync]\nstop_timeout = 5.0\nconnect_timeout = 5.0\n\
             [transport]\nmax_commands_per_cycle = 4\n\
             [[agent]]\nid = 0\n\
             [[agent.camera]]\nname = \"left\"\nwidth = 8\nheight = 4\n\
             [[agent.camera]]\nname = \"right\"\nwidth = 8\nheight = 4\nformat = \"gray8\"\n",
            session(tag)
        );
        let path = dir.join(format!("{tag}.toml"));
        std::fs::write(&path, toml).unwrap();
        path
    }

    fn c_path(path: &Path) -> CString {
        CString::new(path.to_str().unwrap()).unwrap()
    }

    fn connect(path: &Path) -> *mut vrs_agent_t {
        let mut agent = ptr::null_mut();
        // SAFETY: valid C string and out pointer.
        let st = unsafe { vrs_agent_connect(c_path(path).as_ptr(), 0, 5000, &mut agent) };
        assert_eq!(st, VRS_OK, "{}", last_error());
        assert!(!agent.is_null());
        agent
    }

    /// Publishes one frame for agent 0 and signals start.
    fn publish(host: &mut Host) {
        let mut frame = host.loan_frame(0).unwrap();
        frame.header_mut().pose.position = [1.0, 2.0, 3.0];
        frame.header_mut().reward = 0.5;
        frame
            .header_mut()
            .push_status(7, vrsync_bridge::ActionState::Walking);
        frame.header_mut().push_collision(7, 99);
        host.publish(frame).unwrap();
        host.start().unwrap();
    }

    #[test]
    fn header_is_up_to_date() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR"));
        let config = cbindgen::Config::from_file(dir.join("cbindgen.toml")).unwrap();
        let mut generated = Vec::new();
        cbindgen::Builder::new()
            .with_config(config)
            .with_src(dir.join("src/ffi.rs"))
            .generate()
            .expect("cbindgen")
            .write(&mut generated);
        let path = dir.join("include/vrsync.h");
        if std::env::var_os("VRSYNC_UPDATE_HEADER").is_some() {
            std::fs::write(&path, &generated).unwrap();
            return;
        }
        let committed = std::fs::read(&path).unwrap_or_default();
        assert!(
            committed == generated,
            "{} is out of date with src/ffi.rs; regenerate it with \
             `VRSYNC_UPDATE_HEADER=1 cargo test -p vrsync-agent header` and commit it",
            path.display()
        );
    }

    #[test]
    fn version_and_status_names() {
        // SAFETY: static strings.
        let v = unsafe { CStr::from_ptr(vrs_version()) }.to_str().unwrap();
        assert_eq!(v, env!("CARGO_PKG_VERSION"));
        assert_eq!(vrs_protocol_version(), vrsync_bridge::PROTOCOL_VERSION);
        // SAFETY: static strings.
        let name = |s: i32| {
            unsafe { CStr::from_ptr(vrs_status_name(s)) }
                .to_str()
                .unwrap()
        };
        assert_eq!(name(0), "VRS_OK");
        assert_eq!(name(VRS_TIMEOUT as i32), "VRS_TIMEOUT");
        assert_eq!(
            name(VRS_ERROR_INVALID_HANDLE as i32),
            "VRS_ERROR_INVALID_HANDLE"
        );
        assert_eq!(name(12345), "VRS_UNKNOWN_STATUS");
    }

    #[test]
    fn null_and_made_up_handles_are_errors_with_messages() {
        let null = ptr::null_mut();
        let bogus: *mut vrs_agent_t = ptr::without_provenance_mut(0xdead_beef);
        for h in [null, bogus] {
            let mut frame = std::mem::MaybeUninit::<vrs_frame_t>::uninit();
            let mut image = std::mem::MaybeUninit::<vrs_image_t>::uninit();
            let mut id = 0u32;
            // SAFETY: every out pointer is valid; the handle is never dereferenced.
            unsafe {
                assert_eq!(
                    vrs_agent_wait_start(h, 0, frame.as_mut_ptr()),
                    VRS_ERROR_INVALID_HANDLE
                );
                assert!(
                    last_error().starts_with("invalid agent handle"),
                    "{}",
                    last_error()
                );
                assert_eq!(
                    vrs_agent_frame(h, frame.as_mut_ptr()),
                    VRS_ERROR_INVALID_HANDLE
                );
                assert_eq!(
                    vrs_agent_image(h, 0, image.as_mut_ptr()),
                    VRS_ERROR_INVALID_HANDLE
                );
                assert_eq!(
                    vrs_agent_send_move(h, 0.0, 1.0, &mut id),
                    VRS_ERROR_INVALID_HANDLE
                );
                assert_eq!(
                    vrs_agent_send_grasp_release(h, ptr::null_mut()),
                    VRS_ERROR_INVALID_HANDLE
                );
                assert_eq!(vrs_agent_stop(h), VRS_ERROR_INVALID_HANDLE);
                assert_eq!(vrs_agent_id(h, &mut id), VRS_ERROR_INVALID_HANDLE);
                assert_eq!(vrs_agent_disconnect(h), VRS_ERROR_INVALID_HANDLE);
            }
        }
        // SAFETY: the handle is never dereferenced.
        unsafe { vrs_agent_stop(bogus) };
        assert!(last_error().contains("0xdeadbeef"), "{}", last_error());
    }

    #[test]
    fn connect_reports_bad_arguments_config_and_missing_host() {
        let dir = tempfile::tempdir().unwrap();
        let mut agent: *mut vrs_agent_t = ptr::without_provenance_mut(1);
        // SAFETY: valid (or null, on purpose) pointers.
        unsafe {
            assert_eq!(
                vrs_agent_connect(ptr::null(), 0, 0, &mut agent),
                VRS_ERROR_INVALID_ARGUMENT
            );
            assert!(agent.is_null(), "a failed connect leaves NULL behind");
            assert_eq!(last_error(), "config_path must not be null");
            let path = c_path(&dir.path().join("missing.toml"));
            assert_eq!(
                vrs_agent_connect(path.as_ptr(), 0, 0, ptr::null_mut()),
                VRS_ERROR_INVALID_ARGUMENT
            );
            assert_eq!(
                vrs_agent_connect(path.as_ptr(), 0, 0, &mut agent),
                VRS_ERROR_CONFIG
            );
            assert!(last_error().contains("missing.toml"), "{}", last_error());
            let not_utf8 = CString::new(vec![0xff, 0xfe]).unwrap();
            assert_eq!(
                vrs_agent_connect(not_utf8.as_ptr(), 0, 0, &mut agent),
                VRS_ERROR_INVALID_ARGUMENT
            );
            let config = c_path(&write_config(dir.path(), "nohost"));
            assert_eq!(
                vrs_agent_connect(config.as_ptr(), 0, 0, &mut agent),
                VRS_ERROR_CONNECT
            );
            assert!(last_error().contains("no host"), "{}", last_error());
            assert!(agent.is_null());
        }
    }

    #[test]
    fn logging_filter_is_checked() {
        let bad = CString::new("[[[").unwrap();
        // SAFETY: a valid C string.
        assert_eq!(
            unsafe { vrs_init_logging(bad.as_ptr()) },
            VRS_ERROR_INVALID_ARGUMENT
        );
        assert!(last_error().contains("bad log filter"), "{}", last_error());
    }

    #[test]
    fn a_cycle_through_the_c_abi_and_double_free() {
        let dir = tempfile::tempdir().unwrap();
        let path = write_config(dir.path(), "cycle");
        let config = Config::load(&path).unwrap();
        let mut host = Host::builder(&config).create().unwrap();
        let agent = connect(&path);
        host.wait_for_agents(Duration::from_secs(5)).unwrap();

        let mut frame = std::mem::MaybeUninit::<vrs_frame_t>::uninit();
        let mut image = std::mem::MaybeUninit::<vrs_image_t>::uninit();
        let mut id = 0u32;
        let first;
        // SAFETY: every pointer below is valid for its use.
        unsafe {
            // Before the first frame.
            assert_eq!(
                vrs_agent_frame(agent, frame.as_mut_ptr()),
                VRS_ERROR_NO_FRAME
            );
            assert_eq!(vrs_agent_stop(agent), VRS_ERROR_NO_FRAME);
            assert!(
                last_error().contains("before the first frame"),
                "{}",
                last_error()
            );
            // A poll with nothing published: a timeout, not an error.
            assert_eq!(
                vrs_agent_wait_start(agent, 0, frame.as_mut_ptr()),
                VRS_TIMEOUT
            );
            assert!(last_error().contains("no start"), "{}", last_error());

            publish(&mut host);
            assert_eq!(
                vrs_agent_wait_start(agent, 5000, frame.as_mut_ptr()),
                VRS_OK
            );
            assert_eq!(last_error(), "");
            let f = frame.assume_init();
            assert_eq!((f.cycle, f.sim_time_ns, f.agent_id), (0, 0, 0));
            assert!(f.sync_mode);
            assert_eq!(f.pose.position, [1.0, 2.0, 3.0]);
            assert_eq!(f.reward, 0.5);
            assert_eq!(
                (f.image_count, f.status_count, f.collision_count),
                (2, 1, 1)
            );
            assert_eq!(f.previous_outcome, vrs_outcome_t::VRS_OUTCOME_NONE);

            let mut again = std::mem::MaybeUninit::<vrs_frame_t>::uninit();
            assert_eq!(vrs_agent_frame(agent, again.as_mut_ptr()), VRS_OK);
            assert_eq!(again.assume_init(), f);
            assert_eq!(
                vrs_agent_frame(agent, ptr::null_mut()),
                VRS_ERROR_INVALID_ARGUMENT
            );

            assert_eq!(vrs_agent_image(agent, 0, image.as_mut_ptr()), VRS_OK);
            let left = image.assume_init();
            assert_eq!(
                (left.width, left.height, left.stride, left.len),
                (8, 4, 24, 96)
            );
            assert_eq!(left.format, vrs_pixel_format_t::VRS_PIXEL_FORMAT_RGB8);
            assert_eq!(CStr::from_ptr(left.name.as_ptr()).to_str().unwrap(), "left");
            assert!(!left.data.is_null());
            let name = CString::new("right").unwrap();
            assert_eq!(
                vrs_agent_image_by_name(agent, name.as_ptr(), image.as_mut_ptr()),
                VRS_OK
            );
            let right = image.assume_init();
            assert_eq!((right.width, right.stride, right.camera), (8, 8, 1));
            assert_eq!(right.format, vrs_pixel_format_t::VRS_PIXEL_FORMAT_GRAY8);
            // Zero copy: both views point into one shared-memory payload, in camera order
            // (the host may align each image).
            let gap = right.data.offset_from(left.data.add(left.len));
            assert!((0..256).contains(&gap), "gap {gap}");
            assert_eq!(
                vrs_agent_image(agent, 2, image.as_mut_ptr()),
                VRS_ERROR_OUT_OF_RANGE
            );
            assert!(last_error().contains("image index 2"), "{}", last_error());
            let nope = CString::new("main").unwrap();
            assert_eq!(
                vrs_agent_image_by_name(agent, nope.as_ptr(), image.as_mut_ptr()),
                VRS_ERROR_INVALID_ARGUMENT
            );

            let mut status = vrs_action_status_t::default();
            assert_eq!(vrs_agent_status(agent, 0, &mut status), VRS_OK);
            assert_eq!((status.action_id, status.state), (7, 3));
            assert_eq!(
                vrs_agent_status(agent, 1, &mut status),
                VRS_ERROR_OUT_OF_RANGE
            );
            let mut collision = vrs_collision_t::default();
            assert_eq!(vrs_agent_collision(agent, 0, &mut collision), VRS_OK);
            assert_eq!((collision.action_id, collision.collider_id), (7, 99));

            // Commands: typed, generic, with an id of our own; bad ones refused here.
            assert_eq!(vrs_agent_send_move(agent, 90.0, 1.0, &mut id), VRS_OK);
            first = id;
            assert_eq!(
                vrs_agent_send_turn(agent, f32::NAN, &mut id),
                VRS_ERROR_INVALID_ARGUMENT
            );
            assert!(last_error().contains("turn"), "{}", last_error());
            assert_eq!(id, first, "a refused command leaves the id alone");
            let cmd = vrs_command_t {
                kind: vrs_command_kind_t::VRS_COMMAND_TURN as u32,
                object_id: 0,
                args: [45.0, 0.0, 0.0, 0.0],
            };
            assert_eq!(vrs_agent_send(agent, &cmd, &mut id), VRS_OK);
            assert_ne!(id, first);
            assert_eq!(vrs_agent_send_with_id(agent, 4242, &cmd), VRS_OK);
            let bad = vrs_command_t { kind: 77, ..cmd };
            assert_eq!(
                vrs_agent_send(agent, &bad, ptr::null_mut()),
                VRS_ERROR_INVALID_ARGUMENT
            );
            assert!(
                last_error().contains("unknown command kind 77"),
                "{}",
                last_error()
            );
            assert_eq!(
                vrs_agent_send(agent, ptr::null(), ptr::null_mut()),
                VRS_ERROR_INVALID_ARGUMENT
            );
            assert_eq!(vrs_agent_send_cancel_move(agent, ptr::null_mut()), VRS_OK);
            // max_commands_per_cycle = 4
            assert_eq!(
                vrs_agent_send_grasp_id(agent, 1, ptr::null_mut()),
                VRS_ERROR_QUEUE_FULL
            );

            assert_eq!(vrs_agent_stop(agent), VRS_OK);
            assert_eq!(vrs_agent_stop(agent), VRS_ERROR_ALREADY_STOPPED);
            // The frame ended with the stop.
            assert_eq!(
                vrs_agent_image(agent, 0, image.as_mut_ptr()),
                VRS_ERROR_NO_FRAME
            );
        }
        let report = host.collect().unwrap();
        let got: Vec<_> = report.agents()[0]
            .commands()
            .iter()
            .map(|c| (c.decode().unwrap().name(), c.action_id))
            .collect();
        assert_eq!(got.len(), 4);
        assert_eq!(got[0], ("move", first));
        assert_eq!(got[2], ("turn", 4242));
        assert_eq!(got[3].0, "cancel_move");

        // SAFETY: as above.
        unsafe {
            drop(host);
            assert_eq!(
                vrs_agent_wait_start(agent, 5000, frame.as_mut_ptr()),
                VRS_SESSION_CLOSED
            );
            assert_eq!(vrs_agent_disconnect(agent), VRS_OK);
            assert_eq!(vrs_agent_disconnect(agent), VRS_ERROR_INVALID_HANDLE);
            assert!(
                last_error().contains("already disconnected"),
                "{}",
                last_error()
            );
            assert_eq!(vrs_agent_stop(agent), VRS_ERROR_INVALID_HANDLE);
        }
    }

    #[test]
    fn a_handle_belongs_to_its_thread() {
        let dir = tempfile::tempdir().unwrap();
        let path = write_config(dir.path(), "thread");
        let config = Config::load(&path).unwrap();
        let _host = Host::builder(&config).create().unwrap();
        let agent = connect(&path);
        let key = agent.addr();
        let from_other_thread = std::thread::spawn(move || {
            let agent: *mut vrs_agent_t = ptr::without_provenance_mut(key);
            // SAFETY: the handle is never dereferenced.
            let st = unsafe { vrs_agent_stop(agent) };
            // SAFETY: as above.
            let dc = unsafe { vrs_agent_disconnect(agent) };
            (st, dc, last_error())
        })
        .join()
        .unwrap();
        assert_eq!(from_other_thread.0, VRS_ERROR_WRONG_THREAD);
        assert_eq!(from_other_thread.1, VRS_ERROR_WRONG_THREAD);
        assert!(
            from_other_thread.2.contains("another thread"),
            "{}",
            from_other_thread.2
        );
        // SAFETY: as above.
        assert_eq!(unsafe { vrs_agent_disconnect(agent) }, VRS_OK);
    }

    #[test]
    fn panics_become_a_status() {
        let st = boundary(|| panic!("boom"));
        assert_eq!(st, VRS_ERROR_PANIC);
        assert!(last_error().contains("boom"), "{}", last_error());
    }
}
