//! The `*_impl` functions behind the exported `vrs_host_*` functions (`ffi.rs`), each
//! returning a `Result`, and the helpers they share.

use std::ffi::c_char;
use std::time::Duration;

use vrsync_bridge::Config;
use vrsync_bridge::{self, ActionState, ActionStatus, Collision};
use vrsync_bridge::{Host, HostWaitError, SignalHandling};

use vrsync_cabi::{ArgError, c_name, log_filter, str_arg, write_opt, write_required};

use crate::state::{FfiError, ImageView, Phase, ReportCopy, copy_report, register, with_host};
use crate::types::*;

// ---------------------------------------------------------------------------------------
// Helpers
// ---------------------------------------------------------------------------------------

pub(crate) fn image_info(view: &ImageView) -> vrs_host_image_t {
    let d = &view.desc;
    vrs_host_image_t {
        data: view.data,
        len: d.len,
        stride: u64::from(d.stride_bytes),
        width: d.width_px,
        height: d.height_px,
        format: d.pixel_format().map_or(
            vrs_host_pixel_format_t::VRS_HOST_PIXEL_FORMAT_RGB8,
            Into::into,
        ),
        camera: d.camera,
        name: c_name(d.name()),
    }
}

/// Checks the sensor struct before anything is written (a wrong count is the typical
/// sign of a binding whose struct layout does not match the header).
pub(crate) fn check_sensors(s: &vrs_host_sensors_t) -> Result<(), FfiError> {
    if s.status_count > VRS_HOST_MAX_STATUSES {
        return Err(FfiError::InvalidArgument(format!(
            "sensors.status_count = {} exceeds VRS_HOST_MAX_STATUSES ({VRS_HOST_MAX_STATUSES})",
            s.status_count
        )));
    }
    if s.collision_count > VRS_HOST_MAX_COLLISIONS {
        return Err(FfiError::InvalidArgument(format!(
            "sensors.collision_count = {} exceeds VRS_HOST_MAX_COLLISIONS \
             ({VRS_HOST_MAX_COLLISIONS})",
            s.collision_count
        )));
    }
    let statuses = &s.statuses[..s.status_count as usize];
    if let Some((i, bad)) = statuses
        .iter()
        .enumerate()
        .find(|(_, st)| ActionState::from_u32(st.state).is_none())
    {
        return Err(FfiError::InvalidArgument(format!(
            "sensors.statuses[{i}].state = {} is not a vrs_host_action_state_t",
            bad.state
        )));
    }
    Ok(())
}

pub(crate) fn write_header(h: &mut vrsync_bridge::SensorHeader, s: &vrs_host_sensors_t) {
    // A zero rotation becomes the identity (see `From<vrs_pose_t> for Pose`).
    h.pose = s.pose.into();
    h.reward = s.reward;
    h.grid = s.grid.into();
    h.head_motion = s.head_motion.into();
    h.eye = s.eye.into();
    // Every entry is written, the unused ones zeroed: the sample may hold an older frame.
    h.status_count = s.status_count;
    for (i, dst) in h.statuses.iter_mut().enumerate() {
        *dst = match s.statuses.get(i) {
            Some(&src) if i < s.status_count as usize => src.into(),
            _ => ActionStatus::default(),
        };
    }
    h.collision_count = s.collision_count;
    for (i, dst) in h.collisions.iter_mut().enumerate() {
        *dst = match s.collisions.get(i) {
            Some(&src) if i < s.collision_count as usize => src.into(),
            _ => Collision::default(),
        };
    }
}

// ---------------------------------------------------------------------------------------
// Implementations
// ---------------------------------------------------------------------------------------

pub(crate) fn create_impl(
    config_path: *const c_char,
    out_host: *mut *mut vrs_host_t,
) -> Result<(), FfiError> {
    if out_host.is_null() {
        return Err(ArgError::Null("out_host").into());
    }
    // SAFETY: checked non-null; valid for writes by the caller's contract. Cleared first
    // so that a failed create leaves NULL behind.
    unsafe { out_host.write(std::ptr::null_mut()) };
    // SAFETY: a C string by the caller's contract.
    let path = unsafe { str_arg(config_path, "config_path") }?;
    let config = Config::load(path)?;
    // The C ABI keeps its documented behaviour: SIGINT/SIGTERM end waits with
    // VRS_HOST_ERROR_TERMINATED.
    let host = Host::builder(&config)
        .signal_handling(SignalHandling::Install)
        .create()?;
    let key = register(host)?;
    // SAFETY: as above. The handle is a registry key, never dereferenced.
    unsafe { out_host.write(std::ptr::without_provenance_mut(key)) };
    Ok(())
}

