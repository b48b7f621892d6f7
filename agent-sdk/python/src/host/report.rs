//! `vrsync.CycleReport` and `vrsync.AgentReport`: what `Host.collect()` returns.
//!
//! Plain copies of the Rust host's report (it is overwritten by the next cycle); commands
//! are kept as they came off the wire and decoded into command objects when read.

use pyo3::exceptions::PyKeyError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use vrsync_bridge::{ActionValue, AgentOutcome, CycleReport, MotorCommand};

use crate::commands::to_object;

fn outcome_name(o: AgentOutcome) -> &'static str {
    match o {
        AgentOutcome::Stopped => "stopped",
        AgentOutcome::TimedOut => "timed_out",
        AgentOutcome::NotAwaited => "not_awaited",
        AgentOutcome::Async => "async",
        AgentOutcome::Evicted => "evicted",
        AgentOutcome::Left => "left",
    }
}

/// One action's value in one cycle, owned.
enum Action {
    Box(Vec<f32>),
    Discrete(u32),
}

/// One agent's part of a cycle: how its cycle ended and the commands it sent.
#[pyclass(module = "vrsync._vrsync", name = "AgentReport", frozen)]
pub(crate) struct PyAgentReport {
    agent_id: u32,
    outcome: &'static str,
    read_cycle: Option<u64>,
    evicted: bool,
    rejoined: bool,
    left: bool,
    slow: bool,
    wire: Vec<MotorCommand>,
    /// Every configured action (`[[agent.action]]`) in config order, with its value of
    /// this cycle (`None`: none arrived).
    actions: Vec<(String, Option<Action>)>,
    actions_rejected: u32,
}

#[pymethods]
impl PyAgentReport {
    /// The agent's id.
    #[getter]
    fn agent_id(&self) -> u32 {
        self.agent_id
    }

    /// How its cycle ended: `"stopped"` (its stop arrived), `"timed_out"` (the stop
    /// timeout passed without it), `"not_awaited"` (no frame reached it this cycle),
    /// `"async"` (async mode: commands taken as they came), `"evicted"` (lost during the
    /// cycle) or `"left"` (it left the session before its stop).
    #[getter]
    fn outcome(&self) -> &'static str {
        self.outcome
    }

    /// The newest cycle whose frame the agent acknowledged having read (`None` before its
    /// first acknowledgement, and again after an eviction).
    #[getter]
    fn read_cycle(&self) -> Option<u64> {
        self.read_cycle
    }

    /// It was evicted during this cycle (its process died or its connection dropped).
    #[getter]
    fn evicted(&self) -> bool {
        self.evicted
    }

    /// It rejoined in this cycle (its first frame since an eviction or a leave).
    #[getter]
    fn rejoined(&self) -> bool {
        self.rejoined
    }

    /// It left the session gracefully during this cycle.
    #[getter]
    fn left(&self) -> bool {
        self.left
    }

    /// The host waited for its stop past `stop_timeout` (alive but slow).
    #[getter]
    fn slow(&self) -> bool {
        self.slow
    }

    /// The commands it sent this cycle, in the order sent, as command objects (`Move`,
    /// `Turn`, …, the classes `Agent.send` takes). Commands that do not decode (an
    /// unknown kind, a NaN or infinite argument) are left out and counted in
    /// `invalid_commands`; range checks are the simulator's (report what it refused with
    /// `Host.set_rejected`).
    #[getter]
    fn commands<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let list = PyList::empty(py);
        for c in &self.wire {
            if let Ok(cmd) = c.decode() {
                list.append(to_object(py, cmd)?)?;
            }
        }
        Ok(list)
    }

    /// The action id of each command in `commands`, in the same order (the agent chose
    /// them; its frames report the action's status under this id).
    #[getter]
    fn action_ids(&self) -> Vec<u32> {
        self.wire
            .iter()
            .filter(|c| c.decode().is_ok())
            .map(|c| c.action_id)
            .collect()
    }

    /// How many commands it sent this cycle that do not decode (left out of `commands`).
    #[getter]
    fn invalid_commands(&self) -> usize {
        self.wire.iter().filter(|c| c.decode().is_err()).count()
    }

    /// The actions it sent this cycle (`[[agent.action]]`), by name in config order: a
    /// `float32` numpy array (a copy) for a continuous action, an `int` for a discrete
    /// one, `None` when none arrived this cycle. Values are within the configured bounds
    /// (the host refused the others: `actions_rejected`).
    #[getter]
    fn actions<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for (name, value) in &self.actions {
            match value {
                None => d.set_item(name, py.None())?,
                Some(Action::Discrete(choice)) => d.set_item(name, choice)?,
                Some(Action::Box(values)) => d.set_item(name, float32_array(py, values)?)?,
            }
        }
        Ok(d)
    }

    /// Action chunks the host refused this cycle (unknown action, wrong length, out of
    /// bounds, not finite): nothing of those values is in `actions`.
    #[getter]
    fn actions_rejected(&self) -> u32 {
        self.actions_rejected
    }

    fn __repr__(&self) -> String {
        let mut flags = String::new();
        for (set, name) in [
            (self.evicted, " evicted"),
            (self.rejoined, " rejoined"),
            (self.left, " left"),
            (self.slow, " slow"),
        ] {
            if set {
                flags += name;
            }
        }
        format!(
            "<vrsync.AgentReport agent={} outcome={} commands={}{flags}>",
            self.agent_id,
            self.outcome,
            self.wire.len()
        )
    }
}

