//! `vrsync.Agent`: connect, wait for frames, send commands, stop.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::thread::{self, ThreadId};
use std::time::{Duration, Instant};

use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use vrsync_agent::{
    Agent, AgentBuilder, AgentConnectError, SignalHandling, StopError, WaitStartError,
};
use vrsync_bridge::{Config, WaitForStop};

use crate::channels::{PyAction, PyVector, channels_of};
use crate::commands::PyCommand;
pub(crate) use crate::detach::SameThread;
use crate::errors::{error, obj, send_error};
use crate::frame::{Graveyard, PyFrame};

/// The longest the GIL is released in one go while waiting: Ctrl-C is seen within this.
const WAIT_SLICE: Duration = Duration::from_millis(50);

/// The Rust agent, used only on its owner thread (see [`PyAgent::enter`]).
pub(crate) struct AgentCell(Agent);

/// One camera of this agent, as configured: what `Frame.image(name)` returns for it.
#[pyclass(module = "vrsync._vrsync", name = "Camera", frozen, get_all)]
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct PyCamera {
    /// Camera name.
    pub(crate) name: String,
    /// Width in pixels.
    pub(crate) width: u32,
    /// Height in pixels.
    pub(crate) height: u32,
    /// `"rgb8"`, `"rgba8"`, `"gray8"` or `"depth32f"`.
    pub(crate) format: String,
    /// Horizontal field of view in degrees.
    fov_horizontal_deg: f32,
    /// Vertical field of view in degrees.
    fov_vertical_deg: f32,
}

#[pymethods]
impl PyCamera {
    /// The numpy shape of this camera's images: (H, W, 3), (H, W, 4) or (H, W).
    #[getter]
    pub(crate) fn shape(&self) -> Vec<u32> {
        match self.format.as_str() {
            "rgb8" => vec![self.height, self.width, 3],
            "rgba8" => vec![self.height, self.width, 4],
            _ => vec![self.height, self.width],
        }
    }

    /// The numpy dtype name of this camera's images: `"uint8"` or `"float32"`.
    #[getter]
    pub(crate) fn dtype(&self) -> &'static str {
        if self.format == "depth32f" {
            "float32"
        } else {
            "uint8"
        }
    }

    fn __repr__(&self) -> String {
        format!(
            "Camera(name={:?}, width={}, height={}, format={:?})",
            self.name, self.width, self.height, self.format
        )
    }
}

fn format_name(f: vrsync_agent::PixelFormat) -> &'static str {
    use vrsync_agent::PixelFormat as P;
    match f {
        P::Rgb8 => "rgb8",
        P::Rgba8 => "rgba8",
        P::Gray8 => "gray8",
        P::Depth32f => "depth32f",
    }
}

/// An agent connected to a vrsync host: receives one sensor frame per cycle and answers
/// with motor commands and a stop.
///
/// ```python
/// with vrsync.Agent.connect("config/default.toml", agent_id=0) as agent:
///     for frame in agent.frames(timeout=10):   # ends when the host closes the session
///         left = frame.image("left")           # read-only numpy view, no copy
///         agent.send(vrsync.Turn(angle_deg=10))
///         agent.stop()
/// ```
///
/// An agent is used from one thread at a time; it moves to another thread only while no
/// frame of it is alive.
#[pyclass(module = "vrsync._vrsync", name = "Agent")]
pub(crate) struct PyAgent {
    agent: Option<AgentCell>,
    owner: ThreadId,
    graveyard: Arc<Graveyard>,
    id: u32,
    session: String,
    config_path: PathBuf,
    transport: &'static str,
    sync_mode: bool,
    stop_timeout: Duration,
    wait_for_stop: WaitForStop,
    frame_wait: Option<Duration>,
    simulation_time_per_frame: Duration,
    max_commands: u32,
    cameras: Vec<PyCamera>,
    vectors: Vec<PyVector>,
    actions: Vec<PyAction>,
}

/// How long an env waits for its next frame by default. Without limit when the host may
/// wait for a live agent's stop without limit ([`Config::waits_for_live_agents`]): a
/// learner updating in another process holds the cycle for as long as it takes, and a
/// dead host ends the wait anyway (liveness). Otherwise the host ends every cycle within
/// `stop_timeout`: `2 × stop_timeout + 5 s`.
pub(crate) fn default_frame_wait(cfg: &Config) -> Option<Duration> {
    (!cfg.waits_for_live_agents()).then(|| 2 * cfg.sync.stop_timeout + Duration::from_secs(5))
}

