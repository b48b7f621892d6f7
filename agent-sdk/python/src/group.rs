//! `vrsync.AgentGroup`: N agents of one session, stepped together with one call.
//!
//! One `step` sends every agent's commands and stop, then releases the GIL once and takes
//! every agent's next frame (those already there without a system call; it waits only
//! for one that has not come), copying each frame into preallocated, stacked numpy
//! arrays (one `memcpy` per image row block) and dropping it at once: no Python object
//! per agent or frame, no frame held between steps, and no allocation of ours per step.
//! With `zero_copy` (the host stacks the agents' images, `[transport.shm]
//! stacked_images`) the images are not copied at all: each camera's are one view of the
//! cycle's stacked sample (`stacked.rs`).

use std::path::PathBuf;
use std::time::Duration;

use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use vrsync_agent::Agent;
use vrsync_bridge::{Command, Config};

use crate::agent::{PyCamera, cameras_of, connect_one, default_frame_wait, load_config, secs};
use crate::channels::{PyAction, PyVector};
use crate::errors::{error, obj};

mod args;
mod channels;
mod out;
mod sink;
mod stacked;
mod step;
mod wait;

pub(crate) use stacked::Held;

use args::{Planned, indices, mask, planned, reset_command};
use channels::{GroupChannels, act_row};
use out::Out;
use sink::{Sink, image_outputs};

/// Room for this many commands per agent and step from the start (a table entry with
/// more grows the buffer once).
const COMMANDS_PER_AGENT: usize = 8;

/// The longest the GIL is released in one go while waiting: Ctrl-C is seen within this.
const WAIT_SLICE: Duration = Duration::from_millis(50);

/// The agents, used only through `&mut AgentGroup` (PyO3's borrow flag makes every use
/// exclusive) and never holding a frame between calls.
pub(crate) struct Agents(Vec<Agent>);

impl Drop for Agents {
    /// The agents leave together: the closes that wait for the host overlap
    /// ([`vrsync_agent::close_all`]).
    fn drop(&mut self) {
        vrsync_agent::close_all(self.0.drain(..));
    }
}