pub(crate) fn info_impl(
    host: *mut vrs_host_t,
    out_info: *mut vrs_host_info_t,
) -> Result<(), FfiError> {
    with_host(host, |st| {
        let h = &st.host;
        let c = h.config();
        let info = vrs_host_info_t {
            cycle: h.cycle(),
            sim_time_ns: h.sim_time_ns(),
            simulation_time_per_frame_ns: c.sync.simulation_time_per_frame.as_nanos() as u64,
            stop_timeout_ns: c.sync.stop_timeout.as_nanos() as u64,
            connect_timeout_ns: c.sync.connect_timeout.as_nanos() as u64,
            agent_count: st.ids.len() as u32,
            sync_mode: u32::from(c.sync.sync_mode),
            transport: vrs_host_transport_t::of(c.transport.kind),
            tcp_port: h.tcp_local_addr().map_or(0, |a| u32::from(a.port())),
            max_commands_per_cycle: c.transport.max_commands_per_cycle,
            protocol_version: vrsync_bridge::PROTOCOL_VERSION,
        };
        // SAFETY: null or writable by the caller's contract.
        unsafe { write_required(out_info, "out_info", info) }
    })
}

pub(crate) fn agent_info_impl(
    host: *mut vrs_host_t,
    index: u32,
    out_agent: *mut vrs_host_agent_info_t,
) -> Result<(), FfiError> {
    with_host(host, |st| {
        let i = index as usize;
        let agent = st.host.config().agents.get(i).ok_or(FfiError::OutOfRange {
            what: "agent",
            index: i,
            count: st.ids.len(),
        })?;
        let info = vrs_host_agent_info_t {
            agent_id: agent.id,
            camera_count: agent.cameras.len() as u32,
            connected: u32::from(st.host.is_connected(agent.id)),
            reserved: 0,
        };
        // SAFETY: null or writable by the caller's contract.
        unsafe { write_required(out_agent, "out_agent", info) }
    })
}

pub(crate) fn camera_impl(
    host: *mut vrs_host_t,
    agent_id: u32,
    index: u32,
    out_camera: *mut vrs_host_camera_t,
) -> Result<(), FfiError> {
    with_host(host, |st| {
        let slot = st.slot_of(agent_id)?;
        let cameras = &st.host.config().agents[slot].cameras;
        let i = index as usize;
        let c = cameras.get(i).ok_or(FfiError::OutOfRange {
            what: "camera",
            index: i,
            count: cameras.len(),
        })?;
        let info = vrs_host_camera_t {
            len: c.image_bytes() as u64,
            stride: c.stride_bytes() as u64,
            width: c.width_px,
            height: c.height_px,
            format: c.format.into(),
            fov_horizontal_deg: c.fov_horizontal_deg,
            fov_vertical_deg: c.fov_vertical_deg,
            name: c_name(&c.name),
        };
        // SAFETY: null or writable by the caller's contract.
        unsafe { write_required(out_camera, "out_camera", info) }
    })
}

