//! The types of the host C ABI: status codes, enums and the `#[repr(C)]` structs that
//! cross the boundary (declared in `include/vrsync_host.h`).
//!
//! Every struct is plain data with fixed-size fields (`uint32_t`, `uint64_t`, `float`, one
//! data pointer in [`vrs_host_image_t`] and [`vrs_host_agent_report_t`]): no `bool`, no
//! `size_t`, so that the C# binding can mirror each one as a blittable
//! `[StructLayout(LayoutKind.Sequential)]` struct. `vrs_host_sizeof_*` report the sizes
//! for the binding to check against `Marshal.SizeOf`.

#![allow(non_camel_case_types)]

use core::mem::{align_of, offset_of, size_of};
use std::ffi::c_char;

use vrsync_bridge::{ActionSpace, HostStats, MotorCommand, PixelFormat};
use vrsync_cabi::{
    vrs_action_status_t, vrs_collision_t, vrs_eye_position_t, vrs_grid_position_t,
    vrs_head_motion_t, vrs_pose_t,
};

/// Most images (cameras) per agent and frame.
pub const VRS_HOST_MAX_IMAGES: u32 = 4;
/// Most action statuses per sensor frame ([`vrs_host_sensors_t::statuses`]).
pub const VRS_HOST_MAX_STATUSES: u32 = 16;
/// Most collisions per sensor frame ([`vrs_host_sensors_t::collisions`]).
pub const VRS_HOST_MAX_COLLISIONS: u32 = 8;
/// Size of a camera name field: up to 16 bytes of UTF-8 and a terminating NUL.
pub const VRS_HOST_CAMERA_NAME_SIZE: usize = 17;
/// Most vectors (`[[agent.vector]]`) per agent.
pub const VRS_HOST_MAX_VECTORS: u32 = 8;
/// Most actions (`[[agent.action]]`) per agent.
pub const VRS_HOST_MAX_ACTIONS: u32 = 8;
/// Size of a channel (vector, action) name field: up to 16 bytes of UTF-8 and a
/// terminating NUL.
pub const VRS_HOST_CHANNEL_NAME_SIZE: usize = 17;

const _: () = {
    assert!(VRS_HOST_MAX_VECTORS as usize == vrsync_bridge::MAX_VECTORS);
    assert!(VRS_HOST_MAX_ACTIONS as usize == vrsync_bridge::MAX_ACTIONS);
    assert!(VRS_HOST_CHANNEL_NAME_SIZE == vrsync_cabi::CHANNEL_NAME_SIZE);
    assert!(VRS_HOST_MAX_IMAGES as usize == vrsync_bridge::MAX_CAMERAS);
    assert!(VRS_HOST_MAX_STATUSES as usize == vrsync_bridge::MAX_STATUSES);
    assert!(VRS_HOST_MAX_COLLISIONS as usize == vrsync_bridge::MAX_COLLISIONS);
    assert!(VRS_HOST_CAMERA_NAME_SIZE == vrsync_cabi::CAMERA_NAME_SIZE);
};

