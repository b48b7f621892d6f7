//! Rust errors → the exception classes of `vrsync.errors`.
//!
//! The classes are written in Python (so that, say, `HostGoneError` is both a
//! `VrsyncError` and a `ConnectionError`, and IDEs see their docstrings); this module looks
//! them up when an error is raised, which is rare and never on the per-cycle path.

use pyo3::IntoPyObjectExt;
use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use vrsync_agent::SendError;

/// Builds an instance of `vrsync.errors.<class>` with `message`, and sets `attrs` on it.
pub(crate) fn error(
    py: Python<'_>,
    class: &str,
    message: impl Into<String>,
    attrs: &[(&str, Py<PyAny>)],
) -> PyErr {
    let message = message.into();
    let build = || -> PyResult<PyErr> {
        let cls = py.import("vrsync.errors")?.getattr(class)?;
        let inst = cls.call1((message.clone(),))?;
        for (k, v) in attrs {
            inst.setattr(*k, v.bind(py))?;
        }
        Ok(PyErr::from_value(inst))
    };
    // The error classes live in the package that imports this module, so the lookup can
    // fail only for a broken installation: still raise something that names the error.
    build().unwrap_or_else(|e| {
        PyRuntimeError::new_err(format!(
            "{message} (and vrsync.errors.{class} is missing: {e})"
        ))
    })
}

/// Converts `value` for an exception attribute (`None` if it cannot be converted).
pub(crate) fn obj<'py, T: IntoPyObject<'py>>(py: Python<'py>, value: T) -> Py<PyAny> {
    value
        .into_bound_py_any(py)
        .map(Bound::unbind)
        .unwrap_or_else(|_| py.None())
}

/// `QueueFullError` for agent `id`: its motor queue had no room for a command.
pub(crate) fn send_error(py: Python<'_>, e: SendError, id: u32) -> PyErr {
    error(
        py,
        "QueueFullError",
        e.to_string(),
        &[("agent_id", obj(py, id))],
    )
}