pub(crate) fn wait_for_agents_impl(
    host: *mut vrs_host_t,
    timeout_ms: i64,
    out_missing: *mut u32,
    missing_capacity: u32,
    out_missing_count: *mut u32,
) -> Result<(vrs_host_status_t, String), FfiError> {
    if out_missing.is_null() && missing_capacity > 0 {
        return Err(ArgError::Null("out_missing (with missing_capacity > 0)").into());
    }
    with_host(host, |st| {
        st.expect_phase("vrs_host_wait_for_agents", Phase::Frames)?;
        let timeout = u64::try_from(timeout_ms)
            .map(Duration::from_millis)
            .unwrap_or(st.host.config().sync.connect_timeout);
        match st.host.wait_for_agents(timeout) {
            Ok(()) => {
                // SAFETY: null or writable by the caller's contract.
                unsafe { write_opt(out_missing_count, 0) };
                Ok((vrs_host_status_t::VRS_HOST_OK, String::new()))
            }
            Err(e @ HostWaitError::AgentsMissing { .. }) => {
                let message = e.to_string();
                if let HostWaitError::AgentsMissing { missing, .. } = e {
                    for (i, &id) in missing.iter().take(missing_capacity as usize).enumerate() {
                        // SAFETY: non-null (checked above when capacity > 0) and valid
                        // for `missing_capacity` writes by the caller's contract.
                        unsafe { out_missing.add(i).write(id) };
                    }
                    // SAFETY: null or writable by the caller's contract.
                    unsafe { write_opt(out_missing_count, missing.len() as u32) };
                }
                Ok((vrs_host_status_t::VRS_HOST_TIMEOUT, message))
            }
            Err(e) => Err(e.into()),
        }
    })
}

pub(crate) fn loan_frame_impl(
    host: *mut vrs_host_t,
    agent_id: u32,
    out_frame: *mut vrs_host_frame_t,
) -> Result<(), FfiError> {
    const CALL: &str = "vrs_host_loan_frame";
    with_host(host, |st| {
        st.expect_phase(CALL, Phase::Frames)?;
        let slot = st.slot_of(agent_id)?;
        let s = &st.slots[slot];
        if s.frame.is_some() {
            return Err(FfiError::WrongState {
                call: CALL,
                why: format!("agent {agent_id}'s frame is already loaned (publish or discard it)"),
            });
        }
        if s.published {
            return Err(FfiError::WrongState {
                call: CALL,
                why: format!(
                    "agent {agent_id}'s frame was already published this cycle (one frame per \
                     agent and cycle)"
                ),
            });
        }
        let mut frame = st.host.loan_frame(agent_id)?;
        let mut images = [None; vrsync_bridge::MAX_CAMERAS];
        for (dst, image) in images.iter_mut().zip(frame.images_mut()) {
            // The pointer stays valid while the loan lives in the slot: shared memory (or
            // the TCP record buffer) does not move with the `SensorFrameMut`.
            *dst = Some(ImageView {
                data: image.data.as_mut_ptr(),
                desc: image.desc,
            });
        }
        let h = frame.header();
        let info = vrs_host_frame_t {
            cycle: h.cycle,
            sim_time_ns: h.sim_time_ns,
            agent_id,
            image_count: images.iter().flatten().count() as u32,
        };
        let s = &mut st.slots[slot];
        s.frame = Some(frame);
        s.images = images;
        // SAFETY: null or writable by the caller's contract.
        unsafe { write_opt(out_frame, info) };
        Ok(())
    })
}

pub(crate) fn frame_image_impl(
    host: *mut vrs_host_t,
    agent_id: u32,
    index: u32,
    out_image: *mut vrs_host_image_t,
) -> Result<(), FfiError> {
    with_host(host, |st| {
        let slot = st.slot_of(agent_id)?;
        let s = &st.slots[slot];
        if s.frame.is_none() {
            return Err(FfiError::NoFrame {
                call: "vrs_host_frame_image",
                agent: agent_id,
            });
        }
        let count = s.images.iter().flatten().count();
        let view = s
            .images
            .get(index as usize)
            .and_then(Option::as_ref)
            .ok_or(FfiError::OutOfRange {
                what: "image",
                index: index as usize,
                count,
            })?;
        // SAFETY: null or writable by the caller's contract.
        unsafe { write_required(out_image, "out_image", image_info(view)) }
    })
}

pub(crate) fn frame_image_by_name_impl(
    host: *mut vrs_host_t,
    agent_id: u32,
    name: *const c_char,
    out_image: *mut vrs_host_image_t,
) -> Result<(), FfiError> {
    // SAFETY: a C string by the caller's contract.
    let name = unsafe { str_arg(name, "name") }?;
    with_host(host, |st| {
        let slot = st.slot_of(agent_id)?;
        let s = &st.slots[slot];
        if s.frame.is_none() {
            return Err(FfiError::NoFrame {
                call: "vrs_host_frame_image_by_name",
                agent: agent_id,
            });
        }
        let view = s
            .images
            .iter()
            .flatten()
            .find(|v| v.desc.name() == name)
            .ok_or_else(|| FfiError::NoSuchCamera {
                agent: agent_id,
                name: name.to_owned(),
            })?;
        // SAFETY: null or writable by the caller's contract.
        unsafe { write_required(out_image, "out_image", image_info(view)) }
    })
}

