//! Channels (`[[agent.vector]]`, `[[agent.action]]`): the vectors of the current frame as
//! views into shared memory, the agent's channel specs, and the actions it sends. The
//! structs, the `*_impl` functions and the exports, each export a thin wrapper as in
//! `exports.rs`.

use std::ffi::c_char;

use vrsync_cabi::{ArgError, c_name, str_arg, write_opt, write_required};
use vrsync_transport::{ActionSpace, VectorDesc};

use super::calls::current_frame;
use super::state::{FfiError, boundary, with_agent};
use super::types::*;
use sdk::{ActError, Frame};

// For the doc links only (the header keeps the `[`name`]` text).
#[cfg(doc)]
use super::{vrs_agent_disconnect, vrs_agent_stop, vrs_agent_wait_start};

// ---------------------------------------------------------------------------------------
// Types
// ---------------------------------------------------------------------------------------

/// What an action holds ([`vrs_action_spec_t::kind`]). The same numbers as the host
/// API's `vrs_host_action_kind_t`.
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum vrs_action_kind_t {
    /// Nothing (a zeroed struct).
    VRS_ACTION_KIND_NONE = 0,
    /// A continuous action: `len` floats, each within its `low` and `high`.
    VRS_ACTION_KIND_BOX = 1,
    /// A discrete action: a choice in `0..n`.
    VRS_ACTION_KIND_DISCRETE = 2,
}

/// One vector of the current frame: a view into shared memory (on the shm transport), no
/// copy.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct vrs_vector_t {
    /// First value. Valid until the next wait, stop or disconnect; do not write through
    /// it.
    pub data: *const f32,
    /// Number of values at `data`.
    pub len: usize,
    /// Index of the vector in the agent's vector list.
    pub index: u32,
    /// Vector name, NUL-terminated.
    pub name: [c_char; VRS_CHANNEL_NAME_SIZE],
}

/// One vector (`[[agent.vector]]`) of this agent as its config declares it.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct vrs_vector_spec_t {
    /// `len` lower bounds (`-INFINITY` where the config gives none): the observation
    /// space, not enforced. Valid until the agent is disconnected.
    pub low: *const f32,
    /// `len` upper bounds (`INFINITY` where the config gives none).
    pub high: *const f32,
    /// Number of values.
    pub len: usize,
    /// Index of the vector in the agent's vector list.
    pub index: u32,
    /// Vector name, NUL-terminated.
    pub name: [c_char; VRS_CHANNEL_NAME_SIZE],
}

/// One action (`[[agent.action]]`) of this agent as its config declares it.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct vrs_action_spec_t {
    /// Continuous: `len` lower bounds; discrete: NULL. Valid until the agent is
    /// disconnected.
    pub low: *const f32,
    /// Continuous: `len` upper bounds; discrete: NULL.
    pub high: *const f32,
    /// Continuous: number of floats of a value; discrete: 0.
    pub len: usize,
    /// Discrete: number of choices; continuous: 0.
    pub n: u32,
    /// Continuous or discrete.
    pub kind: vrs_action_kind_t,
    /// Index of the action in the agent's action list.
    pub index: u32,
    /// Action name, NUL-terminated.
    pub name: [c_char; VRS_CHANNEL_NAME_SIZE],
}

// ---------------------------------------------------------------------------------------
// Implementations
// ---------------------------------------------------------------------------------------

fn vector_info(frame: &Frame, index: usize, d: &VectorDesc) -> Result<vrs_vector_t, FfiError> {
    // The SDK checked the frame's vector table against the config at the wait, so a
    // vector of the table always lies in the payload.
    let values = frame.vector(d.name()).ok_or_else(|| {
        FfiError::Protocol(format!(
            "vector {:?} does not lie in the frame's payload",
            d.name()
        ))
    })?;
    Ok(vrs_vector_t {
        data: values.as_ptr(),
        len: values.len(),
        index: index as u32,
        name: c_name(d.name()),
    })
}