pub(crate) fn secs(name: &str, v: Option<f64>) -> PyResult<Option<Duration>> {
    v.map(|s| {
        Duration::try_from_secs_f64(s).map_err(|_| {
            PyValueError::new_err(format!(
                "{name} must be a non-negative number of seconds, got {s}"
            ))
        })
    })
    .transpose()
}

fn connect_error(py: Python<'_>, e: AgentConnectError, session: &str, id: u32) -> PyErr {
    let msg = e.to_string();
    // Every connect error names the session and the agent; some add more.
    let raise = |class: &str, extra: Vec<(&'static str, Py<PyAny>)>| {
        let mut attrs = vec![("session", obj(py, session)), ("agent_id", obj(py, id))];
        attrs.extend(extra);
        error(py, class, msg.clone(), &attrs)
    };
    match e {
        AgentConnectError::HostNotFound { waited, .. } => raise(
            "HostNotFoundError",
            vec![("waited", obj(py, waited.as_secs_f64()))],
        ),
        AgentConnectError::IdNotServed { served, .. } => {
            raise("AgentIdNotServedError", vec![("served", obj(py, served))])
        }
        AgentConnectError::VersionMismatch {
            host_protocol,
            agent_protocol,
            ..
        } => raise(
            "VersionMismatchError",
            vec![
                ("host_version", obj(py, host_protocol)),
                ("agent_version", obj(py, agent_protocol.to_string())),
            ],
        ),
        AgentConnectError::IdInUse { .. } => raise("AgentIdInUseError", vec![]),
        AgentConnectError::ChannelMismatch { difference, .. } => raise(
            "ChannelMismatchError",
            vec![
                ("channel", obj(py, difference.name)),
                ("table", obj(py, difference.table)),
                ("host", obj(py, difference.host)),
                ("agent", obj(py, difference.agent)),
            ],
        ),
        AgentConnectError::Refused { .. } => raise("ConnectionRefusedByHostError", vec![]),
        _ => raise("TransportError", vec![]),
    }
}

/// The cameras of one `[[agent]]` entry, in image order.
pub(crate) fn cameras_of(agent: &vrsync_bridge::AgentConfig) -> Vec<PyCamera> {
    agent
        .cameras
        .iter()
        .map(|c| PyCamera {
            name: c.name.clone(),
            width: c.width_px,
            height: c.height_px,
            format: format_name(c.format).to_owned(),
            fov_horizontal_deg: c.fov_horizontal_deg,
            fov_vertical_deg: c.fov_vertical_deg,
        })
        .collect()
}

/// Connects agent `id` of `cfg`, waiting up to `timeout` for the host, in slices so that
/// Ctrl-C raises `KeyboardInterrupt` while the host is not up yet; a stacked agent shares
/// `stack` (the reader of its group's other agents), else opens its own.
pub(crate) fn connect_one(
    py: Python<'_>,
    cfg: &Config,
    id: u32,
    timeout: Duration,
    stack: Option<&vrsync_agent::SharedStack>,
) -> PyResult<Agent> {
    let started = Instant::now();
    loop {
        let left = timeout.saturating_sub(started.elapsed());
        // Slices as short as a wait's: Ctrl-C is seen between two attempts.
        let slice = left.min(WAIT_SLICE);
        let stack = SameThread(stack);
        let attempt = py.detach(move || {
            let stack = stack;
            let mut builder = AgentBuilder::new(cfg, id)
                .connect_timeout(slice)
                // Python keeps its own SIGINT/SIGTERM handlers (Ctrl-C raises
                // KeyboardInterrupt while waiting, see `PyAgent::wait_frame`).
                .signal_handling(SignalHandling::Leave);
            if let Some(stack) = stack.0 {
                builder = builder.stack(stack);
            }
            SameThread(builder.connect())
        });
        match attempt.0 {
            Ok(agent) => return Ok(agent),
            Err(AgentConnectError::HostNotFound { .. }) if started.elapsed() < timeout => {
                py.check_signals()?;
            }
            Err(AgentConnectError::HostNotFound {
                session,
                agent,
                looked_for,
                ..
            }) => {
                // The last attempt waited one slice; the agent waited since the first.
                let e = AgentConnectError::HostNotFound {
                    session,
                    agent,
                    waited: started.elapsed(),
                    looked_for,
                };
                return Err(connect_error(py, e, &cfg.session, id));
            }
            Err(e) => return Err(connect_error(py, e, &cfg.session, id)),
        }
    }
}

