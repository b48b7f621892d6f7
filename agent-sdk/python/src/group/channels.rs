//! The channels of an `AgentGroup`: its agents' vectors stacked into `(N, len)` arrays
//! each step, and `step_actions`' values queued on every agent.

use pyo3::buffer::PyBuffer;
use pyo3::exceptions::{PyKeyError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use vrsync_agent::{ActError, Agent, Frame};
use vrsync_bridge::AgentConfig;

use super::out::Out;
use crate::channels::{PyAction, PyVector, channels_of};
use crate::errors::{error, obj};

/// Where one vector goes: `(N, len)` `float32`.
#[derive(Debug, Clone)]
pub(super) struct VectorSink {
    name: String,
    len: usize,
    ptr: usize,
}

/// The group's channels: the specs every agent shares, and the vector outputs.
pub(super) struct GroupChannels {
    pub(super) vectors: Vec<PyVector>,
    pub(super) actions: Vec<PyAction>,
    pub(super) outs: Vec<(String, Out)>,
    pub(super) sinks: Vec<VectorSink>,
}

impl GroupChannels {
    /// The channels of `agents` (which must all declare the same ones), with an `(n, len)`
    /// output array per vector. `Err` names the first agent whose channels differ.
    pub(super) fn new(
        py: Python<'_>,
        agents: &[&AgentConfig],
        n: usize,
    ) -> PyResult<Result<Self, String>> {
        let Some(first) = agents.first() else {
            return Ok(Ok(Self::empty()));
        };
        let (vectors, actions) = channels_of(first);
        if let Some(other) = agents
            .iter()
            .find(|a| channels_of(a) != (vectors.clone(), actions.clone()))
        {
            return Ok(Err(format!(
                "agent {}'s channels ([[agent.vector]], [[agent.action]]) differ from agent \
                 {}'s; an AgentGroup stacks them, so every agent needs the same ones",
                other.id, first.id
            )));
        }
        let numpy = py.import("numpy")?;
        let mut outs = Vec::with_capacity(vectors.len());
        let mut sinks = Vec::with_capacity(vectors.len());
        for v in &vectors {
            let out = Out::new(py, &numpy, &[n, v.len as usize], "float32")?;
            sinks.push(VectorSink {
                name: v.name.clone(),
                len: v.len as usize,
                ptr: out.ptr,
            });
            outs.push((v.name.clone(), out));
        }
        Ok(Ok(Self {
            vectors,
            actions,
            outs,
            sinks,
        }))
    }

    fn empty() -> Self {
        Self {
            vectors: Vec::new(),
            actions: Vec::new(),
            outs: Vec::new(),
            sinks: Vec::new(),
        }
    }

    /// `{name: (N, len) float32}`, the arrays every step overwrites.
    pub(super) fn vectors_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for (name, out) in &self.outs {
            d.set_item(name, out.array.bind(py))?;
        }
        Ok(d)
    }

    /// The stacked vector `name`.
    pub(super) fn vector<'py>(&self, py: Python<'py>, name: &str) -> PyResult<Bound<'py, PyAny>> {
        self.outs
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, o)| o.array.bind(py).clone())
            .ok_or_else(|| {
                let names: Vec<&str> = self.outs.iter().map(|(n, _)| n.as_str()).collect();
                PyKeyError::new_err(format!("no vector {name:?} (vectors: {names:?})"))
            })
    }

    /// The values of `step_actions`' argument, per action, as one row per agent:
    /// continuous `(N, len)` `float32`, discrete `(N,)` integers.
    pub(super) fn rows(
        &self,
        py: Python<'_>,
        values: &Bound<'_, PyAny>,
        ids: &[u32],
        active: &[bool],
    ) -> PyResult<Vec<ActionRows>> {
        let n = ids.len();
        let numpy = py.import("numpy")?;
        let values = values.cast::<PyDict>().map_err(|_| {
            PyValueError::new_err("step_actions takes a dict {action name: values of N agents}")
        })?;
        if let Some(unknown) = values
            .keys()
            .iter()
            .filter_map(|k| k.extract::<String>().ok())
            .find(|k| !self.actions.iter().any(|a| &a.name == k))
        {
            let names: Vec<&str> = self.actions.iter().map(|a| a.name.as_str()).collect();
            return Err(PyKeyError::new_err(format!(
                "no action {unknown:?} (actions: {names:?})"
            )));
        }
        let mut rows = Vec::with_capacity(self.actions.len());
        for a in &self.actions {
            let Some(v) = values.get_item(&a.name)? else {
                rows.push(ActionRows::None);
                continue;
            };
            let discrete = a.n.is_some();
            let dtype = if discrete { "int64" } else { "float32" };
            let arr = numpy.call_method1("ascontiguousarray", (v, dtype))?;
            let want = if discrete { n } else { n * a.len };
            let row = if discrete { 1 } else { a.len };
            let bad = |found: usize| {
                PyValueError::new_err(format!(
                    "action {:?}: {want} values expected ({n} agents × {row}), got {found}",
                    a.name
                ))
            };
            // Checked for every agent before any is queued, so that a bad value sends
            // nothing at all.
            let refuse = |k: usize, what: String| {
                error(
                    py,
                    "ActionError",
                    format!("agent {}: action {:?}: {what}", ids[k], a.name),
                    &[
                        ("agent_id", obj(py, ids[k])),
                        ("action", obj(py, a.name.as_str())),
                    ],
                )
            };
            if let Some(n_choices) = a.n {
                let buf = PyBuffer::<i64>::get(&arr)?;
                if buf.item_count() != want {
                    return Err(bad(buf.item_count()));
                }
                let choices = buf.to_vec(py)?;
                if let Some(k) =
                    (0..n).find(|&k| active[k] && !(0..i64::from(n_choices)).contains(&choices[k]))
                {
                    return Err(refuse(
                        k,
                        format!("{} is not a choice in 0..{n_choices}", choices[k]),
                    ));
                }
                rows.push(ActionRows::Discrete(choices));
            } else {
                let buf = PyBuffer::<f32>::get(&arr)?;
                if buf.item_count() != want {
                    return Err(bad(buf.item_count()));
                }
                let values = buf.to_vec(py)?;
                let outside = |(i, v): (usize, &f32)| {
                    let (lo, hi) = (a.low[i % a.len], a.high[i % a.len]);
                    !(v.is_finite() && *v >= lo && *v <= hi)
                };
                if let Some((i, v)) = values
                    .iter()
                    .enumerate()
                    .find(|e| active[e.0 / a.len] && outside(*e))
                {
                    let j = i % a.len;
                    return Err(refuse(
                        i / a.len,
                        format!("value {j} is {v}, outside [{}, {}]", a.low[j], a.high[j]),
                    ));
                }
                rows.push(ActionRows::Box(values, a.len));
            }
        }
        Ok(rows)
    }
}

