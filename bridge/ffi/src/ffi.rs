//! The exported `vrs_host_*` functions. Each is a thin wrapper over an `*_impl` function
//! returning a `Result` (`calls.rs`); [`boundary`] catches panics and records the message.

use std::ffi::{CStr, c_char};

use crate::calls::*;
use crate::state::{boundary, boundary_status, destroy, last_error_ptr};
use crate::types::*;

// ---------------------------------------------------------------------------------------
// The exported functions: library
// ---------------------------------------------------------------------------------------

/// The version of this library (`"MAJOR.MINOR.PATCH"`), a static string.
///
/// # Safety
/// Always safe to call; do not free the result.
#[unsafe(no_mangle)]
pub extern "C" fn vrs_host_version() -> *const c_char {
    static VERSION: &CStr =
        match CStr::from_bytes_with_nul(concat!(env!("CARGO_PKG_VERSION"), "\0").as_bytes()) {
            Ok(v) => v,
            Err(_) => c"unknown",
        };
    VERSION.as_ptr()
}

/// The vrsync wire protocol version this library speaks (agents must speak the same).
///
/// # Safety
/// Always safe to call.
#[unsafe(no_mangle)]
pub extern "C" fn vrs_host_protocol_version() -> u32 {
    vrsync_bridge::PROTOCOL_VERSION
}

/// The message of the last `vrs_host_` call made on this thread: why it failed or timed
/// out, or an empty string after a success. Never NULL.
///
/// # Safety
/// Always safe to call. The string belongs to the library and stays valid until the next
/// `vrs_host_` call on this thread; copy it to keep it. Do not free it.
#[unsafe(no_mangle)]
pub extern "C" fn vrs_host_last_error_message() -> *const c_char {
    last_error_ptr()
}

/// The name of a status code (`"VRS_HOST_TIMEOUT"`, …), or `"VRS_HOST_UNKNOWN_STATUS"`.
/// A static string.
///
/// # Safety
/// Always safe to call; do not free the result.
#[unsafe(no_mangle)]
pub extern "C" fn vrs_host_status_name(status: i32) -> *const c_char {
    use vrs_host_status_t::*;
    let all = [
        (VRS_HOST_OK, c"VRS_HOST_OK"),
        (VRS_HOST_TIMEOUT, c"VRS_HOST_TIMEOUT"),
        (VRS_HOST_DEFERRED, c"VRS_HOST_DEFERRED"),
        (
            VRS_HOST_ERROR_INVALID_ARGUMENT,
            c"VRS_HOST_ERROR_INVALID_ARGUMENT",
        ),
        (
            VRS_HOST_ERROR_INVALID_HANDLE,
            c"VRS_HOST_ERROR_INVALID_HANDLE",
        ),
        (VRS_HOST_ERROR_WRONG_THREAD, c"VRS_HOST_ERROR_WRONG_THREAD"),
        (VRS_HOST_ERROR_CONFIG, c"VRS_HOST_ERROR_CONFIG"),
        (VRS_HOST_ERROR_CREATE, c"VRS_HOST_ERROR_CREATE"),
        (
            VRS_HOST_ERROR_UNKNOWN_AGENT,
            c"VRS_HOST_ERROR_UNKNOWN_AGENT",
        ),
        (VRS_HOST_ERROR_WRONG_STATE, c"VRS_HOST_ERROR_WRONG_STATE"),
        (VRS_HOST_ERROR_NO_FRAME, c"VRS_HOST_ERROR_NO_FRAME"),
        (VRS_HOST_ERROR_OUT_OF_RANGE, c"VRS_HOST_ERROR_OUT_OF_RANGE"),
        (VRS_HOST_ERROR_AGENT_LOST, c"VRS_HOST_ERROR_AGENT_LOST"),
        (VRS_HOST_ERROR_TRANSPORT, c"VRS_HOST_ERROR_TRANSPORT"),
        (VRS_HOST_ERROR_TERMINATED, c"VRS_HOST_ERROR_TERMINATED"),
        (
            VRS_HOST_ERROR_UNKNOWN_CHANNEL,
            c"VRS_HOST_ERROR_UNKNOWN_CHANNEL",
        ),
        (VRS_HOST_ERROR_OTHER, c"VRS_HOST_ERROR_OTHER"),
        (VRS_HOST_ERROR_PANIC, c"VRS_HOST_ERROR_PANIC"),
    ];
    all.iter()
        .find(|(s, _)| *s as i32 == status)
        .map_or(c"VRS_HOST_UNKNOWN_STATUS", |(_, name)| name)
        .as_ptr()
}