/// Result of a call: 0 is success, positive values are outcomes that are not errors,
/// negative values are errors (details in `vrs_host_last_error_message`). The numbers
/// shared with the agent SDK's `vrs_status_t` mean the same.
#[repr(i32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum vrs_host_status_t {
    /// Success.
    VRS_HOST_OK = 0,
    /// `vrs_host_wait_for_agents`: some agents did not connect in time (their ids are
    /// reported); wait again or go on without them.
    VRS_HOST_TIMEOUT = 1,
    /// `vrs_host_destroy` from a thread that does not own the host (a .NET finalizer):
    /// the host is destroyed at the owning thread's next `vrs_host_` call.
    VRS_HOST_DEFERRED = 2,
    /// A pointer argument is null or an argument is out of its domain (too many statuses,
    /// not UTF-8, …).
    VRS_HOST_ERROR_INVALID_ARGUMENT = -1,
    /// The host handle is null, unknown, or was already destroyed.
    VRS_HOST_ERROR_INVALID_HANDLE = -2,
    /// The host handle belongs to another thread.
    VRS_HOST_ERROR_WRONG_THREAD = -3,
    /// The config file could not be read or is invalid.
    VRS_HOST_ERROR_CONFIG = -4,
    /// The host could not be created (shared memory, session in use, TCP port taken, …).
    VRS_HOST_ERROR_CREATE = -5,
    /// The agent id is not in the config.
    VRS_HOST_ERROR_UNKNOWN_AGENT = -6,
    /// The call does not fit the cycle's phase (a loan after start, collect before start,
    /// start with an unpublished frame, a second loan for one agent, …).
    VRS_HOST_ERROR_WRONG_STATE = -7,
    /// No frame is loaned for this agent (publish, image or discard without a loan).
    VRS_HOST_ERROR_NO_FRAME = -8,
    /// An index is past the end of its table (image, camera, agent, command, vector,
    /// action).
    VRS_HOST_ERROR_OUT_OF_RANGE = -9,
    /// An agent was lost (its process died or disconnected) and the config says
    /// `on_agent_lost = "abort"`, or `"wait"` and it did not come back in time.
    VRS_HOST_ERROR_AGENT_LOST = -10,
    /// The transport failed.
    VRS_HOST_ERROR_TRANSPORT = -12,
    /// SIGINT or SIGTERM arrived: the program should end.
    VRS_HOST_ERROR_TERMINATED = -13,
    /// The agent has no vector or action of that name in the config (the message lists
    /// those it has).
    VRS_HOST_ERROR_UNKNOWN_CHANNEL = -14,
    /// Something not covered above (see the message).
    VRS_HOST_ERROR_OTHER = -98,
    /// A bug: the library panicked (see the message).
    VRS_HOST_ERROR_PANIC = -99,
}

/// Pixel format of an image (the values of the wire format).
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum vrs_host_pixel_format_t {
    /// 8-bit red, green, blue: 3 bytes per pixel.
    VRS_HOST_PIXEL_FORMAT_RGB8 = 0,
    /// 8-bit red, green, blue, alpha: 4 bytes per pixel.
    VRS_HOST_PIXEL_FORMAT_RGBA8 = 1,
    /// 8-bit grey: 1 byte per pixel.
    VRS_HOST_PIXEL_FORMAT_GRAY8 = 2,
    /// 32-bit float depth in metres, native endian: 4 bytes per pixel.
    VRS_HOST_PIXEL_FORMAT_DEPTH32F = 3,
}

impl From<PixelFormat> for vrs_host_pixel_format_t {
    fn from(f: PixelFormat) -> Self {
        match f {
            PixelFormat::Rgb8 => Self::VRS_HOST_PIXEL_FORMAT_RGB8,
            PixelFormat::Rgba8 => Self::VRS_HOST_PIXEL_FORMAT_RGBA8,
            PixelFormat::Gray8 => Self::VRS_HOST_PIXEL_FORMAT_GRAY8,
            PixelFormat::Depth32f => Self::VRS_HOST_PIXEL_FORMAT_DEPTH32F,
        }
    }
}

/// Execution state of an action, reported to the agent in
/// [`vrs_host_sensors_t::statuses`] (the values of the original
/// `MsgActionExecutationStatus`).
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum vrs_host_action_state_t {
    /// Accepted, not finished yet.
    VRS_HOST_ACTION_IN_EXECUTION = 0,
    /// Completed.
    VRS_HOST_ACTION_FINISHED = 1,
    /// Cancelled, replaced by a newer action, or impossible.
    VRS_HOST_ACTION_ABORTED = 2,
    /// A movement is walking.
    VRS_HOST_ACTION_WALKING = 3,
    /// A movement is rotating.
    VRS_HOST_ACTION_ROTATING = 4,
    /// A movement is walking and rotating.
    VRS_HOST_ACTION_WALKING_ROTATING = 5,
}

/// How one agent's part of a cycle ended ([`vrs_host_agent_report_t::outcome`]).
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum vrs_host_outcome_t {
    /// No frame reached the agent this cycle (not connected), so it was not waited for.
    VRS_HOST_OUTCOME_NOT_AWAITED = 0,
    /// The agent's stop arrived in time.
    VRS_HOST_OUTCOME_STOPPED = 1,
    /// The stop timeout ended the cycle before the agent's stop arrived. Not an error:
    /// the cycle goes on with what arrived, as the original did.
    VRS_HOST_OUTCOME_TIMED_OUT = 2,
    /// Async mode: commands were taken as they arrived.
    VRS_HOST_OUTCOME_ASYNC = 3,
    /// The agent was lost during the cycle (process died or disconnected).
    VRS_HOST_OUTCOME_EVICTED = 4,
    /// The agent left the session gracefully during the cycle (it closed its connection
    /// and said so) before its stop.
    VRS_HOST_OUTCOME_LEFT = 5,
    /// An outcome this version of the ABI does not know.
    VRS_HOST_OUTCOME_OTHER = 255,
}