pub(crate) fn publish_impl(
    host: *mut vrs_host_t,
    agent_id: u32,
    sensors: *const vrs_host_sensors_t,
) -> Result<(), FfiError> {
    const CALL: &str = "vrs_host_publish";
    let sensors = if sensors.is_null() {
        vrs_host_sensors_t::default()
    } else {
        // SAFETY: non-null and valid for reads by the caller's contract. Read unaligned:
        // a binding may hand over a packed copy.
        unsafe { sensors.read_unaligned() }
    };
    check_sensors(&sensors)?;
    with_host(host, |st| {
        st.expect_phase(CALL, Phase::Frames)?;
        let slot = st.slot_of(agent_id)?;
        let s = &mut st.slots[slot];
        let mut frame = s.frame.take().ok_or(FfiError::NoFrame {
            call: CALL,
            agent: agent_id,
        })?;
        s.images = [None; vrsync_bridge::MAX_CAMERAS];
        write_header(frame.header_mut(), &sensors);
        st.host.publish(frame)?;
        st.slots[slot].published = true;
        Ok(())
    })
}

pub(crate) fn discard_frame_impl(host: *mut vrs_host_t, agent_id: u32) -> Result<(), FfiError> {
    with_host(host, |st| {
        let slot = st.slot_of(agent_id)?;
        let s = &mut st.slots[slot];
        s.images = [None; vrsync_bridge::MAX_CAMERAS];
        // Dropping the loan returns the memory unpublished.
        s.frame.take().map(drop).ok_or(FfiError::NoFrame {
            call: "vrs_host_discard_frame",
            agent: agent_id,
        })
    })
}

pub(crate) fn start_impl(host: *mut vrs_host_t) -> Result<(), FfiError> {
    const CALL: &str = "vrs_host_start";
    with_host(host, |st| {
        st.expect_phase(CALL, Phase::Frames)?;
        let loaned: Vec<u32> = st
            .ids
            .iter()
            .zip(&st.slots)
            .filter(|(_, s)| s.frame.is_some())
            .map(|(&id, _)| id)
            .collect();
        if !loaned.is_empty() {
            return Err(FfiError::WrongState {
                call: CALL,
                why: format!(
                    "the frames of agents {loaned:?} are loaned but not published (publish or \
                     discard them first)"
                ),
            });
        }
        st.host.start()?;
        st.phase = Phase::Started;
        Ok(())
    })
}

pub(crate) fn collect_impl(
    host: *mut vrs_host_t,
    out_cycle: *mut vrs_host_cycle_t,
) -> Result<(), FfiError> {
    with_host(host, |st| {
        st.expect_phase("vrs_host_collect", Phase::Started)?;
        let report = st.host.collect()?;
        st.cycle = copy_report(&mut st.reports, report);
        st.phase = Phase::Collected;
        // SAFETY: null or writable by the caller's contract.
        unsafe { write_opt(out_cycle, st.cycle) };
        Ok(())
    })
}

pub(crate) fn agent_report_impl(
    host: *mut vrs_host_t,
    index: u32,
    out_report: *mut vrs_host_agent_report_t,
) -> Result<(), FfiError> {
    with_host(host, |st| {
        st.expect_phase("vrs_host_agent_report", Phase::Collected)?;
        let count = st.reports.len();
        let r = st.reports.get(index as usize).ok_or(FfiError::OutOfRange {
            what: "agent report",
            index: index as usize,
            count,
        })?;
        // SAFETY: null or writable by the caller's contract.
        unsafe { write_required(out_report, "out_report", agent_report(r)) }
    })
}

pub(crate) fn agent_report_by_id_impl(
    host: *mut vrs_host_t,
    agent_id: u32,
    out_report: *mut vrs_host_agent_report_t,
) -> Result<(), FfiError> {
    with_host(host, |st| {
        st.expect_phase("vrs_host_agent_report_by_id", Phase::Collected)?;
        let r = st
            .reports
            .iter()
            .find(|r| r.agent_id == agent_id)
            .ok_or(FfiError::UnknownAgent(agent_id))?;
        // SAFETY: null or writable by the caller's contract.
        unsafe { write_required(out_report, "out_report", agent_report(r)) }
    })
}

