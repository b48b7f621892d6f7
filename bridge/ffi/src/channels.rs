//! Channels (`[[agent.vector]]`, `[[agent.action]]`) in the host C ABI: the specs of each
//! agent's channels from the config, the vectors of a loaned frame as writable memory (the
//! memory the agent reads, on shared memory), and the actions each agent sent in the cycle
//! just collected. The structs, the `*_impl` functions and the exports, each export a
//! thin wrapper as in `ffi.rs`.

#![allow(non_camel_case_types)]

use std::ffi::c_char;

use vrsync_bridge::ActionSpace;
use vrsync_cabi::{c_name, str_arg, write_opt, write_required};

use crate::state::{FfiError, HostState, Phase, ReportCopy, boundary, with_host};
use crate::types::*;

// For the doc links only (the header keeps the `[`name`]` text).
#[cfg(doc)]
use crate::vrs_host_end_cycle;

// ---------------------------------------------------------------------------------------
// Types
// ---------------------------------------------------------------------------------------

/// One writable vector of a loaned frame: on shared memory, the memory the agent will
/// read. The floats hold an older frame's values until written: write all of them.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct vrs_host_vector_t {
    /// First value. Valid until the frame is published or discarded.
    pub data: *mut f32,
    /// Number of floats at `data`.
    pub len: u32,
    /// Index of the vector in the agent's vector list.
    pub index: u32,
    /// Vector name, NUL-terminated.
    pub name: [c_char; VRS_HOST_CHANNEL_NAME_SIZE],
}

/// One vector (`[[agent.vector]]`) of an agent, from the config.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct vrs_host_vector_spec_t {
    /// `len` lower bounds (`-INFINITY` where the config gives none): the observation
    /// space, for the agent's information (not enforced). Valid until the host is
    /// destroyed.
    pub low: *const f32,
    /// `len` upper bounds (`INFINITY` where the config gives none).
    pub high: *const f32,
    /// Number of floats.
    pub len: u32,
    /// Index of the vector in the agent's vector list.
    pub index: u32,
    /// Vector name, NUL-terminated.
    pub name: [c_char; VRS_HOST_CHANNEL_NAME_SIZE],
}

/// One action (`[[agent.action]]`) of an agent, from the config.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct vrs_host_action_spec_t {
    /// Continuous: `len` lower bounds; discrete: NULL. Valid until the host is destroyed.
    pub low: *const f32,
    /// Continuous: `len` upper bounds; discrete: NULL.
    pub high: *const f32,
    /// Continuous: number of floats of a value; discrete: 0.
    pub len: u32,
    /// Discrete: number of choices; continuous: 0.
    pub n: u32,
    /// `VRS_HOST_ACTION_KIND_BOX` or `VRS_HOST_ACTION_KIND_DISCRETE`.
    pub kind: vrs_host_action_kind_t,
    /// Index of the action in the agent's action list.
    pub index: u32,
    /// Action name, NUL-terminated.
    pub name: [c_char; VRS_HOST_CHANNEL_NAME_SIZE],
}

/// What an agent sent for one action in the cycle just collected: the last complete value
/// of the cycle, already checked against the config (length, bounds, finite; a choice
/// below `n`). Values that failed the checks were never applied
/// (`vrs_host_actions_rejected`).
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct vrs_host_action_value_t {
    /// `VRS_HOST_ACTION_KIND_BOX`: `len` floats, valid until `vrs_host_end_cycle`;
    /// otherwise NULL.
    pub values: *const f32,
    /// Number of floats at `values` (0 unless `kind` is `VRS_HOST_ACTION_KIND_BOX`).
    pub len: u32,
    /// `VRS_HOST_ACTION_KIND_DISCRETE`: the choice; otherwise 0.
    pub choice: u32,
    /// What was sent: `VRS_HOST_ACTION_KIND_NONE` when nothing was (keep the previous
    /// value, or apply a default: the simulator's choice).
    pub kind: vrs_host_action_kind_t,
    /// Index of the action in the agent's action list.
    pub index: u32,
    /// Action name, NUL-terminated.
    pub name: [c_char; VRS_HOST_CHANNEL_NAME_SIZE],
}