/// Motor command kinds ([`vrs_host_command_t::kind`]); the values of the wire format.
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum vrs_host_command_kind_t {
    /// Walk `args[0]` degrees heading (world frame, 0 = +z, 90 = +x) for `args[1]` metres.
    VRS_HOST_COMMAND_MOVE = 1,
    /// Turn by `args[0]` degrees (clockwise seen from above, relative).
    VRS_HOST_COMMAND_TURN = 2,
    /// Walk straight to the world position `args[0..3]`.
    VRS_HOST_COMMAND_MOVE_TO = 3,
    /// Cancel the running movement.
    VRS_HOST_COMMAND_CANCEL_MOVE = 4,
    /// Eyes: pan left `args[0]`, pan right `args[1]`, tilt `args[2]` degrees.
    VRS_HOST_COMMAND_EYE_MOVEMENT = 5,
    /// Fixate both eyes on the world point `args[0..3]`.
    VRS_HOST_COMMAND_EYE_FIXATION = 6,
    /// Grasp the object `object_id`.
    VRS_HOST_COMMAND_GRASP_ID = 7,
    /// Grasp what is seen at left-eye pixel (`args[0]`, `args[1]`).
    VRS_HOST_COMMAND_GRASP_POS = 8,
    /// Point at the object `object_id`.
    VRS_HOST_COMMAND_POINT_ID = 9,
    /// Point at left-eye pixel (`args[0]`, `args[1]`).
    VRS_HOST_COMMAND_POINT_POS = 10,
    /// Interact with the object `object_id`.
    VRS_HOST_COMMAND_INTERACT_ID = 11,
    /// Interact with what is seen at left-eye pixel (`args[0]`, `args[1]`).
    VRS_HOST_COMMAND_INTERACT_POS = 12,
    /// Release the grasped object.
    VRS_HOST_COMMAND_GRASP_RELEASE = 13,
    /// Reset the environment (`object_id` = reset type).
    VRS_HOST_COMMAND_ENVIRONMENT_RESET = 14,
    /// Reset the trial (`object_id` = reset type).
    VRS_HOST_COMMAND_TRIAL_RESET = 15,
}

/// The transport a host runs on ([`vrs_host_info_t::transport`]).
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum vrs_host_transport_t {
    /// iceoryx2 shared memory (zero copy, same machine).
    VRS_HOST_TRANSPORT_SHM = 0,
    /// TCP.
    VRS_HOST_TRANSPORT_TCP = 1,
    /// zenoh (agents on other machines).
    VRS_HOST_TRANSPORT_ZENOH = 2,
    /// The original system's protobuf/TCP protocol.
    VRS_HOST_TRANSPORT_LEGACY = 3,
}

impl vrs_host_transport_t {
    /// The constant of `kind`. The `match` covers the bridge's transport registry: a
    /// transport added there does not compile here until it has its constant (and
    /// `tests/transport_constants.rs` then checks the header, the C# binding and the C side
    /// of its layout check for it).
    pub fn of(kind: vrsync_bridge::TransportKind) -> Self {
        use vrsync_bridge::TransportKind as K;
        match kind {
            K::Shm => Self::VRS_HOST_TRANSPORT_SHM,
            K::Tcp => Self::VRS_HOST_TRANSPORT_TCP,
            K::Legacy => Self::VRS_HOST_TRANSPORT_LEGACY,
            K::Zenoh => Self::VRS_HOST_TRANSPORT_ZENOH,
        }
    }
}