/// Sends the library's log (and iceoryx2's) to stderr. `filter` is a `RUST_LOG`-style
/// filter such as `"info"` or `"vrsync_bridge=debug"`; NULL uses the `RUST_LOG`
/// environment variable, or `"warn"`. Without this call the library logs nothing (Unity:
/// stderr ends up in the player log / `Editor.log`). Lines carry ANSI colours only when
/// stderr is a terminal and `NO_COLOR` is unset or empty.
///
/// # Errors
/// `VRS_HOST_ERROR_INVALID_ARGUMENT` for a bad filter or when logging was already set up
/// in this process.
///
/// # Safety
/// `filter` is NULL or a valid NUL-terminated string.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_host_init_logging(filter: *const c_char) -> vrs_host_status_t {
    boundary(|| init_logging_impl(filter))
}

macro_rules! sizeof_fns {
    ($($fn_name:ident => $ty:ty),* $(,)?) => {$(
        #[doc = concat!("`sizeof(", stringify!($ty), ")` as this library was built: a binding")]
        /// compares it with its own struct size before the first call that passes one.
        ///
        /// # Safety
        /// Always safe to call.
        #[unsafe(no_mangle)]
        pub extern "C" fn $fn_name() -> usize {
            core::mem::size_of::<$ty>()
        }
    )*};
}

sizeof_fns! {
    vrs_host_sizeof_sensors => vrs_host_sensors_t,
    vrs_host_sizeof_frame => vrs_host_frame_t,
    vrs_host_sizeof_image => vrs_host_image_t,
    vrs_host_sizeof_camera => vrs_host_camera_t,
    vrs_host_sizeof_agent_info => vrs_host_agent_info_t,
    vrs_host_sizeof_info => vrs_host_info_t,
    vrs_host_sizeof_cycle => vrs_host_cycle_t,
    vrs_host_sizeof_command => vrs_host_command_t,
    vrs_host_sizeof_agent_report => vrs_host_agent_report_t,
    vrs_host_sizeof_stats => vrs_host_stats_t,
}

// ---------------------------------------------------------------------------------------
// The exported functions: the host
// ---------------------------------------------------------------------------------------

/// Creates the host of the session described by the config file at `config_path` (the
/// file the agents use too: session name, transport, agents and their cameras). On
/// success `*out_host` is the new handle; on failure it is NULL. Destroy it with
/// [`vrs_host_destroy`]. Stale shared memory of a crashed earlier run is cleaned up.
///
/// # Errors
/// `VRS_HOST_ERROR_CONFIG` (unreadable or invalid config), `VRS_HOST_ERROR_CREATE`
/// (shared memory, the session is in use by a live host, TCP port taken, …),
/// `VRS_HOST_ERROR_INVALID_ARGUMENT`.
///
/// # Safety
/// `config_path` is NULL or a valid NUL-terminated UTF-8 string; `out_host` is NULL or
/// valid for writing a pointer.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_host_create(
    config_path: *const c_char,
    out_host: *mut *mut vrs_host_t,
) -> vrs_host_status_t {
    boundary(|| create_impl(config_path, out_host))
}

/// Destroys the host: releases loaned frames and closes the session (agents see it
/// closed and end cleanly). The handle is invalid afterwards: using it again, including a
/// second destroy, returns `VRS_HOST_ERROR_INVALID_HANDLE`. Called from a thread that does
/// not own the host (a .NET finalizer), it returns `VRS_HOST_DEFERRED` and the host is
/// destroyed at the owning thread's next `vrs_host_` call.
///
/// # Safety
/// Any value may be passed: the handle is looked up, never dereferenced.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_host_destroy(host: *mut vrs_host_t) -> vrs_host_status_t {
    boundary_status(|| destroy(host))
}

/// The session's settings and the current cycle.
///
/// # Errors
/// `VRS_HOST_ERROR_INVALID_ARGUMENT` (NULL `out_info`), handle errors.
///
/// # Safety
/// Any handle value may be passed; `out_info` is NULL or valid for writing a
/// [`vrs_host_info_t`].
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_host_info(
    host: *mut vrs_host_t,
    out_info: *mut vrs_host_info_t,
) -> vrs_host_status_t {
    boundary(|| info_impl(host, out_info))
}