// ---------------------------------------------------------------------------------------
// Implementations
// ---------------------------------------------------------------------------------------

/// The names of `names`, comma separated, or "none".
fn known<'a>(names: impl Iterator<Item = &'a str>) -> String {
    let list: Vec<&str> = names.collect();
    if list.is_empty() {
        "none".to_owned()
    } else {
        list.join(", ")
    }
}

/// The config of agent `agent_id` (which must be one of the host's).
fn agent_config(st: &HostState, agent_id: u32) -> Result<&vrsync_bridge::AgentConfig, FfiError> {
    st.slot_of(agent_id)?;
    st.host
        .config()
        .agent(agent_id)
        .ok_or(FfiError::UnknownAgent(agent_id))
}

fn channel_counts_impl(
    host: *mut vrs_host_t,
    agent_id: u32,
    out_vector_count: *mut u32,
    out_action_count: *mut u32,
) -> Result<(), FfiError> {
    with_host(host, |st| {
        let a = agent_config(st, agent_id)?;
        // SAFETY: null or writable by the caller's contract.
        unsafe {
            write_opt(out_vector_count, a.vectors.len() as u32);
            write_opt(out_action_count, a.actions.len() as u32);
        }
        Ok(())
    })
}

fn vector_spec_impl(
    host: *mut vrs_host_t,
    agent_id: u32,
    index: u32,
    out_spec: *mut vrs_host_vector_spec_t,
) -> Result<(), FfiError> {
    with_host(host, |st| {
        let vectors = &agent_config(st, agent_id)?.vectors;
        let v = vectors.get(index as usize).ok_or(FfiError::OutOfRange {
            what: "vector",
            index: index as usize,
            count: vectors.len(),
        })?;
        let spec = vrs_host_vector_spec_t {
            low: v.low.as_ptr(),
            high: v.high.as_ptr(),
            len: v.len,
            index,
            name: c_name(&v.name),
        };
        // SAFETY: null or writable by the caller's contract.
        unsafe { write_required(out_spec, "out_spec", spec) }
    })
}

fn action_spec_impl(
    host: *mut vrs_host_t,
    agent_id: u32,
    index: u32,
    out_spec: *mut vrs_host_action_spec_t,
) -> Result<(), FfiError> {
    with_host(host, |st| {
        let actions = &agent_config(st, agent_id)?.actions;
        let a = actions.get(index as usize).ok_or(FfiError::OutOfRange {
            what: "action",
            index: index as usize,
            count: actions.len(),
        })?;
        let (low, high, len, n) = match &a.space {
            ActionSpace::Box { low, high } => (low.as_ptr(), high.as_ptr(), low.len() as u32, 0),
            ActionSpace::Discrete { n } => (std::ptr::null(), std::ptr::null(), 0, *n),
        };
        let spec = vrs_host_action_spec_t {
            low,
            high,
            len,
            n,
            kind: vrs_host_action_kind_t::of(&a.space),
            index,
            name: c_name(&a.name),
        };
        // SAFETY: null or writable by the caller's contract.
        unsafe { write_required(out_spec, "out_spec", spec) }
    })
}

/// Which vector of agent `agent_id`'s loaned frame: by index or by name.
enum Which<'a> {
    Index(u32),
    Name(&'a str),
}