/// One action's values for every agent.
pub(super) enum ActionRows {
    /// Not given: nothing sent.
    None,
    /// `len` floats per agent, agent after agent.
    Box(Vec<f32>, usize),
    /// One choice per agent.
    Discrete(Vec<i64>),
}

/// Queues agent `k`'s row of every action.
pub(super) fn act_row(
    py: Python<'_>,
    agent: &mut Agent,
    actions: &[PyAction],
    rows: &[ActionRows],
    k: usize,
) -> PyResult<()> {
    let id = agent.id();
    for (a, r) in actions.iter().zip(rows) {
        let result = match r {
            ActionRows::None => Ok(()),
            ActionRows::Box(values, len) => agent.act(&a.name, &values[k * len..(k + 1) * len]),
            ActionRows::Discrete(choices) => {
                agent.act_discrete(&a.name, u32::try_from(choices[k]).unwrap_or(u32::MAX))
            }
        };
        result.map_err(|e| match e {
            ActError::Queue(e) => crate::errors::send_error(py, e, id),
            other => error(
                py,
                "ActionError",
                format!("agent {id}: {other}"),
                &[
                    ("agent_id", obj(py, id)),
                    ("action", obj(py, a.name.as_str())),
                ],
            ),
        })?;
    }
    Ok(())
}

/// Whether `frame`'s vectors are the ones the group stacks.
pub(super) fn check_vectors(sinks: &[VectorSink], frame: &Frame) -> Result<(), String> {
    let descs = frame.vector_descs();
    let same = descs.len() == sinks.len()
        && descs
            .iter()
            .zip(sinks)
            .all(|(d, s)| d.name() == s.name && d.len as usize == s.len);
    if same {
        Ok(())
    } else {
        Err(format!(
            "the frame's vectors {:?} are not the config's {:?}",
            descs.iter().map(|d| d.name()).collect::<Vec<_>>(),
            sinks.iter().map(|s| s.name.as_str()).collect::<Vec<_>>()
        ))
    }
}

/// Copies agent `k`'s vectors into row `k` of the outputs.
///
/// # Safety
/// The sinks must point to the group's live `(N, len)` `float32` arrays, `k` < N, and
/// `check_vectors` must have passed for `frame`.
pub(super) unsafe fn write_vectors(sinks: &[VectorSink], k: usize, frame: &Frame) {
    for s in sinks {
        if let Some(values) = frame.vector(&s.name) {
            let n = values.len().min(s.len);
            // SAFETY: row `k` of a C-contiguous `(N, len)` float32 array lies inside it.
            unsafe {
                let dst = (s.ptr as *mut f32).add(k * s.len);
                std::ptr::copy_nonoverlapping(values.as_ptr(), dst, n);
            }
        }
    }
}