/// Agent number `index` (`0..agent_count`, ascending ids) of the config: its id, camera
/// count and whether it is connected now.
///
/// # Errors
/// `VRS_HOST_ERROR_OUT_OF_RANGE`, `VRS_HOST_ERROR_INVALID_ARGUMENT`, handle errors.
///
/// # Safety
/// Any handle value may be passed; `out_agent` is NULL or valid for writing a
/// [`vrs_host_agent_info_t`].
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_host_agent_info(
    host: *mut vrs_host_t,
    index: u32,
    out_agent: *mut vrs_host_agent_info_t,
) -> vrs_host_status_t {
    boundary(|| agent_info_impl(host, index, out_agent))
}

/// Camera `index` of agent `agent_id` as configured (size, format, fields of view): to
/// create render targets before the first cycle.
///
/// # Errors
/// `VRS_HOST_ERROR_UNKNOWN_AGENT`, `VRS_HOST_ERROR_OUT_OF_RANGE`,
/// `VRS_HOST_ERROR_INVALID_ARGUMENT`, handle errors.
///
/// # Safety
/// Any handle value may be passed; `out_camera` is NULL or valid for writing a
/// [`vrs_host_camera_t`].
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_host_camera(
    host: *mut vrs_host_t,
    agent_id: u32,
    index: u32,
    out_camera: *mut vrs_host_camera_t,
) -> vrs_host_status_t {
    boundary(|| camera_impl(host, agent_id, index, out_camera))
}

/// Blocks until every agent of the config is connected, or `timeout_ms` passed (negative:
/// the config's `connect_timeout`). Call it before the first cycle: a *start* sent before
/// an agent listens is lost. Returns `VRS_HOST_TIMEOUT` when some agents are missing:
/// their ids are written to `out_missing` (up to `missing_capacity` of them),
/// `*out_missing_count` is how many are missing (0 on success), and the message names
/// them. Wait again, or run without them (they are not waited for until they connect).
///
/// # Errors
/// `VRS_HOST_ERROR_WRONG_STATE` (in the middle of a cycle), `VRS_HOST_ERROR_TERMINATED`,
/// `VRS_HOST_ERROR_TRANSPORT`, handle errors.
///
/// # Safety
/// Any handle value may be passed; `out_missing` is NULL (then `missing_capacity` must be
/// 0) or valid for writing `missing_capacity` `uint32_t`; `out_missing_count` is NULL or
/// valid for writing one.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_host_wait_for_agents(
    host: *mut vrs_host_t,
    timeout_ms: i64,
    out_missing: *mut u32,
    missing_capacity: u32,
    out_missing_count: *mut u32,
) -> vrs_host_status_t {
    boundary_status(|| {
        wait_for_agents_impl(
            host,
            timeout_ms,
            out_missing,
            missing_capacity,
            out_missing_count,
        )
    })
}

/// Frame 1, step 1: loans agent `agent_id`'s sensor frame of the current cycle. Its
/// header is pre-filled (cycle, simulated time, image table); get each image's writable
/// memory with [`vrs_host_frame_image`], render or copy into it, then
/// [`vrs_host_publish`] it with the sensor data (or [`vrs_host_discard_frame`] it). One
/// frame per agent and cycle.
///
/// # Errors
/// `VRS_HOST_ERROR_WRONG_STATE` (after start, or already loaned/published this cycle),
/// `VRS_HOST_ERROR_UNKNOWN_AGENT`, `VRS_HOST_ERROR_TRANSPORT` (no memory to loan), handle
/// errors.
///
/// # Safety
/// Any handle value may be passed; `out_frame` is NULL or valid for writing a
/// [`vrs_host_frame_t`].
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_host_loan_frame(
    host: *mut vrs_host_t,
    agent_id: u32,
    out_frame: *mut vrs_host_frame_t,
) -> vrs_host_status_t {
    boundary(|| loan_frame_impl(host, agent_id, out_frame))
}

/// Image `index` (camera order) of agent `agent_id`'s loaned frame: where to write its
/// pixels. `data` stays valid until the frame is published or discarded, or the host
/// destroyed.
///
/// # Errors
/// `VRS_HOST_ERROR_NO_FRAME`, `VRS_HOST_ERROR_OUT_OF_RANGE`,
/// `VRS_HOST_ERROR_UNKNOWN_AGENT`, `VRS_HOST_ERROR_INVALID_ARGUMENT`, handle errors.
///
/// # Safety
/// Any handle value may be passed; `out_image` is NULL or valid for writing a
/// [`vrs_host_image_t`]. Writes through `data` must stay within `len` bytes.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_host_frame_image(
    host: *mut vrs_host_t,
    agent_id: u32,
    index: u32,
    out_image: *mut vrs_host_image_t,
) -> vrs_host_status_t {
    boundary(|| frame_image_impl(host, agent_id, index, out_image))
}