/// N agents of one session, driven in lock-step from one process with one call per step.
///
/// ```python
/// group = vrsync.AgentGroup.connect("config/default.toml")   # every [[agent]]
/// group.set_action_table([None, vrsync.MoveAhead(0.5), vrsync.Turn(-30), vrsync.Turn(30)])
/// group.reset()                                   # trial reset for all, waits for frames
/// for _ in range(100):
///     group.step(np.random.randint(0, 4, len(group)))
///     left = group.images["left"]                  # (N, H, W, 3) uint8, overwritten per step
/// group.close()
/// ```
///
/// After `reset`/`step` the output arrays (`images`, `positions`, `rotations`, `rewards`,
/// `sim_time_ns`, `cycles`, `collisions`, `previous_outcome`, `previous_rejected`,
/// `frames_skipped`) hold every agent's new frame, row `k` for `ids[k]`. They are the same
/// arrays every step, overwritten in place: copy what you keep. No frame is held between
/// steps, so the held-frame limit never applies to a group — except to the images of
/// `zero_copy`, which are views of shared memory (see there).
#[pyclass(module = "vrsync._vrsync", name = "AgentGroup")]
pub(crate) struct AgentGroup {
    agents: Option<Agents>,
    ids: Vec<u32>,
    session: String,
    config_path: PathBuf,
    sync_mode: bool,
    stop_timeout: Duration,
    simulation_time_per_frame: Duration,
    step_timeout: Option<Duration>,
    cameras: Vec<PyCamera>,
    transports: Vec<&'static str>,
    /// Whether each agent has received a frame (it may stop only then).
    primed: Vec<bool>,
    /// The rotation of each agent's newest frame (for `MoveAhead`).
    rotations: Vec<[f32; 4]>,
    table: Vec<Vec<Planned>>,
    sink: Sink,
    images: Vec<(String, Out)>,
    /// Whether every step writes the images into new arrays (`fresh_images`).
    fresh: bool,
    /// Whether the agents' payloads are stacked, block after block in the group's order,
    /// with the block stride: zero-copy images are possible.
    stacked: Option<usize>,
    /// Whether the images are views of the stacked sample (`zero_copy`).
    zero_copy: bool,
    /// The step's stacked samples, until its images are made.
    held: Held,
    /// The zero-copy images of the last step, per camera (empty: the group's arrays).
    views: Vec<Py<PyAny>>,
    /// The stacked samples that zero-copy images hold, and the thread that may drop them.
    graveyard: std::sync::Arc<crate::frame::Graveyard>,
    owner: std::thread::ThreadId,
    numpy: Py<PyModule>,
    outs: Vec<(&'static str, Out)>,
    channels: GroupChannels,
    sdk_ns: u64,
    wait_ns: u64,
    steps: u64,
    /// Buffers reused by every step: the agents still waiting for their frame, one
    /// agent's commands, `step`'s actions and reset mask.
    pending: Vec<usize>,
    commands: Vec<Command>,
    picked: Vec<i64>,
    resets: Vec<bool>,
}

/// The block stride of the stacked sample if `agents` (ids `ids`) are stacked in the
/// group's order: consecutive blocks, so that one stride steps from each to the next.
fn stacked_in_order(cfg: &Config, ids: &[u32], agents: &[Agent]) -> Option<usize> {
    let stride = agents.first()?.stack()?.borrow().stride();
    let first = vrsync_bridge::shm::stack_index(cfg, *ids.first()?)?;
    let in_order = ids.iter().zip(agents).enumerate().all(|(k, (&id, a))| {
        a.stack().is_some() && vrsync_bridge::shm::stack_index(cfg, id) == Some(first + k)
    });
    in_order.then_some(stride)
}

impl AgentGroup {
    /// Camera `k`'s current images: the step's zero-copy view, else the group's array.
    fn image_array<'py>(&self, py: Python<'py>, k: usize, out: &Out) -> Bound<'py, PyAny> {
        match self.views.get(k) {
            Some(view) => view.bind(py).clone(),
            None => out.array.bind(py).clone(),
        }
    }

    fn agents(&mut self) -> PyResult<&mut Vec<Agent>> {
        match self.agents.as_mut() {
            Some(a) => Ok(&mut a.0),
            None => Err(closed(&self.session)),
        }
    }

    fn not_primed(&self, py: Python<'_>) -> PyErr {
        error(
            py,
            "UsageError",
            format!(
                "the agents of session {:?} have no frame yet: call reset() before step()",
                self.session
            ),
            &[("session", obj(py, self.session.as_str()))],
        )
    }
}

/// The agent ids of a group: `agent_ids` (each ≥ 0), else every `[[agent]]` of `cfg`; at
/// least one, none twice.
fn group_ids(cfg: &Config, agent_ids: Option<Vec<i64>>) -> PyResult<Vec<u32>> {
    let ids: Vec<u32> = match agent_ids {
        Some(ids) => ids
            .into_iter()
            .map(|i| {
                u32::try_from(i)
                    .map_err(|_| PyValueError::new_err(format!("agent ids must be ≥ 0, got {i}")))
            })
            .collect::<PyResult<_>>()?,
        None => cfg.agents.iter().map(|a| a.id).collect(),
    };
    if ids.is_empty() {
        return Err(PyValueError::new_err(
            "an AgentGroup needs at least one agent",
        ));
    }
    for (i, id) in ids.iter().enumerate() {
        if ids[..i].contains(id) {
            return Err(PyValueError::new_err(format!(
                "agent id {id} is given twice"
            )));
        }
    }
    Ok(ids)
}

/// The error of a use after `close()`.
fn closed(session: &str) -> PyErr {
    pyo3::exceptions::PyRuntimeError::new_err(format!(
        "the AgentGroup of session {session:?} is closed"
    ))
}