impl PyAgent {
    /// Admits the calling thread: the owner, or any thread while no frame of this agent
    /// is alive (ownership moves with it). Drops frames released on other threads.
    fn enter(&mut self) -> PyResult<&mut Agent> {
        let me = thread::current().id();
        if me != self.owner {
            if self.graveyard.alive() > 0 {
                return Err(PyRuntimeError::new_err(
                    "this vrsync Agent is used by another thread that still holds frames of it; \
                     use an agent from one thread (or release its frames before handing it on)",
                ));
            }
            self.owner = me;
        }
        self.graveyard.drain();
        match self.agent.as_mut() {
            Some(cell) => Ok(&mut cell.0),
            None => Err(PyRuntimeError::new_err(format!(
                "agent {} of session {:?} is closed",
                self.id, self.session
            ))),
        }
    }

    /// Waits for the next frame, releasing the GIL in short slices so that Ctrl-C (and
    /// any other signal handler) runs at once.
    /// `Ok(None)`: the host closed the session (a clean end, for `frames()` to stop on).
    fn wait_frame(
        &mut self,
        py: Python<'_>,
        timeout: Option<Duration>,
    ) -> PyResult<Option<PyFrame>> {
        let started = Instant::now();
        let deadline = timeout.map(|t| started + t);
        loop {
            let slice = deadline.map_or(WAIT_SLICE, |d| {
                d.saturating_duration_since(Instant::now()).min(WAIT_SLICE)
            });
            let agent = SameThread(self.enter()?);
            let result = py.detach(move || {
                let agent = agent;
                SameThread(agent.0.wait_start(Some(slice)))
            });
            match result.0 {
                Ok(frame) => {
                    let skipped = self.agent.as_ref().map_or(0, |a| a.0.frames_skipped());
                    return Ok(Some(PyFrame::new(frame, self.graveyard.clone(), skipped)));
                }
                Err(WaitStartError::Timeout { .. }) => {
                    py.check_signals()?;
                    if deadline.is_some_and(|d| Instant::now() >= d) {
                        let e = WaitStartError::Timeout {
                            waited: started.elapsed(),
                            last_cycle: self.agent.as_ref().and_then(|a| a.0.last_cycle()),
                        };
                        return Err(wait_error(py, e, &self.session, self.id, started.elapsed()));
                    }
                }
                Err(WaitStartError::HostClosed) => return Ok(None),
                Err(e) => return Err(wait_error(py, e, &self.session, self.id, started.elapsed())),
            }
        }
    }
}

#[pymethods]
impl PyAgent {
    /// Connects agent `agent_id` to the host of the session in `config` (a vrsync TOML
    /// file), waiting up to `connect_timeout` seconds for the host (default: the config's
    /// `connect_timeout`). `session` overrides the config's session name.
    ///
    /// Raises `ConfigError` (bad file), `HostNotFoundError`, `VersionMismatchError`,
    /// `AgentIdInUseError`, `ChannelMismatchError`, `ConnectionRefusedByHostError`,
    /// `TransportError`.
    #[staticmethod]
    #[pyo3(signature = (config, agent_id, *, session = None, connect_timeout = None))]
    fn connect(
        py: Python<'_>,
        config: PathBuf,
        agent_id: i64,
        session: Option<String>,
        connect_timeout: Option<f64>,
    ) -> PyResult<Self> {
        let id = u32::try_from(agent_id)
            .map_err(|_| PyValueError::new_err(format!("agent_id must be ≥ 0, got {agent_id}")))?;
        let mut cfg = load_config(py, &config)?;
        if let Some(s) = session {
            cfg.session = s;
        }
        let timeout = secs("connect_timeout", connect_timeout)?.unwrap_or(cfg.sync.connect_timeout);
        let agent_cfg = cfg.agents.iter().find(|a| a.id == id).ok_or_else(|| {
            let ids: Vec<u32> = cfg.agents.iter().map(|a| a.id).collect();
            error(
                py,
                "ConfigError",
                format!(
                    "{} has no [[agent]] with id {id} (its agents: {ids:?})",
                    config.display()
                ),
                &[("path", obj(py, config.clone()))],
            )
        })?;
        let agent_transport = agent_cfg.transport;
        let wait_for_stop = agent_cfg.wait_for_stop;
        let cameras = cameras_of(agent_cfg);
        let (vectors, actions) = channels_of(agent_cfg);
        let agent = AgentCell(connect_one(py, &cfg, id, timeout, None)?);
        Ok(Self {
            agent: Some(agent),
            owner: thread::current().id(),
            graveyard: Arc::default(),
            id,
            session: cfg.session.clone(),
            config_path: config,
            transport: agent_transport.as_str(),
            sync_mode: cfg.sync.sync_mode,
            stop_timeout: cfg.sync.stop_timeout,
            wait_for_stop,
            frame_wait: default_frame_wait(&cfg),
            simulation_time_per_frame: cfg.sync.simulation_time_per_frame,
            max_commands: cfg.transport.max_commands_per_cycle,
            cameras,
            vectors,
            actions,
        })
    }