pub(crate) fn agent_report(r: &ReportCopy) -> vrs_host_agent_report_t {
    vrs_host_agent_report_t {
        agent_id: r.agent_id,
        outcome: r.outcome,
        command_count: r.commands.len() as u32,
        reserved: 0,
        commands: if r.commands.is_empty() {
            std::ptr::null()
        } else {
            // Same layout (asserted in types.rs); the buffer is not touched until
            // vrs_host_end_cycle.
            r.commands.as_ptr().cast::<vrs_host_command_t>()
        },
        read_cycle: r
            .read_cycle
            .map_or(-1, |c| i64::try_from(c).unwrap_or(i64::MAX)),
        evicted: u32::from(r.evicted),
        rejoined: u32::from(r.rejoined),
        left: u32::from(r.left),
        slow: u32::from(r.slow),
    }
}

pub(crate) fn command_impl(
    host: *mut vrs_host_t,
    agent_index: u32,
    command_index: u32,
    out_command: *mut vrs_host_command_t,
) -> Result<(), FfiError> {
    with_host(host, |st| {
        st.expect_phase("vrs_host_command", Phase::Collected)?;
        let count = st.reports.len();
        let r = st
            .reports
            .get(agent_index as usize)
            .ok_or(FfiError::OutOfRange {
                what: "agent report",
                index: agent_index as usize,
                count,
            })?;
        let c = r
            .commands
            .get(command_index as usize)
            .ok_or(FfiError::OutOfRange {
                what: "command",
                index: command_index as usize,
                count: r.commands.len(),
            })?;
        let command = vrs_host_command_t {
            kind: c.kind,
            action_id: c.action_id,
            object_id: c.object_id,
            reserved: c.reserved,
            args: c.args,
        };
        // SAFETY: null or writable by the caller's contract.
        unsafe { write_required(out_command, "out_command", command) }
    })
}

pub(crate) fn set_rejected_impl(
    host: *mut vrs_host_t,
    agent_id: u32,
    rejected: u32,
) -> Result<(), FfiError> {
    with_host(host, |st| {
        st.slot_of(agent_id)?;
        st.host.set_rejected(agent_id, rejected);
        Ok(())
    })
}

pub(crate) fn end_cycle_impl(host: *mut vrs_host_t) -> Result<(), FfiError> {
    with_host(host, |st| {
        st.expect_phase("vrs_host_end_cycle", Phase::Collected)?;
        for s in &mut st.slots {
            s.published = false;
        }
        for r in &mut st.reports {
            r.commands.clear();
        }
        st.phase = Phase::Frames;
        Ok(())
    })
}

pub(crate) fn stats_impl(
    host: *mut vrs_host_t,
    out_stats: *mut vrs_host_stats_t,
) -> Result<(), FfiError> {
    with_host(host, |st| {
        let stats = vrs_host_stats_t::from(st.host.stats());
        // SAFETY: null or writable by the caller's contract.
        unsafe { write_required(out_stats, "out_stats", stats) }
    })
}

pub(crate) fn init_logging_impl(filter: *const c_char) -> Result<(), FfiError> {
    // SAFETY: a C string by the caller's contract.
    let filter = unsafe { log_filter(filter) }?;
    use tracing_subscriber::Layer;
    use tracing_subscriber::layer::SubscriberExt;
    use tracing_subscriber::util::SubscriberInitExt;
    tracing_subscriber::registry()
        .with(
            tracing_subscriber::fmt::layer()
                .with_writer(std::io::stderr)
                // Colour only on a terminal without NO_COLOR: a host's stderr is often a log
                // file (Unity's `Editor.log`). The rule vr-sim and the agent SDK use too.
                .with_ansi(vrsync_bridge::ansi_on_stderr())
                .with_filter(filter),
        )
        // Peers dropped in a TLS handshake count as refused (whatever the filter).
        .with(vrsync_bridge::refusal_layer())
        .try_init()
        .map_err(|_| FfiError::LoggingAlreadySet)
}