#[pymethods]
impl AgentGroup {
    /// Connects the agents `agent_ids` (default: every `[[agent]]` of the config) of the
    /// session in `config`, one connection each, in this process. Every agent must have
    /// the same cameras (names, sizes, formats), so that their images stack.
    /// `step_timeout`: seconds a step waits for all frames (default: without limit when
    /// the host waits for live agents' stops, `[sync] wait_for_stop = "alive"`; else
    /// `2 × stop_timeout + 5`; the host's death ends a wait either way).
    ///
    /// Raises what `Agent.connect` raises; `ConfigError` for agents with different
    /// cameras or an id that is not in the config, `ValueError` for a repeated id.
    #[staticmethod]
    #[pyo3(signature = (config, agent_ids = None, *, session = None, connect_timeout = None, step_timeout = None))]
    fn connect(
        py: Python<'_>,
        config: PathBuf,
        agent_ids: Option<Vec<i64>>,
        session: Option<String>,
        connect_timeout: Option<f64>,
        step_timeout: Option<f64>,
    ) -> PyResult<Self> {
        let mut cfg: Config = load_config(py, &config)?;
        if let Some(s) = session {
            cfg.session = s;
        }
        let ids = group_ids(&cfg, agent_ids)?;
        let config_error =
            |msg: String| error(py, "ConfigError", msg, &[("path", obj(py, config.clone()))]);
        let mut cameras: Option<Vec<PyCamera>> = None;
        let mut transports = Vec::with_capacity(ids.len());
        let mut agent_cfgs = Vec::with_capacity(ids.len());
        for id in &ids {
            let a = cfg.agents.iter().find(|a| a.id == *id).ok_or_else(|| {
                let all: Vec<u32> = cfg.agents.iter().map(|a| a.id).collect();
                config_error(format!(
                    "{} has no [[agent]] with id {id} (its agents: {all:?})",
                    config.display()
                ))
            })?;
            transports.push(a.transport.as_str());
            agent_cfgs.push(a);
            let c = cameras_of(a);
            match &cameras {
                None => cameras = Some(c),
                Some(first) if *first != c => {
                    return Err(config_error(format!(
                        "{}: agent {id}'s cameras differ from agent {}'s; an AgentGroup \
                         stacks images, so every agent needs the same cameras",
                        config.display(),
                        ids[0]
                    )));
                }
                Some(_) => {}
            }
        }
        let cameras = cameras.unwrap_or_default();
        let n = ids.len();
        let channels = GroupChannels::new(py, &agent_cfgs, n)?
            .map_err(|e| config_error(format!("{}: {e}", config.display())))?;
        let numpy = py.import("numpy")?;
        let (images, image_sinks) = image_outputs(py, &numpy, &cameras, n)?;
        let outs = vec![
            ("positions", Out::new(py, &numpy, &[n, 3], "float32")?),
            ("rotations", Out::new(py, &numpy, &[n, 4], "float32")?),
            ("rewards", Out::new(py, &numpy, &[n], "float32")?),
            ("sim_time_ns", Out::new(py, &numpy, &[n], "uint64")?),
            ("cycles", Out::new(py, &numpy, &[n], "uint64")?),
            ("collisions", Out::new(py, &numpy, &[n], "uint32")?),
            ("previous_outcome", Out::new(py, &numpy, &[n], "uint8")?),
            ("previous_rejected", Out::new(py, &numpy, &[n], "uint32")?),
            ("frames_skipped", Out::new(py, &numpy, &[n], "uint64")?),
        ];
        let sink = Sink {
            images: image_sinks,
            positions: outs[0].1.ptr,
            rotations: outs[1].1.ptr,
            rewards: outs[2].1.ptr,
            sim_time_ns: outs[3].1.ptr,
            cycles: outs[4].1.ptr,
            collisions: outs[5].1.ptr,
            outcomes: outs[6].1.ptr,
            rejected: outs[7].1.ptr,
            skipped: outs[8].1.ptr,
            vectors: channels.sinks.clone(),
        };
        let timeout = secs("connect_timeout", connect_timeout)?.unwrap_or(cfg.sync.connect_timeout);
        let step_timeout = match step_timeout {
            Some(_) => secs("step_timeout", step_timeout)?,
            None => default_frame_wait(&cfg),
        };
        let mut agents: Vec<Agent> = Vec::with_capacity(n);
        for id in &ids {
            // On an error the agents connected so far are dropped (they leave). Stacked
            // agents share the first one's reader of the stacked sample.
            let stack = agents.first().and_then(Agent::stack).cloned();
            agents.push(connect_one(py, &cfg, *id, timeout, stack.as_ref())?);
        }
        let stacked = stacked_in_order(&cfg, &ids, &agents);
        let held = Held::new(n, cameras.len());
        let camera_count = cameras.len();
        Ok(Self {
            agents: Some(Agents(agents)),
            primed: vec![false; n],
            rotations: vec![[0.0, 0.0, 0.0, 1.0]; n],
            ids,
            session: cfg.session.clone(),
            config_path: config,
            sync_mode: cfg.sync.sync_mode,
            stop_timeout: cfg.sync.stop_timeout,
            simulation_time_per_frame: cfg.sync.simulation_time_per_frame,
            step_timeout,
            cameras,
            transports,
            table: Vec::new(),
            held,
            sink,
            images,
            fresh: false,
            stacked,
            zero_copy: false,
            views: Vec::with_capacity(camera_count),
            graveyard: Default::default(),
            owner: std::thread::current().id(),
            numpy: numpy.unbind(),
            outs,
            channels,
            sdk_ns: 0,
            wait_ns: 0,
            steps: 0,
            pending: Vec::with_capacity(n),
            commands: Vec::with_capacity(COMMANDS_PER_AGENT),
            picked: Vec::with_capacity(n),
            resets: Vec::with_capacity(n),
        })
    }