    /// Waits for the next frame (newer than the last one returned) and returns it.
    /// `timeout` in seconds; `None` waits without limit (the host's liveness is still
    /// checked, and Ctrl-C raises `KeyboardInterrupt`).
    ///
    /// Raises `HostClosedError` when the host ended the session, `HostGoneError` (a
    /// `ConnectionError`) when its process died, `WaitTimeoutError` (a `TimeoutError`),
    /// `TooManyFramesHeldError`.
    #[pyo3(signature = (timeout = None))]
    fn wait(&mut self, py: Python<'_>, timeout: Option<f64>) -> PyResult<PyFrame> {
        let timeout = secs("timeout", timeout)?;
        self.wait_frame(py, timeout)?.ok_or_else(|| {
            wait_error(
                py,
                WaitStartError::HostClosed,
                &self.session,
                self.id,
                Duration::ZERO,
            )
        })
    }

    /// Iterates over frames until the host closes the session (the loop then ends
    /// cleanly). `timeout` applies to each wait, as in `wait`.
    #[pyo3(signature = (timeout = None))]
    fn frames(slf: Bound<'_, Self>, timeout: Option<f64>) -> PyResult<FrameIter> {
        Ok(FrameIter {
            agent: slf.unbind(),
            timeout: secs("timeout", timeout)?,
        })
    }

    /// Queues `command` for this cycle and returns its action id (frames report the
    /// action's status and collisions under this id). Nothing reaches the host before
    /// `stop()`.
    ///
    /// Raises `QueueFullError` beyond the config's `max_commands_per_cycle`.
    fn send(&mut self, py: Python<'_>, command: PyRef<'_, PyCommand>) -> PyResult<u32> {
        let cmd = command.command;
        let id = self.id;
        let agent = self.enter()?;
        agent.send(cmd).map_err(|e| send_error(py, e, id))
    }

    /// Queues `command` with an action id of your choice (0 ..= 2³²−1).
    fn send_with_id(
        &mut self,
        py: Python<'_>,
        action_id: i64,
        command: PyRef<'_, PyCommand>,
    ) -> PyResult<()> {
        let action_id = u32::try_from(action_id).map_err(|_| {
            PyValueError::new_err(format!(
                "action_id must be in 0..={}, got {action_id}",
                u32::MAX
            ))
        })?;
        let cmd = command.command;
        let id = self.id;
        let agent = self.enter()?;
        agent
            .send_with_id(action_id, cmd)
            .map_err(|e| send_error(py, e, id))
    }

    /// Queues the value of action `name` (`[[agent.action]]`) for this cycle: a sequence of
    /// floats (a list, a numpy array) for a continuous action, an int for a discrete one.
    /// It reaches the host with `stop()`; the host takes the last value sent in a cycle.
    ///
    /// Raises `ActionError` (a `ValueError`) naming the action when the name is unknown or
    /// the value has the wrong length, lies outside the bounds, is not finite or is not a
    /// valid choice (nothing is queued then); `QueueFullError` beyond
    /// `max_commands_per_cycle` (a continuous action takes one entry per 4 values).
    fn act(&mut self, py: Python<'_>, name: &str, value: &Bound<'_, PyAny>) -> PyResult<()> {
        let agent = self.enter()?;
        crate::channels::act(py, agent, name, value)
    }