/// The result of one cycle: `Host.collect()`.
#[pyclass(module = "vrsync._vrsync", name = "CycleReport", frozen)]
pub(crate) struct PyCycleReport {
    cycle: u64,
    sim_time_ns: u64,
    timed_out: bool,
    late_batches: u32,
    agents: Vec<Py<PyAgentReport>>,
}

impl PyCycleReport {
    /// A copy of `report`.
    pub(crate) fn new(py: Python<'_>, report: &CycleReport) -> PyResult<Self> {
        let agents = report
            .agents()
            .iter()
            .map(|a| {
                Py::new(
                    py,
                    PyAgentReport {
                        agent_id: a.agent_id,
                        outcome: outcome_name(a.outcome),
                        read_cycle: a.read_cycle,
                        evicted: a.evicted,
                        rejoined: a.rejoined,
                        left: a.left,
                        slow: a.slow,
                        wire: a.commands().to_vec(),
                        actions: a
                            .actions()
                            .map(|(name, v)| {
                                let v = v.map(|v| match v {
                                    ActionValue::Box(values) => Action::Box(values.to_vec()),
                                    ActionValue::Discrete(choice) => Action::Discrete(choice),
                                });
                                (name.to_owned(), v)
                            })
                            .collect(),
                        actions_rejected: a.actions_rejected(),
                    },
                )
            })
            .collect::<PyResult<_>>()?;
        Ok(Self {
            cycle: report.cycle,
            sim_time_ns: report.sim_time_ns,
            timed_out: report.timed_out,
            late_batches: report.late_batches,
            agents,
        })
    }
}

#[pymethods]
impl PyCycleReport {
    /// The cycle this report ends.
    #[getter]
    fn cycle(&self) -> u64 {
        self.cycle
    }

    /// Simulated time at the start of the cycle, in nanoseconds.
    #[getter]
    fn sim_time_ns(&self) -> u64 {
        self.sim_time_ns
    }

    /// Whether the cycle ended by the stop timeout (some agent's stop is missing).
    #[getter]
    fn timed_out(&self) -> bool {
        self.timed_out
    }

    /// Batches for earlier cycles (or after a stop) dropped during this cycle.
    #[getter]
    fn late_batches(&self) -> u32 {
        self.late_batches
    }

    /// Every agent's report, in the config's agent order.
    #[getter]
    fn agents<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        PyList::new(py, self.agents.iter().map(|a| a.clone_ref(py)))
    }

    /// The report of agent `agent_id`. Raises `KeyError` for an id not in the session.
    fn agent(&self, py: Python<'_>, agent_id: i64) -> PyResult<Py<PyAgentReport>> {
        self.agents
            .iter()
            .find(|a| i64::from(a.get().agent_id) == agent_id)
            .map(|a| a.clone_ref(py))
            .ok_or_else(|| {
                PyKeyError::new_err(format!("agent {agent_id} is not part of this session"))
            })
    }

    fn __repr__(&self) -> String {
        format!(
            "<vrsync.CycleReport cycle={} sim_time={:.3}s agents={}{}>",
            self.cycle,
            self.sim_time_ns as f64 * 1e-9,
            self.agents.len(),
            if self.timed_out { " timed_out" } else { "" }
        )
    }
}

/// A new `float32` numpy array holding `values`.
fn float32_array<'py>(py: Python<'py>, values: &[f32]) -> PyResult<Bound<'py, PyAny>> {
    use pyo3::sync::PyOnceLock;
    static ARRAY: PyOnceLock<(Py<PyAny>, Py<PyAny>)> = PyOnceLock::new();
    let (array, float32) = ARRAY.get_or_try_init(py, || {
        let np = py.import("numpy")?;
        Ok::<_, PyErr>((
            np.getattr("array")?.unbind(),
            np.getattr("float32")?.unbind(),
        ))
    })?;
    array.bind(py).call1((values.to_vec(), float32.bind(py)))
}
