//! The arguments of the group's steps: action-table entries, indices, masks, resets.

use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use vrsync_bridge::Command;

use crate::commands::{MoveAhead, PyCommand};

/// One command of an action-table entry.
#[derive(Debug, Clone, Copy)]
pub(super) enum Planned {
    Fixed(Command),
    Ahead(MoveAhead),
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

/// Integers from a numpy array (any integer dtype) or a sequence.
pub(super) fn indices(values: &Bound<'_, PyAny>, n: usize, what: &str) -> PyResult<Vec<i64>> {
    let v: Vec<i64> = match pyo3::buffer::PyBuffer::<i64>::get(values) {
        Ok(b) if b.dimensions() == 1 => b.to_vec(values.py())?,
        _ => values.extract::<Vec<i64>>().map_err(|_| {
            PyTypeError::new_err(format!(
                "{what} must be {n} integers (a numpy array or a sequence)"
            ))
        })?,
    };
    if v.len() != n {
        return Err(PyValueError::new_err(format!(
            "{what} has {} entries for {n} agents",
            v.len()
        )));
    }
    Ok(v)
}

/// Booleans from a numpy array or a sequence (`None`: all false).
pub(super) fn mask(values: Option<&Bound<'_, PyAny>>, n: usize, what: &str) -> PyResult<Vec<bool>> {
    let Some(values) = values.filter(|v| !v.is_none()) else {
        return Ok(vec![false; n]);
    };
    let v: Vec<bool> = values
        .try_iter()?
        .map(|x| x?.is_truthy())
        .collect::<PyResult<_>>()?;
    if v.len() != n {
        return Err(PyValueError::new_err(format!(
            "{what} has {} entries for {n} agents",
            v.len()
        )));
    }
    Ok(v)
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