/// The names of `names`, comma separated, or "none".
fn known<'a>(names: impl Iterator<Item = &'a str>) -> String {
    let list: Vec<&str> = names.collect();
    if list.is_empty() {
        "none".to_owned()
    } else {
        list.join(", ")
    }
}

fn vector_impl(
    agent: *mut vrs_agent_t,
    index: usize,
    out_vector: *mut vrs_vector_t,
) -> Result<(), FfiError> {
    with_agent(agent, |st| {
        let frame = current_frame(st)?;
        let descs = frame.vector_descs();
        let d = descs.get(index).ok_or(FfiError::OutOfRange {
            what: "vector",
            index,
            count: descs.len(),
        })?;
        let info = vector_info(frame, index, d)?;
        // SAFETY: null or writable by the caller's contract.
        unsafe { write_required(out_vector, "out_vector", info) }
    })
}

fn vector_by_name_impl(
    agent: *mut vrs_agent_t,
    name: *const c_char,
    out_vector: *mut vrs_vector_t,
) -> Result<(), FfiError> {
    // SAFETY: a C string by the caller's contract.
    let name = unsafe { str_arg(name, "name") }?;
    with_agent(agent, |st| {
        let frame = current_frame(st)?;
        let descs = frame.vector_descs();
        let index =
            descs
                .iter()
                .position(|d| d.name() == name)
                .ok_or_else(|| FfiError::NoSuchVector {
                    agent: st.agent.id(),
                    name: name.to_owned(),
                    known: known(descs.iter().map(VectorDesc::name)),
                })?;
        let info = vector_info(frame, index, &descs[index])?;
        // SAFETY: null or writable by the caller's contract.
        unsafe { write_required(out_vector, "out_vector", info) }
    })
}

fn channel_counts_impl(
    agent: *mut vrs_agent_t,
    out_vector_count: *mut u32,
    out_action_count: *mut u32,
) -> Result<(), FfiError> {
    with_agent(agent, |st| {
        // SAFETY: null or writable by the caller's contract.
        unsafe {
            write_opt(out_vector_count, st.vectors.len() as u32);
            write_opt(out_action_count, st.agent.actions().len() as u32);
        }
        Ok(())
    })
}

fn vector_spec_impl(
    agent: *mut vrs_agent_t,
    index: usize,
    out_spec: *mut vrs_vector_spec_t,
) -> Result<(), FfiError> {
    with_agent(agent, |st| {
        let v = st.vectors.get(index).ok_or(FfiError::OutOfRange {
            what: "vector",
            index,
            count: st.vectors.len(),
        })?;
        let spec = vrs_vector_spec_t {
            low: v.low.as_ptr(),
            high: v.high.as_ptr(),
            len: v.len as usize,
            index: index as u32,
            name: c_name(&v.name),
        };
        // SAFETY: null or writable by the caller's contract.
        unsafe { write_required(out_spec, "out_spec", spec) }
    })
}

fn action_spec_impl(
    agent: *mut vrs_agent_t,
    index: usize,
    out_spec: *mut vrs_action_spec_t,
) -> Result<(), FfiError> {
    with_agent(agent, |st| {
        let actions = st.agent.actions();
        let a = actions.get(index).ok_or(FfiError::OutOfRange {
            what: "action",
            index,
            count: actions.len(),
        })?;
        let (low, high, len, n, kind) = match &a.space {
            ActionSpace::Box { low, high } => (
                low.as_ptr(),
                high.as_ptr(),
                low.len(),
                0,
                vrs_action_kind_t::VRS_ACTION_KIND_BOX,
            ),
            ActionSpace::Discrete { n } => (
                std::ptr::null(),
                std::ptr::null(),
                0,
                *n,
                vrs_action_kind_t::VRS_ACTION_KIND_DISCRETE,
            ),
        };
        let spec = vrs_action_spec_t {
            low,
            high,
            len,
            n,
            kind,
            index: index as u32,
            name: c_name(&a.name),
        };
        // SAFETY: null or writable by the caller's contract.
        unsafe { write_required(out_spec, "out_spec", spec) }
    })
}

