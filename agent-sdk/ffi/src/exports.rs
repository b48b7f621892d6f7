//! The exported functions of the library, the connection and the current frame. Each is
//! a thin wrapper over an `*_impl` function of `calls.rs`; [`boundary`] catches panics and
//! records the message.

use std::ffi::{CStr, c_char};

use super::calls::*;
use super::state::{boundary, last_error_ptr};
use super::types::*;

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
    vrsync_transport::PROTOCOL_VERSION
}

/// The message of the last call made on this thread: why it failed or timed out, or an
/// empty string after a success. Never NULL.
///
/// # Safety
/// Always safe to call. The string belongs to the library and stays valid until the next
/// `vrs_` call on this thread; copy it to keep it. Do not free it.
#[unsafe(no_mangle)]
pub extern "C" fn vrs_last_error_message() -> *const c_char {
    last_error_ptr()
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
        (VRS_ERROR_UNKNOWN_CHANNEL, c"VRS_ERROR_UNKNOWN_CHANNEL"),
        (VRS_ERROR_WRONG_LENGTH, c"VRS_ERROR_WRONG_LENGTH"),
        (VRS_ERROR_OUT_OF_BOUNDS, c"VRS_ERROR_OUT_OF_BOUNDS"),
        (
            VRS_ERROR_CHOICE_OUT_OF_RANGE,
            c"VRS_ERROR_CHOICE_OUT_OF_RANGE",
        ),
        (VRS_ERROR_WRONG_ACTION_KIND, c"VRS_ERROR_WRONG_ACTION_KIND"),
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