    /// Sends the queued commands with the *stop* flag: this agent is done with the cycle
    /// of the newest frame. Raises `HostClosedError` when the session already ended.
    fn stop(&mut self, py: Python<'_>) -> PyResult<()> {
        let session = self.session.clone();
        let id = self.id;
        let agent = self.enter()?;
        agent.stop().map_err(|e| stop_error(py, e, &session, id))
    }

    /// Disconnects. Frames still held stay readable. Idempotent.
    fn close(&mut self) {
        if self.agent.is_some() && thread::current().id() == self.owner {
            self.graveyard.drain();
        }
        self.agent = None;
    }

    fn __enter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    #[pyo3(signature = (*_args))]
    fn __exit__(&mut self, _args: &Bound<'_, pyo3::types::PyTuple>) -> bool {
        self.close();
        false
    }

    /// This agent's id.
    #[getter]
    fn id(&self) -> u32 {
        self.id
    }

    /// The session name.
    #[getter]
    fn session(&self) -> &str {
        &self.session
    }

    /// The config file this agent was connected with.
    #[getter]
    fn config_path(&self) -> PathBuf {
        self.config_path.clone()
    }

    /// `"shm"` or `"tcp"`.
    #[getter]
    fn transport(&self) -> &'static str {
        self.transport
    }

    /// Whether the session runs in lock-step (sync) mode.
    #[getter]
    fn sync_mode(&self) -> bool {
        self.sync_mode
    }

    /// Seconds after which the host reports this agent's missing stop (`"alive"`) or
    /// ends the cycle without it (`"timeout"`): see `wait_for_stop`.
    #[getter]
    fn stop_timeout(&self) -> f64 {
        self.stop_timeout.as_secs_f64()
    }

    /// How the host waits for this agent's stop in sync mode: `"alive"` (as long as this
    /// agent lives; past `stop_timeout` it is reported as slow) or `"timeout"` (the cycle
    /// ends without it after `stop_timeout`).
    #[getter]
    fn wait_for_stop(&self) -> &'static str {
        self.wait_for_stop.as_str()
    }

    /// How long the envs wait for the next frame by default, in seconds; `None`: without
    /// limit, because the host waits for live agents (a dead host still ends the wait).
    #[getter]
    fn frame_wait(&self) -> Option<f64> {
        self.frame_wait.map(|t| t.as_secs_f64())
    }

    /// Simulated seconds per cycle.
    #[getter]
    fn simulation_time_per_frame(&self) -> f64 {
        self.simulation_time_per_frame.as_secs_f64()
    }

    /// Most commands this agent may send per cycle.
    #[getter]
    fn max_commands_per_cycle(&self) -> u32 {
        self.max_commands
    }

    /// The agent's cameras as configured, in image order.
    #[getter]
    fn cameras(&self) -> Vec<PyCamera> {
        self.cameras.clone()
    }

    /// The agent's vectors (`[[agent.vector]]`) as configured: what `Frame.vector(name)`
    /// returns, in payload order.
    #[getter]
    fn vector_specs(&self) -> Vec<PyVector> {
        self.vectors.clone()
    }

    /// The agent's actions (`[[agent.action]]`) as configured: what `act(name, value)`
    /// takes, in config order.
    #[getter]
    fn action_specs(&self) -> Vec<PyAction> {
        self.actions.clone()
    }

    /// The cycle of the newest frame received, or `None` before the first.
    #[getter]
    fn last_cycle(&self) -> Option<u64> {
        self.agent.as_ref().and_then(|a| a.0.last_cycle())
    }

    /// Frames this agent never saw because a newer one was waiting.
    #[getter]
    fn frames_skipped(&self) -> u64 {
        self.agent.as_ref().map_or(0, |a| a.0.frames_skipped())
    }

    /// Frames of this agent alive now (kept alive by `Frame` objects or their image
    /// arrays). A wait fails with `TooManyFramesHeldError` when it is already
    /// `MAX_FRAMES_HELD`.
    #[getter]
    fn frames_held(&self) -> usize {
        self.graveyard.alive()
    }

    /// Whether `close()` was called.
    #[getter]
    fn closed(&self) -> bool {
        self.agent.is_none()
    }

    fn __repr__(&self) -> String {
        format!(
            "<vrsync.Agent id={} session={:?} transport={}{}>",
            self.id,
            self.session,
            self.transport,
            if self.agent.is_none() { " closed" } else { "" }
        )
    }
}