fn frame_vector_impl(
    host: *mut vrs_host_t,
    agent_id: u32,
    which: Which<'_>,
    call: &'static str,
    out_vector: *mut vrs_host_vector_t,
) -> Result<(), FfiError> {
    with_host(host, |st| {
        let slot = st.slot_of(agent_id)?;
        let frame = st.slots[slot].frame.as_mut().ok_or(FfiError::NoFrame {
            call,
            agent: agent_id,
        })?;
        let descs = frame.vector_descs();
        let index = match which {
            Which::Index(i) if (i as usize) < descs.len() => i as usize,
            Which::Index(i) => {
                return Err(FfiError::OutOfRange {
                    what: "vector",
                    index: i as usize,
                    count: descs.len(),
                });
            }
            Which::Name(name) => descs.iter().position(|d| d.name() == name).ok_or_else(|| {
                FfiError::NoSuchChannel {
                    agent: agent_id,
                    what: "vector",
                    name: name.to_owned(),
                    known: known(descs.iter().map(|d| d.name())),
                }
            })?,
        };
        let desc = descs[index];
        // The host laid the frame out from its own config: every vector of its table lies
        // in the payload, 4-byte aligned.
        let values = frame.vector_mut(desc.name()).ok_or_else(|| {
            FfiError::InvalidArgument(format!(
                "agent {agent_id}'s vector {:?} does not lie in its frame",
                desc.name()
            ))
        })?;
        let info = vrs_host_vector_t {
            // The pointer stays valid while the loan lives in the slot, as the images'.
            data: values.as_mut_ptr(),
            len: desc.len,
            index: index as u32,
            name: c_name(desc.name()),
        };
        // SAFETY: null or writable by the caller's contract.
        unsafe { write_required(out_vector, "out_vector", info) }
    })
}

/// The report copy of agent `agent_id` in the cycle just collected.
fn collected<'s>(
    st: &'s HostState,
    agent_id: u32,
    call: &'static str,
) -> Result<&'s ReportCopy, FfiError> {
    st.expect_phase(call, Phase::Collected)?;
    st.reports
        .iter()
        .find(|r| r.agent_id == agent_id)
        .ok_or(FfiError::UnknownAgent(agent_id))
}

fn action_impl(
    host: *mut vrs_host_t,
    agent_id: u32,
    which: Which<'_>,
    call: &'static str,
    out_action: *mut vrs_host_action_value_t,
) -> Result<(), FfiError> {
    with_host(host, |st| {
        let r = collected(st, agent_id, call)?;
        let index = match which {
            Which::Index(i) if (i as usize) < r.actions.len() => i as usize,
            Which::Index(i) => {
                return Err(FfiError::OutOfRange {
                    what: "action",
                    index: i as usize,
                    count: r.actions.len(),
                });
            }
            Which::Name(name) => {
                let specs = &agent_config(st, agent_id)?.actions;
                specs.iter().position(|a| a.name == name).ok_or_else(|| {
                    FfiError::NoSuchChannel {
                        agent: agent_id,
                        what: "action",
                        name: name.to_owned(),
                        known: known(specs.iter().map(|a| a.name.as_str())),
                    }
                })?
            }
        };
        let a = r.actions.get(index).ok_or(FfiError::OutOfRange {
            what: "action",
            index,
            count: r.actions.len(),
        })?;
        let boxed = a.kind == vrs_host_action_kind_t::VRS_HOST_ACTION_KIND_BOX;
        let value = vrs_host_action_value_t {
            // The buffer is not touched until the next collect (reads end at
            // vrs_host_end_cycle).
            values: if boxed {
                a.values.as_ptr()
            } else {
                std::ptr::null()
            },
            len: if boxed { a.values.len() as u32 } else { 0 },
            choice: a.choice,
            kind: a.kind,
            index: index as u32,
            name: a.name,
        };
        // SAFETY: null or writable by the caller's contract.
        unsafe { write_required(out_action, "out_action", value) }
    })
}

fn actions_rejected_impl(
    host: *mut vrs_host_t,
    agent_id: u32,
    out_rejected: *mut u32,
) -> Result<(), FfiError> {
    with_host(host, |st| {
        let r = collected(st, agent_id, "vrs_host_actions_rejected")?;
        // SAFETY: null or writable by the caller's contract.
        unsafe { write_required(out_rejected, "out_rejected", r.actions_rejected) }
    })
}

// ---------------------------------------------------------------------------------------
// The exported functions
// ---------------------------------------------------------------------------------------

sizeof_fns! {
    vrs_host_sizeof_vector => vrs_host_vector_t,
    vrs_host_sizeof_vector_spec => vrs_host_vector_spec_t,
    vrs_host_sizeof_action_spec => vrs_host_action_spec_t,
    vrs_host_sizeof_action_value => vrs_host_action_value_t,
}