// Every constant of `vrs_host_command_kind_t` and `vrs_host_action_state_t` (and of the
// agent ABI's copies) is checked against the protocol's catalogue (`CommandKind::ALL`,
// `ActionState::ALL`), name and value, through the header these enums generate:
// tests/command_catalogue.rs.
const _: () = {
    assert!(
        vrs_host_pixel_format_t::VRS_HOST_PIXEL_FORMAT_DEPTH32F as u32
            == PixelFormat::Depth32f as u32
    );
    assert!(
        vrs_host_action_state_t::VRS_HOST_ACTION_WALKING_ROTATING as u32
            == vrsync_bridge::ActionState::WalkingRotating as u32
    );
};

/// Opaque host handle. It is a registry key, not a pointer to memory: the library never
/// dereferences it, so a null, stale or made-up handle is an error, never a crash.
pub struct vrs_host_t {
    _private: [u8; 0],
}

/// The sensor structs both C ABIs share (`vrsync_cabi::sensors`), under this ABI's names;
/// `cbindgen.toml` renames them likewise in the header.
pub use vrsync_cabi::{
    vrs_action_status_t as vrs_host_action_status_t, vrs_collision_t as vrs_host_collision_t,
    vrs_eye_position_t as vrs_host_eye_position_t, vrs_grid_position_t as vrs_host_grid_position_t,
    vrs_head_motion_t as vrs_host_head_motion_t, vrs_pose_t as vrs_host_pose_t,
};

/// The sensor data of one agent's frame, everything but the images: passed to
/// `vrs_host_publish`, which copies it into the frame's header in shared memory.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct vrs_host_sensors_t {
    /// Body pose.
    pub pose: vrs_pose_t,
    /// Reward since the previous frame.
    pub reward: f32,
    /// Grid position sensor.
    pub grid: vrs_grid_position_t,
    /// Head motion sensor.
    pub head_motion: vrs_head_motion_t,
    /// Eye position sensor.
    pub eye: vrs_eye_position_t,
    /// Valid entries in `statuses` (at most `VRS_HOST_MAX_STATUSES`).
    pub status_count: u32,
    /// Valid entries in `collisions` (at most `VRS_HOST_MAX_COLLISIONS`).
    pub collision_count: u32,
    /// Action statuses that changed since the previous frame.
    pub statuses: [vrs_action_status_t; VRS_HOST_MAX_STATUSES as usize],
    /// Collisions since the previous frame.
    pub collisions: [vrs_collision_t; VRS_HOST_MAX_COLLISIONS as usize],
}

impl Default for vrs_host_sensors_t {
    fn default() -> Self {
        Self {
            pose: vrs_pose_t::default(),
            reward: 0.0,
            grid: vrs_grid_position_t::default(),
            head_motion: vrs_head_motion_t::default(),
            eye: vrs_eye_position_t::default(),
            status_count: 0,
            collision_count: 0,
            statuses: [vrs_action_status_t::default(); VRS_HOST_MAX_STATUSES as usize],
            collisions: [vrs_collision_t::default(); VRS_HOST_MAX_COLLISIONS as usize],
        }
    }
}

/// A loaned sensor frame (`vrs_host_loan_frame`).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct vrs_host_frame_t {
    /// Cycle number the frame belongs to.
    pub cycle: u64,
    /// Simulated time at the start of the cycle, nanoseconds.
    pub sim_time_ns: u64,
    /// The agent the frame is for.
    pub agent_id: u32,
    /// Number of images (`vrs_host_frame_image` indices `0..image_count`).
    pub image_count: u32,
}

/// One writable image of a loaned frame: on shared memory, the memory the agent will
/// read. Rows are `stride` bytes apart, origin top-left. The bytes hold an older frame
/// until written: write all of them.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct vrs_host_image_t {
    /// First byte of the first (top) row. Valid until the frame is published or
    /// discarded.
    pub data: *mut u8,
    /// Number of bytes at `data` (`stride * height`).
    pub len: u64,
    /// Bytes per row (`width * bytes per pixel`, no padding).
    pub stride: u64,
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Pixel format.
    pub format: vrs_host_pixel_format_t,
    /// Index of the camera in the agent's camera list.
    pub camera: u32,
    /// Camera name, NUL-terminated (`left`, `right`, …).
    pub name: [c_char; VRS_HOST_CAMERA_NAME_SIZE],
}