/// The SDK's refusal as the boundary's error: a full queue gets the action's name.
fn act_error(name: &str, e: ActError) -> FfiError {
    match e {
        ActError::Queue(source) => FfiError::ActQueue {
            action: name.to_owned(),
            source,
        },
        other => FfiError::Act(other),
    }
}

fn act_impl(
    agent: *mut vrs_agent_t,
    name: *const c_char,
    values: *const f32,
    len: usize,
) -> Result<(), FfiError> {
    // SAFETY: a C string by the caller's contract.
    let name = unsafe { str_arg(name, "name") }?;
    let values: &[f32] = if len == 0 {
        &[]
    } else if values.is_null() {
        return Err(ArgError::Null("values (with len > 0)").into());
    } else {
        // SAFETY: non-null and valid for reading `len` floats by the caller's contract;
        // any bit pattern is an f32.
        unsafe { std::slice::from_raw_parts(values, len) }
    };
    with_agent(agent, |st| {
        st.agent.act(name, values).map_err(|e| act_error(name, e))
    })
}

fn act_discrete_impl(
    agent: *mut vrs_agent_t,
    name: *const c_char,
    choice: u32,
) -> Result<(), FfiError> {
    // SAFETY: a C string by the caller's contract.
    let name = unsafe { str_arg(name, "name") }?;
    with_agent(agent, |st| {
        st.agent
            .act_discrete(name, choice)
            .map_err(|e| act_error(name, e))
    })
}

// ---------------------------------------------------------------------------------------
// The exported functions
// ---------------------------------------------------------------------------------------

/// Vector `index` (`0..vector_count` of [`vrs_agent_channel_counts`], config order) of the
/// current frame: `out_vector->data` points into shared memory (no copy) and stays valid
/// until the next [`vrs_agent_wait_start`], [`vrs_agent_stop`] or
/// [`vrs_agent_disconnect`], like image data.
///
/// # Errors
/// `VRS_ERROR_OUT_OF_RANGE`, `VRS_ERROR_NO_FRAME`, `VRS_ERROR_INVALID_ARGUMENT` (NULL
/// `out_vector`), handle errors.
///
/// # Safety
/// `out_vector` is NULL or valid for writing a `vrs_vector_t`. Do not write through
/// `out_vector->data`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_vector(
    agent: *mut vrs_agent_t,
    index: usize,
    out_vector: *mut vrs_vector_t,
) -> vrs_status_t {
    boundary(|| vector_impl(agent, index, out_vector))
}

/// Like [`vrs_agent_vector`], for the vector called `name` (`"joints"`, …).
///
/// # Errors
/// `VRS_ERROR_UNKNOWN_CHANNEL` (no such vector: the message lists the agent's vectors),
/// `VRS_ERROR_NO_FRAME`, `VRS_ERROR_INVALID_ARGUMENT` (NULL pointers, not UTF-8), handle
/// errors.
///
/// # Safety
/// `name` is NULL or a valid NUL-terminated string; `out_vector` is NULL or valid for
/// writing a `vrs_vector_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_vector_by_name(
    agent: *mut vrs_agent_t,
    name: *const c_char,
    out_vector: *mut vrs_vector_t,
) -> vrs_status_t {
    boundary(|| vector_by_name_impl(agent, name, out_vector))
}

/// How many vectors (`[[agent.vector]]`) and actions (`[[agent.action]]`) this agent's
/// config declares (every frame carries exactly these: a frame that differs is refused
/// at the wait). Either out pointer may be NULL. Needs no current frame.
///
/// # Errors
/// Handle errors.
///
/// # Safety
/// `out_vector_count` and `out_action_count` are each NULL or valid for writing a
/// `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_channel_counts(
    agent: *mut vrs_agent_t,
    out_vector_count: *mut u32,
    out_action_count: *mut u32,
) -> vrs_status_t {
    boundary(|| channel_counts_impl(agent, out_vector_count, out_action_count))
}