/// Like [`vrs_host_frame_image`], by camera name (`"left"`, `"right"`, …).
///
/// # Errors
/// `VRS_HOST_ERROR_INVALID_ARGUMENT` (no such camera, NULL), `VRS_HOST_ERROR_NO_FRAME`,
/// `VRS_HOST_ERROR_UNKNOWN_AGENT`, handle errors.
///
/// # Safety
/// Any handle value may be passed; `name` is NULL or a valid NUL-terminated string;
/// `out_image` is NULL or valid for writing a [`vrs_host_image_t`].
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_host_frame_image_by_name(
    host: *mut vrs_host_t,
    agent_id: u32,
    name: *const c_char,
    out_image: *mut vrs_host_image_t,
) -> vrs_host_status_t {
    boundary(|| frame_image_by_name_impl(host, agent_id, name, out_image))
}

/// Frame 1, step 2: copies `sensors` into the loaned frame's header and publishes the
/// frame to its agent (NULL `sensors`: identity pose, zeros, no statuses). The image
/// pointers of the frame are invalid afterwards. A frame for an agent that is not
/// connected is dropped and counted (`frames_undelivered`); that agent is not waited for
/// this cycle.
///
/// # Errors
/// `VRS_HOST_ERROR_INVALID_ARGUMENT` (more statuses or collisions than fit, an unknown
/// action state: the frame stays loaned), `VRS_HOST_ERROR_NO_FRAME`,
/// `VRS_HOST_ERROR_WRONG_STATE`, `VRS_HOST_ERROR_TRANSPORT`, handle errors.
///
/// # Safety
/// Any handle value may be passed; `sensors` is NULL or valid for reading a
/// [`vrs_host_sensors_t`].
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_host_publish(
    host: *mut vrs_host_t,
    agent_id: u32,
    sensors: *const vrs_host_sensors_t,
) -> vrs_host_status_t {
    boundary(|| publish_impl(host, agent_id, sensors))
}

/// Returns agent `agent_id`'s loaned frame unpublished (the agent gets no frame this
/// cycle and is not waited for). Its image pointers are invalid afterwards.
///
/// # Errors
/// `VRS_HOST_ERROR_NO_FRAME`, `VRS_HOST_ERROR_UNKNOWN_AGENT`, handle errors.
///
/// # Safety
/// Any handle value may be passed.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_host_discard_frame(
    host: *mut vrs_host_t,
    agent_id: u32,
) -> vrs_host_status_t {
    boundary(|| discard_frame_impl(host, agent_id))
}

/// Frame 1, step 3: signals *start* to every agent at once (the original's
/// `MsgStartSync`, one broadcast instead of one message per agent). Every loaned frame
/// must be published or discarded first.
///
/// # Errors
/// `VRS_HOST_ERROR_WRONG_STATE` (frames still loaned, start already sent),
/// `VRS_HOST_ERROR_TRANSPORT`, handle errors.
///
/// # Safety
/// Any handle value may be passed.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_host_start(host: *mut vrs_host_t) -> vrs_host_status_t {
    boundary(|| start_impl(host))
}

/// Frame 2: waits for the stops. Sync mode: blocks until every agent whose frame was
/// published this cycle sent its stop, or the config's `stop_timeout` passed (one deadline
/// for all agents); an agent whose stop is missing gets `VRS_HOST_OUTCOME_TIMED_OUT` in its
/// report — not an error. Async mode: waits until the next tick of
/// `simulation_time_per_frame` real time, taking commands as they arrive. Then the cycle
/// number advances; read each agent's commands with [`vrs_host_agent_report`] and finish
/// with [`vrs_host_end_cycle`].
///
/// # Errors
/// `VRS_HOST_ERROR_WRONG_STATE` (no start), `VRS_HOST_ERROR_TERMINATED` (SIGINT/SIGTERM),
/// `VRS_HOST_ERROR_TRANSPORT`, `VRS_HOST_ERROR_AGENT_LOST` (an agent lost with
/// `on_agent_lost = "abort"` or `"wait"`), handle errors.
///
/// # Safety
/// Any handle value may be passed; `out_cycle` is NULL or valid for writing a
/// [`vrs_host_cycle_t`].
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_host_collect(
    host: *mut vrs_host_t,
    out_cycle: *mut vrs_host_cycle_t,
) -> vrs_host_status_t {
    boundary(|| collect_impl(host, out_cycle))
}