/// One camera of an agent, from the config (to size render targets before the first
/// cycle).
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct vrs_host_camera_t {
    /// Bytes of one image (`stride * height`).
    pub len: u64,
    /// Bytes per row.
    pub stride: u64,
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels (given, or derived from the fields of view).
    pub height: u32,
    /// Pixel format.
    pub format: vrs_host_pixel_format_t,
    /// Horizontal field of view, degrees.
    pub fov_horizontal_deg: f32,
    /// Vertical field of view, degrees (Unity's `Camera.fieldOfView`).
    pub fov_vertical_deg: f32,
    /// Camera name, NUL-terminated.
    pub name: [c_char; VRS_HOST_CAMERA_NAME_SIZE],
}

/// One agent of the session, from the config.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct vrs_host_agent_info_t {
    /// Agent id.
    pub agent_id: u32,
    /// Number of cameras (`vrs_host_camera` indices `0..camera_count`).
    pub camera_count: u32,
    /// 1 if the agent is connected now, else 0 (a TCP agent whose link was lost counts as
    /// connected while its place is held for its return: `[sync] resume_window`).
    pub connected: u32,
    /// Reserved, zero.
    pub reserved: u32,
}

/// The session: what the config says and where the host is.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct vrs_host_info_t {
    /// Current cycle number (the next frame's).
    pub cycle: u64,
    /// Simulated time at the start of the current cycle, nanoseconds.
    pub sim_time_ns: u64,
    /// Simulated time per cycle (`simulation_time_per_frame`), nanoseconds.
    pub simulation_time_per_frame_ns: u64,
    /// How long `vrs_host_collect` waits for stops (`stop_timeout`), nanoseconds.
    pub stop_timeout_ns: u64,
    /// The config's `connect_timeout`, nanoseconds.
    pub connect_timeout_ns: u64,
    /// Number of agents in the config (`vrs_host_agent_info` indices).
    pub agent_count: u32,
    /// 1 in sync (lock-step) mode, 0 in async mode.
    pub sync_mode: u32,
    /// The transport.
    pub transport: vrs_host_transport_t,
    /// The TCP port agents connect to (the bound one if the config said 0); 0 on shm.
    pub tcp_port: u32,
    /// Most commands one agent may send per cycle.
    pub max_commands_per_cycle: u32,
    /// The wire protocol version.
    pub protocol_version: u32,
}

/// The end of one cycle (`vrs_host_collect`).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct vrs_host_cycle_t {
    /// Cycle number that ended.
    pub cycle: u64,
    /// Simulated time at its start, nanoseconds. The world advances by
    /// `simulation_time_per_frame` now.
    pub sim_time_ns: u64,
    /// Number of agent reports (`vrs_host_agent_report` indices), in agent id order.
    pub agent_count: u32,
    /// Agents whose stop did not arrive before the stop timeout (0 = all in time).
    pub timed_out_agents: u32,
    /// Batches for earlier cycles (or after a stop) dropped during this cycle.
    pub late_batches: u32,
    /// Commands received this cycle, all agents together.
    pub command_count: u32,
    /// Agents evicted during this cycle (lost: process died or disconnected); which ones:
    /// `evicted` in their reports.
    pub evicted_agents: u32,
    /// Agents that rejoined in this cycle (their first frame since an eviction or a leave
    /// reached them); which ones: `rejoined` in their reports.
    pub rejoined_agents: u32,
    /// Agents that left the session gracefully during this cycle (their SDK's `close()`
    /// said so: not a fault, not evicted, not timed out; the id is free for a new
    /// connection, which takes part from the next cycle); which ones: `left` in their
    /// reports.
    pub left_agents: u32,
    /// Agents the host waited for past `stop_timeout` in this cycle (their
    /// `wait_for_stop` is `"alive"` and they stayed connected: busy, not lost; nothing was
    /// dropped); which ones: `slow` in their reports.
    pub slow_agents: u32,
}

/// A motor command as the agent sent it. `kind` is a `vrs_host_command_kind_t` value, or
/// any other number if the agent sent garbage: check it, and the arguments (NaN, range),
/// before applying. Same layout as the wire format, so command arrays are handed out
/// without a copy.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct vrs_host_command_t {
    /// A `vrs_host_command_kind_t` value (not checked).
    pub kind: u32,
    /// The action id the agent chose; report its state back in `statuses`.
    pub action_id: u32,
    /// Object id or reset type, for the kinds that take one.
    pub object_id: u32,
    /// Reserved, zero.
    pub reserved: u32,
    /// Float arguments, meaning per kind.
    pub args: [f32; 4],
}