/// How many vectors (`[[agent.vector]]`) and actions (`[[agent.action]]`) agent
/// `agent_id` has in the config: [`vrs_host_vector_spec`] and [`vrs_host_action_spec`]
/// indices. Either out pointer may be NULL.
///
/// # Errors
/// `VRS_HOST_ERROR_UNKNOWN_AGENT`, handle errors.
///
/// # Safety
/// Any handle value may be passed; `out_vector_count` and `out_action_count` are each
/// NULL or valid for writing a `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_host_channel_counts(
    host: *mut vrs_host_t,
    agent_id: u32,
    out_vector_count: *mut u32,
    out_action_count: *mut u32,
) -> vrs_host_status_t {
    boundary(|| channel_counts_impl(host, agent_id, out_vector_count, out_action_count))
}

/// Vector `index` of agent `agent_id` as configured (name, length, observation bounds):
/// to prepare what to write before the first cycle.
///
/// # Errors
/// `VRS_HOST_ERROR_UNKNOWN_AGENT`, `VRS_HOST_ERROR_OUT_OF_RANGE`,
/// `VRS_HOST_ERROR_INVALID_ARGUMENT` (NULL `out_spec`), handle errors.
///
/// # Safety
/// Any handle value may be passed; `out_spec` is NULL or valid for writing a
/// [`vrs_host_vector_spec_t`].
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_host_vector_spec(
    host: *mut vrs_host_t,
    agent_id: u32,
    index: u32,
    out_spec: *mut vrs_host_vector_spec_t,
) -> vrs_host_status_t {
    boundary(|| vector_spec_impl(host, agent_id, index, out_spec))
}

/// Action `index` of agent `agent_id` as configured (name, kind, length and bounds, or
/// number of choices).
///
/// # Errors
/// `VRS_HOST_ERROR_UNKNOWN_AGENT`, `VRS_HOST_ERROR_OUT_OF_RANGE`,
/// `VRS_HOST_ERROR_INVALID_ARGUMENT` (NULL `out_spec`), handle errors.
///
/// # Safety
/// Any handle value may be passed; `out_spec` is NULL or valid for writing a
/// [`vrs_host_action_spec_t`].
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_host_action_spec(
    host: *mut vrs_host_t,
    agent_id: u32,
    index: u32,
    out_spec: *mut vrs_host_action_spec_t,
) -> vrs_host_status_t {
    boundary(|| action_spec_impl(host, agent_id, index, out_spec))
}

/// Vector `index` (config order) of agent `agent_id`'s loaned frame: where to write its
/// floats, the memory the agent reads (on shared memory; no copy). `data` stays valid
/// until the frame is published or discarded, or the host destroyed.
///
/// # Errors
/// `VRS_HOST_ERROR_NO_FRAME`, `VRS_HOST_ERROR_OUT_OF_RANGE`,
/// `VRS_HOST_ERROR_UNKNOWN_AGENT`, `VRS_HOST_ERROR_INVALID_ARGUMENT` (NULL
/// `out_vector`), handle errors.
///
/// # Safety
/// Any handle value may be passed; `out_vector` is NULL or valid for writing a
/// [`vrs_host_vector_t`]. Writes through `data` must stay within `len` floats.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_host_frame_vector(
    host: *mut vrs_host_t,
    agent_id: u32,
    index: u32,
    out_vector: *mut vrs_host_vector_t,
) -> vrs_host_status_t {
    boundary(|| {
        frame_vector_impl(
            host,
            agent_id,
            Which::Index(index),
            "vrs_host_frame_vector",
            out_vector,
        )
    })
}