/// Agent report `index` (`0..agent_count` of the cycle, in agent id order) of the cycle
/// just collected: its outcome and its commands (`commands[0..command_count]`, valid until
/// [`vrs_host_end_cycle`]).
///
/// # Errors
/// `VRS_HOST_ERROR_WRONG_STATE` (not collected), `VRS_HOST_ERROR_OUT_OF_RANGE`,
/// `VRS_HOST_ERROR_INVALID_ARGUMENT`, handle errors.
///
/// # Safety
/// Any handle value may be passed; `out_report` is NULL or valid for writing a
/// [`vrs_host_agent_report_t`].
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_host_agent_report(
    host: *mut vrs_host_t,
    index: u32,
    out_report: *mut vrs_host_agent_report_t,
) -> vrs_host_status_t {
    boundary(|| agent_report_impl(host, index, out_report))
}

/// The report of agent `agent_id` in the cycle just collected (as
/// [`vrs_host_agent_report`], found by id instead of position).
///
/// # Errors
/// `VRS_HOST_ERROR_UNKNOWN_AGENT` (not an agent of the config), `VRS_HOST_ERROR_WRONG_STATE`
/// (not after collect), `VRS_HOST_ERROR_INVALID_ARGUMENT` (NULL `out_report`), handle
/// errors.
///
/// # Safety
/// Any handle value may be passed; `out_report` is NULL or valid for writing a
/// [`vrs_host_agent_report_t`].
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_host_agent_report_by_id(
    host: *mut vrs_host_t,
    agent_id: u32,
    out_report: *mut vrs_host_agent_report_t,
) -> vrs_host_status_t {
    boundary(|| agent_report_by_id_impl(host, agent_id, out_report))
}

/// Copies command `command_index` of agent report `agent_index` (for callers that prefer
/// copies to the report's pointer).
///
/// # Errors
/// `VRS_HOST_ERROR_WRONG_STATE` (not collected), `VRS_HOST_ERROR_OUT_OF_RANGE`,
/// `VRS_HOST_ERROR_INVALID_ARGUMENT`, handle errors.
///
/// # Safety
/// Any handle value may be passed; `out_command` is NULL or valid for writing a
/// [`vrs_host_command_t`].
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_host_command(
    host: *mut vrs_host_t,
    agent_index: u32,
    command_index: u32,
    out_command: *mut vrs_host_command_t,
) -> vrs_host_status_t {
    boundary(|| command_impl(host, agent_index, command_index, out_command))
}

/// Records how many of agent `agent_id`'s commands of the cycle just collected the
/// simulator rejected (NaN, out of range, unknown object); the agent sees the number in
/// its next frame.
///
/// # Errors
/// `VRS_HOST_ERROR_UNKNOWN_AGENT`, handle errors.
///
/// # Safety
/// Any handle value may be passed.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_host_set_rejected(
    host: *mut vrs_host_t,
    agent_id: u32,
    rejected: u32,
) -> vrs_host_status_t {
    boundary(|| set_rejected_impl(host, agent_id, rejected))
}

/// Ends the collected cycle: the report's command pointers become invalid and the next
/// cycle's frames may be loaned.
///
/// # Errors
/// `VRS_HOST_ERROR_WRONG_STATE` (not collected), handle errors.
///
/// # Safety
/// Any handle value may be passed.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_host_end_cycle(host: *mut vrs_host_t) -> vrs_host_status_t {
    boundary(|| end_cycle_impl(host))
}

/// Counters since the host was created.
///
/// # Errors
/// `VRS_HOST_ERROR_INVALID_ARGUMENT` (NULL `out_stats`), handle errors.
///
/// # Safety
/// Any handle value may be passed; `out_stats` is NULL or valid for writing a
/// [`vrs_host_stats_t`].
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_host_stats(
    host: *mut vrs_host_t,
    out_stats: *mut vrs_host_stats_t,
) -> vrs_host_status_t {
    boundary(|| stats_impl(host, out_stats))
}