    /// Sets the discrete action table that `step(actions)` indexes: each entry is `None`
    /// (no command), a `Command`, a `MoveAhead`, or a sequence of those.
    fn set_action_table(&mut self, table: &Bound<'_, PyAny>) -> PyResult<()> {
        let mut t = Vec::new();
        for e in table.try_iter()? {
            t.push(planned(&e?)?);
        }
        self.table = t;
        Ok(())
    }

    /// The number of entries of the action table.
    #[getter]
    fn num_actions(&self) -> usize {
        self.table.len()
    }

    /// Sends every agent's reset (`kind` `"trial"` or `"environment"`) with its stop and
    /// waits for every agent's next frame (the one in which the reset is done). Agents
    /// that have no frame yet first wait for one.
    #[pyo3(signature = (kind = "trial"))]
    fn reset(&mut self, py: Python<'_>, kind: &str) -> PyResult<()> {
        let cmd = reset_command(kind)?;
        if self.primed.iter().any(|p| !p) {
            let primed = self.primed.clone();
            // First frames only: agents that have one stop without commands.
            self.run(py, |k, _, _| primed[k])?;
        }
        self.run(py, |_, _, buffer| {
            buffer.push(cmd);
            true
        })
    }

    /// One lock-step cycle for every agent: agent `k` sends the commands of table entry
    /// `actions[k]` and its stop (agents with `reset[k]` true send a reset of
    /// `reset_kind` instead), then every agent's next frame is written into the output
    /// arrays. `actions`: N integers (numpy array or sequence).
    ///
    /// Raises `UsageError` before the first `reset()`, `ValueError` for an index outside
    /// the table, and the errors of `Agent.wait`/`Agent.stop`.
    #[pyo3(signature = (actions, *, reset = None, reset_kind = "trial"))]
    fn step(
        &mut self,
        py: Python<'_>,
        actions: &Bound<'_, PyAny>,
        reset: Option<&Bound<'_, PyAny>>,
        reset_kind: &str,
    ) -> PyResult<()> {
        let n = self.ids.len();
        // The group's own buffers (taken out while `run` borrows the group): no
        // allocation per step.
        let mut picked = std::mem::take(&mut self.picked);
        let mut resets = std::mem::take(&mut self.resets);
        let parsed = indices(actions, n, "actions", &mut picked)
            .and_then(|()| mask(reset, n, "reset", &mut resets));
        let table = std::mem::take(&mut self.table);
        let result = parsed.and_then(|()| {
            let reset_cmd = reset_command(reset_kind)?;
            if self.primed.iter().any(|p| !p) {
                return Err(self.not_primed(py));
            }
            for (k, &a) in picked.iter().enumerate() {
                if !resets[k] && usize::try_from(a).map_or(true, |a| a >= table.len()) {
                    return Err(PyValueError::new_err(format!(
                        "action {a} of agent {} is not in the action table (0..{})",
                        self.ids[k],
                        table.len()
                    )));
                }
            }
            self.run(py, |k, rot, buffer| {
                if resets[k] {
                    buffer.push(reset_cmd);
                } else if let Some(entry) =
                    usize::try_from(picked[k]).ok().and_then(|a| table.get(a))
                {
                    buffer.extend(entry.iter().map(|p| p.resolve(rot)));
                }
                true
            })
        });
        (self.table, self.picked, self.resets) = (table, picked, resets);
        result
    }