/// Like [`vrs_host_frame_vector`], by vector name (`"joints"`, …).
///
/// # Errors
/// `VRS_HOST_ERROR_UNKNOWN_CHANNEL` (no such vector: the message lists the agent's),
/// `VRS_HOST_ERROR_NO_FRAME`, `VRS_HOST_ERROR_UNKNOWN_AGENT`,
/// `VRS_HOST_ERROR_INVALID_ARGUMENT` (NULL pointers, not UTF-8), handle errors.
///
/// # Safety
/// Any handle value may be passed; `name` is NULL or a valid NUL-terminated string;
/// `out_vector` is NULL or valid for writing a [`vrs_host_vector_t`].
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_host_frame_vector_by_name(
    host: *mut vrs_host_t,
    agent_id: u32,
    name: *const c_char,
    out_vector: *mut vrs_host_vector_t,
) -> vrs_host_status_t {
    boundary(|| {
        // SAFETY: a C string by the caller's contract.
        let name = unsafe { str_arg(name, "name") }?;
        frame_vector_impl(
            host,
            agent_id,
            Which::Name(name),
            "vrs_host_frame_vector_by_name",
            out_vector,
        )
    })
}

/// Action `index` (config order) of agent `agent_id` in the cycle just collected: what
/// it sent (`kind` `VRS_HOST_ACTION_KIND_NONE` when nothing). `values` stays valid until
/// [`vrs_host_end_cycle`].
///
/// # Errors
/// `VRS_HOST_ERROR_WRONG_STATE` (not collected), `VRS_HOST_ERROR_UNKNOWN_AGENT`,
/// `VRS_HOST_ERROR_OUT_OF_RANGE`, `VRS_HOST_ERROR_INVALID_ARGUMENT` (NULL `out_action`),
/// handle errors.
///
/// # Safety
/// Any handle value may be passed; `out_action` is NULL or valid for writing a
/// [`vrs_host_action_value_t`].
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_host_action(
    host: *mut vrs_host_t,
    agent_id: u32,
    index: u32,
    out_action: *mut vrs_host_action_value_t,
) -> vrs_host_status_t {
    boundary(|| {
        action_impl(
            host,
            agent_id,
            Which::Index(index),
            "vrs_host_action",
            out_action,
        )
    })
}

/// Like [`vrs_host_action`], by action name (`"torque"`, …).
///
/// # Errors
/// `VRS_HOST_ERROR_UNKNOWN_CHANNEL` (no such action: the message lists the agent's),
/// `VRS_HOST_ERROR_WRONG_STATE`, `VRS_HOST_ERROR_UNKNOWN_AGENT`,
/// `VRS_HOST_ERROR_INVALID_ARGUMENT` (NULL pointers, not UTF-8), handle errors.
///
/// # Safety
/// Any handle value may be passed; `name` is NULL or a valid NUL-terminated string;
/// `out_action` is NULL or valid for writing a [`vrs_host_action_value_t`].
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_host_action_by_name(
    host: *mut vrs_host_t,
    agent_id: u32,
    name: *const c_char,
    out_action: *mut vrs_host_action_value_t,
) -> vrs_host_status_t {
    boundary(|| {
        // SAFETY: a C string by the caller's contract.
        let name = unsafe { str_arg(name, "name") }?;
        action_impl(
            host,
            agent_id,
            Which::Name(name),
            "vrs_host_action_by_name",
            out_action,
        )
    })
}

/// How many of agent `agent_id`'s action chunks the cycle just collected refused (an
/// unknown action, a wrong length, out of bounds or not finite, a choice out of range):
/// none of it was applied. The total since the start: `actions_rejected` of
/// [`vrs_host_stats_t`].
///
/// # Errors
/// `VRS_HOST_ERROR_WRONG_STATE` (not collected), `VRS_HOST_ERROR_UNKNOWN_AGENT`,
/// `VRS_HOST_ERROR_INVALID_ARGUMENT` (NULL `out_rejected`), handle errors.
///
/// # Safety
/// Any handle value may be passed; `out_rejected` is NULL or valid for writing a
/// `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_host_actions_rejected(
    host: *mut vrs_host_t,
    agent_id: u32,
    out_rejected: *mut u32,
) -> vrs_host_status_t {
    boundary(|| actions_rejected_impl(host, agent_id, out_rejected))
}