/// A wait error of agent `id` of `session` as the matching `vrsync.errors` exception.
pub(crate) fn wait_error(
    py: Python<'_>,
    e: WaitStartError,
    session: &str,
    id: u32,
    waited: Duration,
) -> PyErr {
    let msg = e.to_string();
    let base = [("session", obj(py, session)), ("agent_id", obj(py, id))];
    match e {
        WaitStartError::HostClosed => error(py, "HostClosedError", msg, &base),
        WaitStartError::HostGone { .. } => error(py, "HostGoneError", msg, &base),
        WaitStartError::BadFrame { .. } => error(py, "ProtocolError", msg, &base),
        WaitStartError::Timeout { last_cycle, .. } => error(
            py,
            "WaitTimeoutError",
            format!(
                "no frame from the host of session {session:?} within {:.3} s (last cycle seen: {})",
                waited.as_secs_f64(),
                last_cycle.map_or_else(|| "none".to_owned(), |c| c.to_string())
            ),
            &base,
        ),
        WaitStartError::TooManyFramesHeld { max } => error(
            py,
            "TooManyFramesHeldError",
            too_many_held_message(id, max),
            &[
                ("session", obj(py, session)),
                ("agent_id", obj(py, id)),
                ("max", obj(py, max)),
            ],
        ),
        _ => error(py, "TransportError", msg, &base),
    }
}

/// The text of `TooManyFramesHeldError`.
pub(crate) fn too_many_held_message(id: u32, max: usize) -> String {
    format!(
        "agent {id} already holds {max} frames, the most it may (the frame being read and \
         one more): numpy arrays of earlier frames keep their frames alive; copy what you \
         keep beyond the cycle (`arr.copy()`) or drop those arrays. With the Gymnasium or \
         PettingZoo envs, use copy_observations=True (the default): frame-stacking \
         wrappers such as gymnasium.wrappers.FrameStackObservation keep their last \
         observations, which with copy_observations=False are such views"
    )
}

/// A stop error of agent `id` of `session` as the matching `vrsync.errors` exception.
pub(crate) fn stop_error(py: Python<'_>, e: StopError, session: &str, id: u32) -> PyErr {
    let msg = e.to_string();
    let base = [("session", obj(py, session)), ("agent_id", obj(py, id))];
    match e {
        StopError::HostClosed => error(py, "HostClosedError", msg, &base),
        StopError::NoFrame | StopError::AlreadyStopped { .. } => {
            error(py, "UsageError", msg, &base)
        }
        _ => error(py, "TransportError", msg, &base),
    }
}

/// Iterator returned by `Agent.frames()`: yields frames until the host closes the session.
#[pyclass(module = "vrsync._vrsync")]
pub(crate) struct FrameIter {
    agent: Py<PyAgent>,
    timeout: Option<Duration>,
}

#[pymethods]
impl FrameIter {
    fn __iter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    fn __next__(&self, py: Python<'_>) -> PyResult<Option<PyFrame>> {
        let mut agent = self.agent.bind(py).try_borrow_mut()?;
        agent.wait_frame(py, self.timeout)
    }
}

/// Loads `config`; a failure is a `ConfigError` carrying the path.
pub(crate) fn load_config(py: Python<'_>, config: &Path) -> PyResult<Config> {
    Config::load(config).map_err(|e| {
        error(
            py,
            "ConfigError",
            e.to_string(),
            &[("path", obj(py, config))],
        )
    })
}

/// The agent ids of the config file `config` (its `[[agent]]` entries), sorted.
///
/// Raises `ConfigError` for a file that does not load.
#[pyfunction]
fn config_agent_ids(py: Python<'_>, config: PathBuf) -> PyResult<Vec<u32>> {
    let cfg = load_config(py, &config)?;
    Ok(cfg.agents.iter().map(|a| a.id).collect())
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(config_agent_ids, m)?)?;
    m.add_class::<PyAgent>()?;
    m.add_class::<FrameIter>()?;
    m.add_class::<PyCamera>()?;
    Ok(())
}
