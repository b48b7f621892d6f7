//! Channels seen from Python: the spec classes `vrsync.Vector` and `vrsync.Action`, and the
//! conversion of `Agent.act(name, value)`'s value.

use pyo3::buffer::PyBuffer;
use pyo3::prelude::*;
use vrsync_agent::{ActError, Agent};
use vrsync_bridge::{ActionConfig, ActionSpace, AgentConfig, VectorConfig};

use crate::errors::{error, obj};

/// A float vector the host writes into every frame (`[[agent.vector]]`):
/// `Frame.vector(name)` reads it.
#[pyclass(module = "vrsync._vrsync", name = "Vector", frozen, get_all)]
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct PyVector {
    /// Name.
    pub(crate) name: String,
    /// Number of float32 values.
    pub(crate) len: u32,
    /// Lower bound of each value (-inf when not configured).
    pub(crate) low: Vec<f32>,
    /// Upper bound of each value (inf when not configured).
    pub(crate) high: Vec<f32>,
}

#[pymethods]
impl PyVector {
    fn __repr__(&self) -> String {
        format!("Vector(name={:?}, len={})", self.name, self.len)
    }
}

/// What the agent sends back each cycle (`[[agent.action]]`): `Agent.act(name, value)`.
#[pyclass(module = "vrsync._vrsync", name = "Action", frozen, get_all)]
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct PyAction {
    /// Name.
    pub(crate) name: String,
    /// `"box"` (continuous float32 values within `low`/`high`) or `"discrete"` (a choice
    /// in `0..n`).
    pub(crate) kind: &'static str,
    /// Number of values (1 for a discrete action).
    pub(crate) len: usize,
    /// Number of choices of a discrete action; `None` for a continuous one.
    pub(crate) n: Option<u32>,
    /// Lowest value accepted, per value (empty for a discrete action).
    pub(crate) low: Vec<f32>,
    /// Highest value accepted, per value (empty for a discrete action).
    pub(crate) high: Vec<f32>,
}

#[pymethods]
impl PyAction {
    fn __repr__(&self) -> String {
        match self.n {
            Some(n) => format!("Action(name={:?}, kind='discrete', n={n})", self.name),
            None => format!("Action(name={:?}, kind='box', len={})", self.name, self.len),
        }
    }
}

impl From<&VectorConfig> for PyVector {
    fn from(v: &VectorConfig) -> Self {
        Self {
            name: v.name.clone(),
            len: v.len,
            low: v.low.clone(),
            high: v.high.clone(),
        }
    }
}

impl From<&ActionConfig> for PyAction {
    fn from(a: &ActionConfig) -> Self {
        let (kind, n, low, high) = match &a.space {
            ActionSpace::Box { low, high } => ("box", None, low.clone(), high.clone()),
            ActionSpace::Discrete { n } => ("discrete", Some(*n), Vec::new(), Vec::new()),
        };
        Self {
            name: a.name.clone(),
            kind,
            len: a.len(),
            n,
            low,
            high,
        }
    }
}

/// The channels of `agent` as Python spec objects.
pub(crate) fn channels_of(agent: &AgentConfig) -> (Vec<PyVector>, Vec<PyAction>) {
    (
        agent.vectors.iter().map(Into::into).collect(),
        agent.actions.iter().map(Into::into).collect(),
    )
}

/// The values of a continuous action: a float32 buffer (numpy array) read at once, else
/// any sequence of numbers.
fn floats(value: &Bound<'_, PyAny>) -> PyResult<Vec<f32>> {
    if let Ok(buf) = PyBuffer::<f32>::get(value)
        && buf.is_c_contiguous()
    {
        return buf.to_vec(value.py());
    }
    value.extract::<Vec<f32>>()
}

/// `Agent.act(name, value)` on the Rust agent: a continuous action takes a sequence of
/// floats, a discrete one an int.
pub(crate) fn act(
    py: Python<'_>,
    agent: &mut Agent,
    name: &str,
    value: &Bound<'_, PyAny>,
) -> PyResult<()> {
    let id = agent.id();
    let space = agent
        .actions()
        .iter()
        .find(|a| a.name == name)
        .map(|a| a.space.clone());
    let result = match space {
        // The Rust error names the agent's actions.
        None => agent.act(name, &[]),
        Some(ActionSpace::Discrete { n }) => {
            let choice: i64 = value.extract().map_err(|_| {
                act_error(
                    py,
                    id,
                    name,
                    format!(
                        "action {name:?} is a choice: give an int, not {}",
                        type_name(value)
                    ),
                )
            })?;
            match u32::try_from(choice) {
                Ok(choice) => agent.act_discrete(name, choice),
                Err(_) => {
                    let why = format!("action {name:?} is a choice in 0..{n}, got {choice}");
                    return Err(act_error(py, id, name, why));
                }
            }
        }
        Some(ActionSpace::Box { .. }) => {
            let values = floats(value).map_err(|_| {
                act_error(
                    py,
                    id,
                    name,
                    format!(
                        "action {name:?} takes a sequence of floats (a list or a numpy array), \
                         not {}",
                        type_name(value)
                    ),
                )
            })?;
            agent.act(name, &values)
        }
    };
    result.map_err(|e| match e {
        ActError::Queue(e) => crate::errors::send_error(py, e, id),
        other => act_error(py, id, name, other.to_string()),
    })
}

fn type_name(value: &Bound<'_, PyAny>) -> String {
    value
        .get_type()
        .name()
        .map(|n| n.to_string())
        .unwrap_or_else(|_| "this value".into())
}

fn act_error(py: Python<'_>, id: u32, action: &str, message: String) -> PyErr {
    error(
        py,
        "ActionError",
        message,
        &[("agent_id", obj(py, id)), ("action", obj(py, action))],
    )
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyVector>()?;
    m.add_class::<PyAction>()?;
    Ok(())
}
