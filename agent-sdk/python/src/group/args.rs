//! The arguments of the group's steps: action-table entries, indices, masks, resets.

use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use vrsync_bridge::Command;

use crate::commands::{MoveAhead, PyCommand, heading_deg};

/// One command of an action-table entry.
#[derive(Debug, Clone, Copy)]
pub(super) enum Planned {
    Fixed(Command),
    Ahead(MoveAhead),
}

impl Planned {
    /// The command to send for a body whose rotation is `rotation`.
    pub(super) fn resolve(&self, rotation: [f32; 4]) -> Command {
        match self {
            Self::Fixed(c) => *c,
            Self::Ahead(m) => m.resolve(heading_deg(rotation)),
        }
    }
}

/// Parses one action-table entry or one agent's commands: `None`, a command, a
/// `MoveAhead`, or a sequence of those.
pub(super) fn planned(entry: &Bound<'_, PyAny>) -> PyResult<Vec<Planned>> {
    if entry.is_none() {
        return Ok(Vec::new());
    }
    let one = |e: &Bound<'_, PyAny>| -> PyResult<Planned> {
        if let Ok(c) = e.cast::<PyCommand>() {
            return Ok(Planned::Fixed(c.get().command));
        }
        if let Ok(a) = e.cast::<MoveAhead>() {
            return Ok(Planned::Ahead(*a.get()));
        }
        Err(PyTypeError::new_err(format!(
            "expected a vrsync Command, a MoveAhead, or None, got {}: a function of the \
             frame cannot run inside the batched step (map actions to commands in Python \
             and use step_commands, or action_fn in the envs)",
            e.repr().map_or_else(|_| "?".to_owned(), |r| r.to_string())
        )))
    };
    if entry.cast::<PyCommand>().is_ok() || entry.cast::<MoveAhead>().is_ok() || entry.is_callable()
    {
        return Ok(vec![one(entry)?]);
    }
    let mut v = Vec::new();
    for e in entry.try_iter().map_err(|_| {
        PyTypeError::new_err(format!(
            "expected a vrsync Command, a MoveAhead, a sequence of them, or None, got {}",
            entry
                .repr()
                .map_or_else(|_| "?".to_owned(), |r| r.to_string())
        ))
    })? {
        v.push(one(&e?)?);
    }
    Ok(v)
}

/// Integers from a numpy array or a sequence, into `out` (replacing its contents). A
/// one-dimensional, contiguous `int64` array is read without allocating.
pub(super) fn indices(
    values: &Bound<'_, PyAny>,
    n: usize,
    what: &str,
    out: &mut Vec<i64>,
) -> PyResult<()> {
    out.clear();
    if !read_int64s(values, out) {
        let v: Vec<i64> = match pyo3::buffer::PyBuffer::<i64>::get(values) {
            Ok(b) if b.dimensions() == 1 => b.to_vec(values.py())?,
            _ => values.extract::<Vec<i64>>().map_err(|_| {
                PyTypeError::new_err(format!(
                    "{what} must be {n} integers (a numpy array or a sequence)"
                ))
            })?,
        };
        *out = v;
    }
    if out.len() != n {
        return Err(PyValueError::new_err(format!(
            "{what} has {} entries for {n} agents",
            out.len()
        )));
    }
    Ok(())
}

/// Appends the items of `values` to `out` if it exports a one-dimensional, C-contiguous
/// buffer of native 8-byte integers (a numpy `int64` array); `false` (nothing read, no
/// error set) otherwise. Unlike `PyBuffer::get`, which boxes the buffer view, it
/// allocates nothing but `out`'s growth.
fn read_int64s(values: &Bound<'_, PyAny>, out: &mut Vec<i64>) -> bool {
    let mut view = core::mem::MaybeUninit::<pyo3::ffi::Py_buffer>::uninit();
    // SAFETY: `view` is written by a successful `PyObject_GetBuffer` and released once
    // below; the GIL is held (`values` is bound).
    unsafe {
        let flags = pyo3::ffi::PyBUF_FORMAT | pyo3::ffi::PyBUF_C_CONTIGUOUS;
        if pyo3::ffi::PyObject_GetBuffer(values.as_ptr(), view.as_mut_ptr(), flags) != 0 {
            pyo3::ffi::PyErr_Clear();
            return false;
        }
        let view = view.assume_init_mut();
        let format = if view.format.is_null() {
            b"B".as_slice()
        } else {
            core::ffi::CStr::from_ptr(view.format).to_bytes()
        };
        let native_int64 = matches!(
            format,
            b"q" | b"l" | b"@q" | b"@l" | b"=q" | b"=l" | b"<q" | b"<l"
        ) && cfg!(target_endian = "little")
            && view.itemsize == 8
            && view.ndim == 1;
        if native_int64 {
            let count = usize::try_from(view.len).unwrap_or(0) / 8;
            out.extend_from_slice(core::slice::from_raw_parts(view.buf.cast::<i64>(), count));
        }
        pyo3::ffi::PyBuffer_Release(view);
        native_int64
    }
}

/// Booleans from a numpy array or a sequence (`None`: all false), into `out` (replacing
/// its contents).
pub(super) fn mask(
    values: Option<&Bound<'_, PyAny>>,
    n: usize,
    what: &str,
    out: &mut Vec<bool>,
) -> PyResult<()> {
    out.clear();
    let Some(values) = values.filter(|v| !v.is_none()) else {
        out.resize(n, false);
        return Ok(());
    };
    for x in values.try_iter()? {
        out.push(x?.is_truthy()?);
    }
    if out.len() != n {
        return Err(PyValueError::new_err(format!(
            "{what} has {} entries for {n} agents",
            out.len()
        )));
    }
    Ok(())
}

pub(super) fn reset_command(kind: &str) -> PyResult<Command> {
    match kind {
        "trial" => Ok(Command::TrialReset { reset_type: 0 }),
        "environment" => Ok(Command::EnvironmentReset { reset_type: 0 }),
        other => Err(PyValueError::new_err(format!(
            "reset kind must be \"trial\" or \"environment\", got {other:?}"
        ))),
    }
}