    /// One lock-step cycle with explicit commands: `commands[k]` (a `Command`, a
    /// `MoveAhead`, a sequence of them, or `None`) for agent `k`, then every agent's
    /// next frame, as `step`.
    fn step_commands(&mut self, py: Python<'_>, commands: &Bound<'_, PyAny>) -> PyResult<()> {
        let n = self.ids.len();
        let list: Vec<Vec<Planned>> = commands
            .try_iter()?
            .map(|e| planned(&e?))
            .collect::<PyResult<_>>()?;
        if list.len() != n {
            return Err(PyValueError::new_err(format!(
                "commands has {} entries for {n} agents",
                list.len()
            )));
        }
        if self.primed.iter().any(|p| !p) {
            return Err(self.not_primed(py));
        }
        self.run(py, |k, rot, buffer| {
            buffer.extend(list[k].iter().map(|p| p.resolve(rot)));
            true
        })
    }

    /// Camera name → its stacked images, `(N, H, W, 3)`/`(N, H, W, 4)` `uint8` or
    /// `(N, H, W)` `uint8`/`float32`: the same arrays every step, overwritten in place
    /// (new arrays each step with `fresh_images` or `zero_copy`).
    #[getter]
    fn images<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for (k, (name, out)) in self.images.iter().enumerate() {
            d.set_item(name, self.image_array(py, k, out))?;
        }
        Ok(d)
    }

    /// Whether the group's agents are stacked (`[transport.shm] stacked_images`, every
    /// agent of the group on shared memory, in id order, none left out between two of
    /// them): then `zero_copy` can be turned on.
    #[getter]
    fn stacked(&self) -> bool {
        self.stacked.is_some()
    }

    /// Whether `images` are read-only views of the shared memory the host wrote (default
    /// `False`): no copy at all. Each step gives new arrays, valid as long as they are
    /// held; like frames, at most 2 steps' images can be held at once (keep copies of
    /// what you keep longer, or the next step raises `TooManyFramesHeldError`). Needs
    /// `stacked`. A step whose frames are of different cycles (async mode) copies into
    /// the group's arrays instead. `fresh_images` does not apply to it.
    #[getter]
    fn zero_copy(&self) -> bool {
        self.zero_copy
    }

    #[setter]
    fn set_zero_copy(&mut self, on: bool) -> PyResult<()> {
        if on && self.stacked.is_none() {
            return Err(PyValueError::new_err(format!(
                "zero-copy images need the group's agents stacked: [transport.shm] \
                 stacked_images = true in {}, every agent of the group on shared memory and \
                 the group's ids the config's shared-memory agents in id order (got {:?})",
                self.config_path.display(),
                self.ids
            )));
        }
        self.zero_copy = on;
        if !on {
            self.views.clear();
        }
        Ok(())
    }

    /// Whether every step writes the images into new arrays (default `False`: the same
    /// arrays every step, overwritten in place). With `True` the arrays a step leaves
    /// (`images`, `image(name)`) keep their contents after later steps, for callers that
    /// hand out fresh observations: one copy from shared memory per image and step, where
    /// copying the arrays after the step would be a second. The other outputs are
    /// overwritten in place either way.
    #[getter]
    fn fresh_images(&self) -> bool {
        self.fresh
    }

    #[setter]
    fn set_fresh_images(&mut self, fresh: bool) {
        self.fresh = fresh;
    }

    /// The stacked images of camera `name` (see `images`).
    fn image<'py>(&self, py: Python<'py>, name: &str) -> PyResult<Bound<'py, PyAny>> {
        self.images
            .iter()
            .enumerate()
            .find(|(_, (n, _))| n == name)
            .map(|(k, (_, o))| self.image_array(py, k, o))
            .ok_or_else(|| {
                let names: Vec<&str> = self.images.iter().map(|(n, _)| n.as_str()).collect();
                pyo3::exceptions::PyKeyError::new_err(format!(
                    "no camera {name:?} (cameras: {names:?})"
                ))
            })
    }

    /// The stacked vectors (`[[agent.vector]]`): `{name: (N, len) float32}`, row `k` for
    /// `ids[k]`, overwritten in place by every step (as `images`).
    #[getter]
    fn vectors<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        self.channels.vectors_dict(py)
    }

    /// The stacked vector `name` (see `vectors`).
    fn vector<'py>(&self, py: Python<'py>, name: &str) -> PyResult<Bound<'py, PyAny>> {
        self.channels.vector(py, name)
    }

    /// The agents' `[[agent.vector]]` entries (the same for every agent).
    #[getter]
    fn vector_specs(&self) -> Vec<PyVector> {
        self.channels.vectors.clone()
    }

    /// The agents' `[[agent.action]]` entries (the same for every agent).
    #[getter]
    fn action_specs(&self) -> Vec<PyAction> {
        self.channels.actions.clone()
    }

    /// One lock-step cycle with channel actions: `values` maps an action's name to every
    /// agent's value, `(N, len)` floats for a continuous action, `(N,)` ints for a
    /// discrete one (an action left out is not sent); each agent sends its row and its
    /// stop (agents with `reset[k]` true send a reset of `reset_kind` instead, agents
    /// with `active[k]` false only their stop: their rows are ignored), then every
    /// agent's next frame is written into the output arrays.
    ///
    /// Raises `UsageError` before the first `reset()`, `KeyError` for an unknown action,
    /// `ValueError` for the wrong number of values, `ActionError` for a value out of its
    /// bounds (nothing is sent then), and the errors of `Agent.wait`/`Agent.stop`.
    #[pyo3(signature = (values, *, reset = None, reset_kind = "trial", active = None))]
    fn step_actions(
        &mut self,
        py: Python<'_>,
        values: &Bound<'_, PyAny>,
        reset: Option<&Bound<'_, PyAny>>,
        reset_kind: &str,
        active: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<()> {
        let n = self.ids.len();
        let (mut reset_mask, mut active_mask) = (Vec::new(), Vec::new());
        mask(reset, n, "reset", &mut reset_mask)?;
        let reset = reset_mask;
        let active = match active {
            Some(a) => {
                mask(Some(a), n, "active", &mut active_mask)?;
                active_mask
            }
            None => vec![true; n],
        };
        let active: Vec<bool> = (0..n).map(|k| active[k] && !reset[k]).collect();
        let rows = self.channels.rows(py, values, &self.ids, &active)?;
        let reset_cmd = reset_command(reset_kind)?;
        if self.primed.iter().any(|p| !p) {
            return Err(self.not_primed(py));
        }
        let specs = self.channels.actions.clone();
        for (k, agent) in self.agents()?.iter_mut().enumerate() {
            if active[k] {
                act_row(py, agent, &specs, &rows, k)?;
            }
        }
        self.run(py, |k, _, buffer| {
            if reset[k] {
                buffer.push(reset_cmd);
            }
            true
        })
    }

    /// Body positions `(N, 3)` `float32`, metres.
    #[getter]
    fn positions<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        self.outs[0].1.array.bind(py).clone()
    }

    /// Body rotations `(N, 4)` `float32`, quaternions (x, y, z, w).
    #[getter]
    fn rotations<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        self.outs[1].1.array.bind(py).clone()
    }

    /// Rewards received since the previous frame, `(N,)` `float32`.
    #[getter]
    fn rewards<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        self.outs[2].1.array.bind(py).clone()
    }

    /// Simulated time of each frame in nanoseconds, `(N,)` `uint64`.
    #[getter]
    fn sim_time_ns<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        self.outs[3].1.array.bind(py).clone()
    }

    /// The cycle of each agent's frame, `(N,)` `uint64` (equal for all in sync mode).
    #[getter]
    fn cycles<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        self.outs[4].1.array.bind(py).clone()
    }

    /// Collisions each frame brings (each once), `(N,)` `uint32`.
    #[getter]
    fn collisions<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        self.outs[5].1.array.bind(py).clone()
    }

    /// How each agent's previous cycle ended, `(N,)` `uint8`: 0 none (first frame or
    /// async mode), 1 stopped, 2 timed out (the host did not get the stop in time).
    #[getter]
    fn previous_outcome<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        self.outs[6].1.array.bind(py).clone()
    }

    /// Commands of each agent the host rejected in the previous cycle, `(N,)` `uint32`.
    #[getter]
    fn previous_rejected<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        self.outs[7].1.array.bind(py).clone()
    }

    /// Frames each agent never saw since it connected, `(N,)` `uint64`.
    #[getter]
    fn frames_skipped<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        self.outs[8].1.array.bind(py).clone()
    }

    /// `(steps, sdk_seconds, wait_seconds)` since connect (or `reset_timing`): calls of
    /// `reset`/`step`/`step_commands` (a `reset` that first waits for the first frames
    /// counts twice), the time spent inside them except blocked waiting (sending,
    /// receiving, copying), and the time blocked waiting for frames.
    #[getter]
    fn timing(&self) -> (u64, f64, f64) {
        (
            self.steps,
            self.sdk_ns as f64 * 1e-9,
            self.wait_ns as f64 * 1e-9,
        )
    }

    /// Sets `timing` back to zero.
    fn reset_timing(&mut self) {
        (self.steps, self.sdk_ns, self.wait_ns) = (0, 0, 0);
    }

    /// Disconnects every agent (each leaves the session). Idempotent. Returns within about
    /// a second even when the host does not answer (a frozen process, a lost link).
    fn close(&mut self, py: Python<'_>) {
        if let Some(agents) = self.agents.take() {
            // The closes may wait for the host: without the GIL.
            py.detach(move || drop(agents));
        }
    }

    fn __enter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    #[pyo3(signature = (*_args))]
    fn __exit__(&mut self, py: Python<'_>, _args: &Bound<'_, PyTuple>) -> bool {
        self.close(py);
        false
    }

    fn __len__(&self) -> usize {
        self.ids.len()
    }

    /// The agent ids, in row order.
    #[getter]
    fn ids(&self) -> Vec<u32> {
        self.ids.clone()
    }

    /// The session name.
    #[getter]
    fn session(&self) -> &str {
        &self.session
    }

    /// The config file the agents were connected with.
    #[getter]
    fn config_path(&self) -> PathBuf {
        self.config_path.clone()
    }

    /// Whether the session runs in lock-step (sync) mode.
    #[getter]
    fn sync_mode(&self) -> bool {
        self.sync_mode
    }

    /// Seconds the host waits for an agent's stop (see the config's `[sync]`).
    #[getter]
    fn stop_timeout(&self) -> f64 {
        self.stop_timeout.as_secs_f64()
    }

    /// Seconds a step waits for every frame; `None`: without limit (see `connect`).
    #[getter]
    fn step_timeout(&self) -> Option<f64> {
        self.step_timeout.map(|t| t.as_secs_f64())
    }

    /// Simulated seconds per cycle.
    #[getter]
    fn simulation_time_per_frame(&self) -> f64 {
        self.simulation_time_per_frame.as_secs_f64()
    }

    /// The cameras every agent has, in image order.
    #[getter]
    fn cameras(&self) -> Vec<PyCamera> {
        self.cameras.clone()
    }

    /// Each agent's transport (`"shm"`, `"tcp"` or `"zenoh"`), in row order.
    #[getter]
    fn transports(&self) -> Vec<&'static str> {
        self.transports.clone()
    }

    /// Whether `close()` was called.
    #[getter]
    fn closed(&self) -> bool {
        self.agents.is_none()
    }

    fn __reduce__(&self) -> PyResult<()> {
        Err(PyTypeError::new_err(
            "an AgentGroup holds live connections to a vrsync host and cannot be pickled or \
             sent to another process: build it in the process that uses it",
        ))
    }

    fn __repr__(&self) -> String {
        format!(
            "<vrsync.AgentGroup ids={:?} session={:?}{}>",
            self.ids,
            self.session,
            if self.agents.is_none() { " closed" } else { "" }
        )
    }
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<AgentGroup>()?;
    m.add_class::<stacked::PyStackedSample>()?;
    Ok(())
}