/// Vector `index` (`0..vector_count`) of this agent as its config declares it: name,
/// length and the observation bounds (`low`, `high`, valid until the agent is
/// disconnected). Needs no current frame.
///
/// # Errors
/// `VRS_ERROR_OUT_OF_RANGE`, `VRS_ERROR_INVALID_ARGUMENT` (NULL `out_spec`), handle
/// errors.
///
/// # Safety
/// `out_spec` is NULL or valid for writing a `vrs_vector_spec_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_vector_spec(
    agent: *mut vrs_agent_t,
    index: usize,
    out_spec: *mut vrs_vector_spec_t,
) -> vrs_status_t {
    boundary(|| vector_spec_impl(agent, index, out_spec))
}

/// Action `index` (`0..action_count`) of this agent as its config declares it: name,
/// kind, length and bounds (continuous; valid until the agent is disconnected) or number
/// of choices (discrete). Needs no current frame.
///
/// # Errors
/// `VRS_ERROR_OUT_OF_RANGE`, `VRS_ERROR_INVALID_ARGUMENT` (NULL `out_spec`), handle
/// errors.
///
/// # Safety
/// `out_spec` is NULL or valid for writing a `vrs_action_spec_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_action_spec(
    agent: *mut vrs_agent_t,
    index: usize,
    out_spec: *mut vrs_action_spec_t,
) -> vrs_status_t {
    boundary(|| action_spec_impl(agent, index, out_spec))
}

/// Queues the value of the continuous action `name` for this cycle: `len` floats at
/// `values`, each within the action's bounds. It goes out with the next
/// [`vrs_agent_stop`]; the host takes the last value sent in a cycle. Nothing is queued
/// when the call fails; the message names the action (and the length or bound).
///
/// # Errors
/// `VRS_ERROR_UNKNOWN_CHANNEL` (no such action), `VRS_ERROR_WRONG_LENGTH`,
/// `VRS_ERROR_OUT_OF_BOUNDS` (a value outside its bounds, NaN or infinite),
/// `VRS_ERROR_WRONG_ACTION_KIND` (a discrete action: use [`vrs_agent_act_discrete`]),
/// `VRS_ERROR_QUEUE_FULL` (it takes one queue entry per 4 values),
/// `VRS_ERROR_INVALID_ARGUMENT` (NULL `name`, NULL `values` with `len > 0`), handle
/// errors.
///
/// # Safety
/// `name` is NULL or a valid NUL-terminated string; `values` is valid for reading `len`
/// floats (or NULL when `len` is 0).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_act(
    agent: *mut vrs_agent_t,
    name: *const c_char,
    values: *const f32,
    len: usize,
) -> vrs_status_t {
    boundary(|| act_impl(agent, name, values, len))
}

/// Queues the choice of the discrete action `name` for this cycle (`0..n`), as
/// [`vrs_agent_act`].
///
/// # Errors
/// `VRS_ERROR_UNKNOWN_CHANNEL` (no such action), `VRS_ERROR_CHOICE_OUT_OF_RANGE`,
/// `VRS_ERROR_WRONG_ACTION_KIND` (a continuous action: use [`vrs_agent_act`]),
/// `VRS_ERROR_QUEUE_FULL`, `VRS_ERROR_INVALID_ARGUMENT` (NULL `name`), handle errors.
///
/// # Safety
/// `name` is NULL or a valid NUL-terminated string.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn vrs_agent_act_discrete(
    agent: *mut vrs_agent_t,
    name: *const c_char,
    choice: u32,
) -> vrs_status_t {
    boundary(|| act_discrete_impl(agent, name, choice))
}
