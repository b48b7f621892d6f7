//! The `*_impl` functions behind the exported `vrs_*` functions, each returning a
//! `Result`, and the helpers they share.

use std::ffi::c_char;
use std::time::Duration;

use vrsync_cabi::{ArgError, c_name, log_filter, str_arg, write_opt, write_required};
use vrsync_transport::{Command, Config};

use super::state::{AGENTS, AgentState, FfiError, with_agent};
use super::types::*;
use sdk::{AgentBuilder, Frame, SignalHandling};

// ---------------------------------------------------------------------------------------
// Helpers
// ---------------------------------------------------------------------------------------

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
        pose: h.pose.into(),
        reward: h.reward,
        grid: h.grid.into(),
        head_motion: h.head_motion.into(),
        eye: h.eye.into(),
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
    let data = image.data();
    Ok(vrs_image_t {
        data: data.as_ptr(),
        len: data.len(),
        width: image.width(),
        height: image.height(),
        stride: image.stride(),
        format: image.format().into(),
        camera: image.desc().camera,
        name: c_name(image.name()),
    })
}

pub(super) fn current_frame(state: &AgentState) -> Result<&Frame, FfiError> {
    state.frame.as_ref().ok_or(FfiError::NoFrame)
}

pub(super) fn command_from(c: &vrs_command_t) -> Result<Command, FfiError> {
    let wire = vrsync_transport::MotorCommand {
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
        return Err(ArgError::Null("out_agent").into());
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
    let vectors = config
        .agent(agent_id)
        .map(|a| a.vectors.clone())
        .unwrap_or_default();
    let key = AGENTS.insert(|_| AgentState {
        frame: None,
        agent,
        vectors,
    })?;
    // SAFETY: as above. The handle is a registry key, never dereferenced.
    unsafe { out_agent.write(std::ptr::without_provenance_mut(key)) };
    Ok(())
}

pub(super) fn disconnect_impl(agent: *mut vrs_agent_t) -> Result<(), FfiError> {
    Ok(AGENTS.remove(agent)?)
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
        let value = vrs_action_status_t::from(s);
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
        let value = vrs_collision_t::from(c);
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
            write_required::<_, FfiError>(out_known, "out_known", state.is_some())?;
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
        return Err(ArgError::Null("command").into());
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
    // SAFETY: a C string by the caller's contract.
    let filter = unsafe { log_filter(filter) }?;
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(vrsync_transport::ansi_on_stderr())
        .try_init()
        .map_err(|_| FfiError::LoggingAlreadySet)
}
