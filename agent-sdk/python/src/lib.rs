//! # vrsync-python
//!
//! The extension module `vrsync._vrsync`: the Rust agent SDK ([`vrsync_agent::Agent`]) seen
//! from Python. One implementation of the protocol, so the version/layout check, the
//! newest-frame rule, host-liveness detection and both transports are the Rust ones.
//!
//! - `agent::PyAgent` connects, waits (releasing the GIL, in slices short enough that
//!   Ctrl-C raises `KeyboardInterrupt` at once), sends and stops.
//! - `frame::PyFrame` holds one received frame; its images and vectors are read-only,
//!   zero-copy numpy arrays whose base is the frame (which it keeps alive).
//! - `group::AgentGroup` drives N agents of one session with one call per lock-step
//!   cycle, writing every frame into stacked numpy arrays (the batched vector envs' core).
//! - `commands` holds one small class per command of the catalogue, checked when built.
//! - `host::PyHost` is the other side: a simulator written in Python serves agents
//!   through the Rust host, writing each agent's images straight into its loaned frame
//!   through writable numpy views (`host::PyHostFrame`).
//! - `buffer` makes those numpy arrays over frame memory with numpy's C API (both sides).
//! - Errors are the exception classes of `vrsync.errors` (pure Python, so that they can
//!   inherit from both `VrsyncError` and the matching built-in such as `TimeoutError`).
//!
//! The pure-Python part of the package (`python/vrsync/`) adds the Gymnasium and PettingZoo
//! environments and the original client's names.

mod agent;
mod buffer;
mod channels;
mod commands;
mod detach;
mod errors;
mod frame;
mod group;
mod host;
mod sensors;
mod threads;

use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;

/// Testing aid, not API: creates `n` iceoryx2 nodes `<prefix>.<k>` and never removes them,
/// so they are dead nodes once this process exits (the Ctrl-C tests fill the registry with
/// a few hundred leftovers this way).
#[pyfunction]
fn _leak_nodes_for_tests(prefix: &str, n: usize) -> PyResult<()> {
    vrsync_bridge::shm::leak_nodes_for_tests(prefix, n).map_err(PyRuntimeError::new_err)
}

/// Testing aid, not API: how many dead iceoryx2 nodes have a name starting with `prefix`.
#[pyfunction]
fn _dead_nodes_for_tests(prefix: &str) -> u64 {
    vrsync_bridge::shm::dead_nodes_for_tests(prefix, false)
}

/// Testing aid, not API: removes the dead iceoryx2 nodes whose name starts with `prefix`;
/// returns how many there were.
#[pyfunction]
fn _remove_dead_nodes_for_tests(prefix: &str) -> u64 {
    vrsync_bridge::shm::dead_nodes_for_tests(prefix, true)
}

/// Rust's allocations in the extension are counted (a relaxed atomic add each), so that
/// the benchmark can show what a step allocates ([`_allocations`]).
#[global_allocator]
static ALLOC: vrsync_alloc_count::CountingAlloc = vrsync_alloc_count::CountingAlloc;

/// Benchmark aid, not API: how many allocations (and reallocations) the extension's Rust
/// code made so far in this process.
#[pyfunction]
fn _allocations() -> u64 {
    vrsync_alloc_count::allocations()
}

/// The extension module `vrsync._vrsync`.
#[pymodule]
fn _vrsync(m: &Bound<'_, PyModule>) -> PyResult<()> {
    agent::register(m)?;
    group::register(m)?;
    host::register(m)?;
    m.add_class::<frame::PyFrame>()?;
    sensors::register(m)?;
    commands::register(m)?;
    channels::register(m)?;
    m.add_function(wrap_pyfunction!(_leak_nodes_for_tests, m)?)?;
    m.add_function(wrap_pyfunction!(_dead_nodes_for_tests, m)?)?;
    m.add_function(wrap_pyfunction!(_remove_dead_nodes_for_tests, m)?)?;
    m.add_function(wrap_pyfunction!(_allocations, m)?)?;
    m.add("PROTOCOL_VERSION", vrsync_bridge::PROTOCOL_VERSION)?;
    m.add("MAX_FRAMES_HELD", vrsync_bridge::AGENT_MAX_HELD_FRAMES)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
