//! The `*_impl` functions behind the exported `vrs_*` functions, each returning a
//! `Result`, and the helpers they share.

use std::ffi::{CStr, c_char};
use std::time::Duration;

use vrsync_bridge::{Command, Config};

use super::state::{
    AGENTS, AgentState, FfiError, handle_key, register, unknown_handle, with_agent,
};
use super::types::*;
use crate::agent::{AgentBuilder, Frame, SignalHandling};

// ---------------------------------------------------------------------------------------
// Helpers
// ---------------------------------------------------------------------------------------

/// Writes `value` through `out` when `out` is not null.
///
/// # Safety
/// `out` is null or valid for writing a `T`.
pub(super) unsafe fn write_opt<T>(out: *mut T, value: T) {
    if !out.is_null() {
        // SAFETY: non-null and, by the caller's contract, valid for writes.
        unsafe { out.write(value) }
    }
}

/// Writes `value` through `out`, which must not be null.
///
/// # Safety
/// `out` is null or valid for writing a `T`.
pub(super) unsafe fn write_required<T>(
    out: *mut T,
    what: &'static str,
    value: T,
) -> Result<(), FfiError> {
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
pub(super) unsafe fn str_arg<'a>(
    s: *const c_char,
    what: &'static str,
) -> Result<&'a str, FfiError> {
    if s.is_null() {
        return Err(FfiError::Null(what));
    }
    // SAFETY: non-null and NUL-terminated by the caller's contract.
    let c = unsafe { CStr::from_ptr(s) };
    c.to_str()
        .map_err(|e| FfiError::InvalidArgument(format!("{what} is not UTF-8: {e}")))
}

/// A timeout in milliseconds; negative means none.
pub(super) fn timeout_arg(timeout_ms: i64) -> Option<Duration> {
    u64::try_from(timeout_ms).ok().map(Duration::from_millis)
}

pub(super) fn frame_info(frame: &Frame, frames_skipped: u64) -> vrs_frame_t {
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

pub(super) fn image_info(frame: &Frame, index: usize) -> Result<vrs_image_t, FfiError> {
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

pub(super) fn current_frame(state: &AgentState) -> Result<&Frame, FfiError> {
    state.frame.as_ref().ok_or(FfiError::NoFrame)
}

pub(super) fn command_from(c: &vrs_command_t) -> Result<Command, FfiError> {
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
pub(super) fn checked(command: Command) -> Result<Command, FfiError> {
    command
        .encode(0)
        .decode()
        .map_err(|e| FfiError::InvalidArgument(format!("{}: {e}", command.name())))
}

// ---------------------------------------------------------------------------------------
// Implementations
// ---------------------------------------------------------------------------------------

pub(super) fn connect_impl(
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

pub(super) fn disconnect_impl(agent: *mut vrs_agent_t) -> Result<(), FfiError> {
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

pub(super) fn wait_start_impl(
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

pub(super) fn frame_impl(
    agent: *mut vrs_agent_t,
    out_frame: *mut vrs_frame_t,
) -> Result<(), FfiError> {
    with_agent(agent, |st| {
        let info = frame_info(current_frame(st)?, st.agent.frames_skipped());
        // SAFETY: null or writable by the caller's contract.
        unsafe { write_required(out_frame, "out_frame", info) }
    })
}

pub(super) fn image_impl(
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

pub(super) fn image_by_name_impl(
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

pub(super) fn status_impl(
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

pub(super) fn collision_impl(
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

pub(super) fn action_state_impl(
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

pub(super) fn send_impl(
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

pub(super) fn send_with_id_impl(
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

pub(super) fn stop_impl(agent: *mut vrs_agent_t) -> Result<(), FfiError> {
    with_agent(agent, |st| {
        // The frame ends at stop: release the shared memory before the host needs it.
        st.frame = None;
        Ok(st.agent.stop()?)
    })
}

pub(super) fn agent_id_impl(agent: *mut vrs_agent_t, out_id: *mut u32) -> Result<(), FfiError> {
    with_agent(agent, |st| {
        let id = st.agent.id();
        // SAFETY: null or writable by the caller's contract.
        unsafe { write_required(out_id, "out_id", id) }
    })
}

pub(super) fn init_logging_impl(filter: *const c_char) -> Result<(), FfiError> {
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