/// One agent's part of the cycle that ended.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct vrs_host_agent_report_t {
    /// Agent id.
    pub agent_id: u32,
    /// How its part of the cycle ended.
    pub outcome: vrs_host_outcome_t,
    /// Number of commands at `commands`.
    pub command_count: u32,
    /// Reserved, zero.
    pub reserved: u32,
    /// The commands in the order the agent sent them; NULL when there are none. Valid
    /// until `vrs_host_end_cycle`.
    pub commands: *const vrs_host_command_t,
    /// The newest cycle whose frame the agent acknowledged having read, -1 before its
    /// first acknowledgement (and after an eviction). A frame it was sent and never
    /// acknowledged before a newer one was, it skipped (its events still reach it).
    pub read_cycle: i64,
    /// 1 if the agent was evicted during this cycle (also after its stop arrived), else 0.
    pub evicted: u32,
    /// 1 if the agent rejoined in this cycle (its first frame since an eviction or a leave
    /// reached it), else 0.
    pub rejoined: u32,
    /// 1 if the agent left the session gracefully during this cycle (its SDK's `close()`
    /// said so: not a fault, not evicted; its id is free for a new connection, which takes
    /// part from the next cycle), else 0. If its stop had arrived first, `outcome` stays
    /// `VRS_HOST_OUTCOME_STOPPED`, else it is `VRS_HOST_OUTCOME_LEFT`.
    pub left: u32,
    /// 1 if the host waited for the agent's stop past `stop_timeout` in this cycle (its
    /// `wait_for_stop` is `"alive"` and it stayed connected: a slow agent, reported, not
    /// timed out), else 0.
    pub slow: u32,
}

/// Counters since the host was created.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct vrs_host_stats_t {
    /// Cycles completed.
    pub cycles: u64,
    /// Cycles that ended by the stop timeout.
    pub stop_timeouts: u64,
    /// Agent-cycles that timed out (one cycle with two missing agents counts 2).
    pub agent_timeouts: u64,
    /// Batches dropped because they named an earlier cycle or followed the stop.
    pub late_batches: u64,
    /// Batches dropped because they named a cycle that had not started.
    pub future_batches: u64,
    /// Commands received.
    pub commands_received: u64,
    /// Commands dropped because an agent exceeded `max_commands_per_cycle`.
    pub commands_overflowed: u64,
    /// Frames that reached no agent (not connected).
    pub frames_undelivered: u64,
    /// Evictions (an agent evicted twice counts 2).
    pub evictions: u64,
    /// Times an evicted agent, or one that left, came back.
    pub rejoins: u64,
    /// Frames delivered to an agent.
    pub frames_delivered: u64,
    /// Frames an agent acknowledged having read; `frames_delivered - frames_read` were
    /// skipped (a newer one was read first) or are still being read.
    pub frames_read: u64,
    /// Action statuses dropped because an agent acknowledged nothing for long enough that
    /// its table of unacknowledged events (`VRS_HOST_MAX_STATUSES`) was full.
    pub statuses_dropped: u64,
    /// Collisions dropped likewise (`VRS_HOST_MAX_COLLISIONS`).
    pub collisions_dropped: u64,
    /// Cycles in which the host waited past `stop_timeout` for an agent whose
    /// `wait_for_stop` is `"alive"` (it was busy, not lost: nothing was dropped). Not
    /// stop timeouts.
    pub slow_stops: u64,
    /// Graceful leaves: an agent's SDK said it leaves (`close()`, drop). Not evictions,
    /// not timeouts.
    pub leaves: u64,
    /// Peers refused or dropped before they were admitted as agents (garbage, a wrong
    /// token or protocol version, an unknown or taken id, a silent connection).
    pub peers_refused: u64,
    /// Action chunks refused (an unknown action, a value of the wrong length, out of its
    /// bounds or not finite, a choice out of range): none of it was applied. Per agent and
    /// cycle: `vrs_host_actions_rejected`.
    pub actions_rejected: u64,
    /// Times an agent whose link was lost came back within `[sync] resume_window` and went
    /// on where it was (TCP and zenoh agents): not evictions, not rejoins.
    pub resumes: u64,
}

impl From<&HostStats> for vrs_host_stats_t {
    fn from(s: &HostStats) -> Self {
        Self {
            cycles: s.cycles,
            stop_timeouts: s.stop_timeouts,
            agent_timeouts: s.agent_timeouts,
            late_batches: s.late_batches,
            future_batches: s.future_batches,
            commands_received: s.commands_received,
            commands_overflowed: s.commands_overflowed,
            frames_undelivered: s.frames_undelivered,
            evictions: s.evictions,
            rejoins: s.rejoins,
            frames_delivered: s.frames_delivered,
            frames_read: s.frames_read,
            statuses_dropped: s.statuses_dropped,
            collisions_dropped: s.collisions_dropped,
            slow_stops: s.slow_stops,
            leaves: s.leaves,
            peers_refused: s.peers_refused,
            actions_rejected: s.actions_rejected,
            resumes: s.resumes,
        }
    }
}

// The command array of a report is the host's `[MotorCommand]`, handed out as is.
const _: () = {
    assert!(size_of::<vrs_host_command_t>() == size_of::<MotorCommand>());
    assert!(align_of::<vrs_host_command_t>() == align_of::<MotorCommand>());
    assert!(offset_of!(vrs_host_command_t, kind) == offset_of!(MotorCommand, kind));
    assert!(offset_of!(vrs_host_command_t, action_id) == offset_of!(MotorCommand, action_id));
    assert!(offset_of!(vrs_host_command_t, object_id) == offset_of!(MotorCommand, object_id));
    assert!(offset_of!(vrs_host_command_t, reserved) == offset_of!(MotorCommand, reserved));
    assert!(offset_of!(vrs_host_command_t, args) == offset_of!(MotorCommand, args));
    // Sizes the C# binding mirrors (64-bit targets; the pointer structs differ on 32-bit).
    assert!(size_of::<vrs_host_sensors_t>() == 328);
    assert!(size_of::<vrs_host_command_t>() == 32);
    assert!(size_of::<vrs_host_cycle_t>() == 48);
    assert!(size_of::<vrs_host_stats_t>() == 152);
    // Fields are only ever appended: the offsets of the first ABI's fields stay put.
    assert!(offset_of!(vrs_host_cycle_t, rejoined_agents) == 36);
    assert!(offset_of!(vrs_host_cycle_t, left_agents) == 40);
    assert!(offset_of!(vrs_host_stats_t, collisions_dropped) == 104);
    assert!(offset_of!(vrs_host_stats_t, slow_stops) == 112);
    assert!(offset_of!(vrs_host_stats_t, actions_rejected) == 136);
    assert!(offset_of!(vrs_host_stats_t, resumes) == 144);
};

// The report holds a pointer: these hold on 64-bit targets, which the C# binding mirrors.
#[cfg(target_pointer_width = "64")]
const _: () = {
    assert!(size_of::<vrs_host_agent_report_t>() == 48);
    assert!(offset_of!(vrs_host_agent_report_t, rejoined) == 36);
    assert!(offset_of!(vrs_host_agent_report_t, left) == 40);
};

/// What an action holds (`vrs_host_action_spec_t::kind`), or what an agent sent for it
/// in a cycle (`vrs_host_action_value_t::kind`). The same numbers as the agent SDK's
/// `vrs_action_kind_t`.
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum vrs_host_action_kind_t {
    /// Nothing: the agent sent no (valid, complete) value for the action this cycle.
    VRS_HOST_ACTION_KIND_NONE = 0,
    /// A continuous action: `len` floats, each within its bounds.
    VRS_HOST_ACTION_KIND_BOX = 1,
    /// A discrete action: a choice in `0..n`.
    VRS_HOST_ACTION_KIND_DISCRETE = 2,
}

impl vrs_host_action_kind_t {
    /// The kind of an action of `space`. The `match` covers the bridge's action spaces: a
    /// space added there does not compile here until it has its constant (and
    /// `tests/channel_constants.rs` then checks the headers and the C# binding for it).
    pub fn of(space: &ActionSpace) -> Self {
        match space {
            ActionSpace::Box { .. } => Self::VRS_HOST_ACTION_KIND_BOX,
            ActionSpace::Discrete { .. } => Self::VRS_HOST_ACTION_KIND_DISCRETE,
        }
    }
}
