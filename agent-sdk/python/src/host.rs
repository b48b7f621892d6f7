//! `vrsync.Host`: the host API in Python, for simulators written in Python (MuJoCo,
//! PyBullet, Gymnasium envs) to serve vrsync agents.
//!
//! The Rust host ([`vrsync_bridge::Host`]) does the work; this module adds what Python
//! needs: frames whose images are writable numpy views of the loaned memory (see
//! [`frame`]), waits that release the GIL and end on Ctrl-C, reports as Python objects
//! (see [`report`]) and typed exceptions.
//!
//! # Ctrl-C
//! The host calls an interrupt hook at least every 50 ms while it waits (for agents, for
//! stops, for the tick); the hook takes the GIL for a moment and runs Python's pending
//! signal handlers. When one raises (Ctrl-C's `KeyboardInterrupt`), the hook keeps the
//! exception and ends the wait, and the waiting method raises it.
//!
//! # Threads
//! The host's transports are not thread-safe (iceoryx2 `ipc::Service` ports), so the host
//! and its frames are `unsendable` classes: usable only on the thread that created them.
//! Releasing the GIL does not move anything: [`SameThread`] carries the host through
//! `Python::detach`, whose closure runs on the calling thread.

use std::cell::RefCell;
use std::path::PathBuf;
use std::rc::Rc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use pyo3::exceptions::{PyKeyError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use vrsync_bridge::{
    Host, HostCycleError, HostTransportError, HostWaitError, SensorFrameMut, SignalHandling,
};

use crate::agent::{PyCamera, SameThread, cameras_of, load_config, secs};
use crate::errors::{error, obj};

mod frame;
mod report;

use frame::FrameNames;
pub(crate) use frame::PyHostFrame;
pub(crate) use report::{PyAgentReport, PyCycleReport};

/// Tells the frames of one `Host` from those of another (`publish` checks).
static NEXT_HOST: AtomicU64 = AtomicU64::new(1);

/// The exception a signal handler raised while the host waited, kept by the interrupt
/// hook for the waiting method to raise.
type Raised = Rc<RefCell<Option<PyErr>>>;

/// The host's interrupt hook: runs Python's pending signal handlers (the GIL is taken
/// for that moment only); `true`, with the exception kept in `raised`, when one raised.
fn interrupt_hook(raised: Raised) -> impl FnMut() -> bool + 'static {
    move || {
        Python::attach(|py| match py.check_signals() {
            Ok(()) => false,
            Err(e) => {
                *raised.borrow_mut() = Some(e);
                true
            }
        })
    }
}

/// The simulator side of a vrsync session: serves the agents of a config file over the
/// transports the config names for them (shared memory, TCP, zenoh; one lock-step world).
///
/// One cycle:
///
/// ```python
/// with vrsync.Host("world.toml") as host:
///     host.wait_for_agents()
///     while running:
///         for agent_id in host.agent_ids:
///             frame = host.loan(agent_id)
///             view = frame.image("left")      # writable numpy view, no copy
///             render(agent_id, out=view)
///             del view                        # views must be gone before publish
///             frame.set_pose(position, rotation)
///             host.publish(frame)
///         host.start()
///         report = host.collect()             # GIL released; Ctrl-C ends it
///         for ar in report.agents:
///             apply(ar.agent_id, ar.commands)
/// ```
///
/// In sync mode `collect` returns once every agent that got a frame sent its stop for
/// this cycle (or its stop timeout passed); in async mode at the next tick of
/// `simulation_time_per_frame` real time, with the commands that arrived meanwhile.
///
/// Used from the thread that created it (as are its frames).
#[pyclass(module = "vrsync._vrsync", name = "Host", unsendable)]
pub(crate) struct PyHost {
    host: Option<Host>,
    /// This host's number (frames carry it).
    token: u64,
    config_path: PathBuf,
    session: String,
    sync_mode: bool,
    simulation_time_per_frame: Duration,
    connect_timeout: Duration,
    cameras: Vec<(u32, Vec<PyCamera>)>,
    /// Each agent's camera and vector names, made at its first loan and shared by its
    /// frames.
    names: Vec<(u32, Rc<FrameNames>)>,
    raised: Raised,
}

impl PyHost {
    fn host(&mut self, py: Python<'_>) -> PyResult<&mut Host> {
        match self.host.as_mut() {
            Some(h) => Ok(h),
            None => Err(error(
                py,
                "UsageError",
                format!("the host of session {:?} is closed", self.session),
                &[("session", obj(py, &self.session))],
            )),
        }
    }

    /// The names of `frame`'s agent, shared (see [`FrameNames`]).
    fn names_of(&mut self, frame: &SensorFrameMut) -> Rc<FrameNames> {
        let id = frame.agent_id();
        match self.names.iter_mut().find(|(a, _)| *a == id) {
            Some((_, names)) if names.fits(frame) => names.clone(),
            Some((_, names)) => {
                *names = Rc::new(FrameNames::of(frame));
                names.clone()
            }
            None => {
                let names = Rc::new(FrameNames::of(frame));
                self.names.push((id, names.clone()));
                names
            }
        }
    }

    /// The exception the interrupt hook kept (Ctrl-C's `KeyboardInterrupt`).
    fn raised(&self, py: Python<'_>) -> PyErr {
        self.raised.borrow_mut().take().unwrap_or_else(|| {
            error(
                py,
                "TransportError",
                format!("session {:?}: the wait was interrupted", self.session),
                &[("session", obj(py, &self.session))],
            )
        })
    }

    fn cycle_error(&self, py: Python<'_>, e: HostCycleError) -> PyErr {
        if let HostCycleError::Terminated = e {
            return self.raised(py);
        }
        let msg = format!("session {:?}: {e}", self.session);
        let session = ("session", obj(py, &self.session));
        match e {
            HostCycleError::UnknownAgent(id) => PyKeyError::new_err(format!(
                "agent {id} is not part of session {:?} (its agents: {:?})",
                self.session,
                self.agent_ids()
            )),
            HostCycleError::StaleFrame { agent, .. } => error(
                py,
                "UsageError",
                msg,
                &[session, ("agent_id", obj(py, agent))],
            ),
            HostCycleError::AgentLost { agent, .. }
            | HostCycleError::AgentNotBack { agent, .. } => error(
                py,
                "AgentLostError",
                msg,
                &[session, ("agent_id", obj(py, agent))],
            ),
            _ => error(py, "TransportError", msg, &[session]),
        }
    }
}

/// `HostWaitError::AgentsMissing` as `HostWaitTimeout`; anything else as `TransportError`.
fn wait_error(py: Python<'_>, e: HostWaitError, session: &str) -> PyErr {
    let msg = e.to_string();
    match e {
        HostWaitError::AgentsMissing {
            missing,
            left,
            waited,
            ..
        } => error(
            py,
            "HostWaitTimeout",
            msg,
            &[
                ("session", obj(py, session)),
                ("missing", obj(py, missing)),
                ("left", obj(py, left)),
                ("waited", obj(py, waited.as_secs_f64())),
            ],
        ),
        _ => error(py, "TransportError", msg, &[("session", obj(py, session))]),
    }
}

fn agent_id(v: i64) -> PyResult<u32> {
    u32::try_from(v).map_err(|_| PyValueError::new_err(format!("agent_id must be ≥ 0, got {v}")))
}

#[pymethods]
impl PyHost {
    /// Creates the host of the session in `config` (a vrsync TOML file): the services and
    /// listeners of every transport its agents use. `session` overrides the config's
    /// session name; `agents` resizes the agent list to ids `0..agents` (new agents copy
    /// the last configured agent's cameras and channels), as `vr-sim run --spawn-agents`
    /// does.
    ///
    /// Raises `ConfigError` (bad file or arguments), `TransportError` (a transport cannot
    /// be set up: a TCP address in use, too little shared memory, ...).
    #[new]
    #[pyo3(signature = (config, *, session = None, agents = None))]
    fn new(
        py: Python<'_>,
        config: PathBuf,
        session: Option<String>,
        agents: Option<u32>,
    ) -> PyResult<Self> {
        let config_error = |e: vrsync_bridge::ConfigLoadError| {
            error(
                py,
                "ConfigError",
                e.to_string(),
                &[("path", obj(py, config.clone()))],
            )
        };
        let mut cfg = load_config(py, &config)?;
        if let Some(s) = session {
            cfg = cfg.with_session(&s).map_err(config_error)?;
        }
        if let Some(n) = agents {
            cfg = cfg.with_agent_count(n).map_err(config_error)?;
        }
        let session = cfg.session.clone();
        let transport_error = |msg: String| {
            error(
                py,
                "TransportError",
                msg,
                &[("session", obj(py, session.clone()))],
            )
        };
        // /dev/shm is filled lazily: too little of it would be a SIGBUS at the first write
        // into a frame, not an error here.
        vrsync_bridge::check_shm_budget(&cfg).map_err(|e| transport_error(e.to_string()))?;
        let mut host = py
            .detach(|| {
                SameThread(
                    Host::builder(&cfg)
                        // Python keeps its own SIGINT/SIGTERM handlers (Ctrl-C raises
                        // KeyboardInterrupt while the host waits).
                        .signal_handling(SignalHandling::Leave)
                        .create(),
                )
            })
            .0
            .map_err(|e| transport_error(format!("session {session:?}: {e}")))?;
        let raised = Raised::default();
        host.set_interrupt(interrupt_hook(raised.clone()));
        Ok(Self {
            host: Some(host),
            token: NEXT_HOST.fetch_add(1, Ordering::Relaxed),
            config_path: config,
            sync_mode: cfg.sync.sync_mode,
            simulation_time_per_frame: cfg.sync.simulation_time_per_frame,
            connect_timeout: cfg.sync.connect_timeout,
            cameras: cfg.agents.iter().map(|a| (a.id, cameras_of(a))).collect(),
            names: Vec::new(),
            session,
            raised,
        })
    }

    /// Waits until every agent of the session is connected (frames sent earlier would be
    /// lost), up to `timeout` seconds (default: the config's `connect_timeout`). The GIL
    /// is released; Ctrl-C raises `KeyboardInterrupt`.
    ///
    /// Raises `HostWaitTimeout` (a `TimeoutError`) naming the missing agents.
    #[pyo3(signature = (timeout = None))]
    fn wait_for_agents(&mut self, py: Python<'_>, timeout: Option<f64>) -> PyResult<()> {
        let timeout = secs("timeout", timeout)?.unwrap_or(self.connect_timeout);
        let host = SameThread(self.host(py)?);
        let result = py.detach(move || {
            let host = host;
            SameThread(host.0.wait_for_agents(timeout))
        });
        match result.0 {
            Ok(()) => Ok(()),
            Err(HostWaitError::Terminated) => Err(self.raised(py)),
            Err(e) => Err(wait_error(py, e, &self.session)),
        }
    }

    /// Loans agent `agent_id`'s sensor frame for the current cycle, its header filled in
    /// (cycle, simulated time, image table, the previous cycle's outcome). Write it, then
    /// `publish` it.
    ///
    /// Raises `KeyError` for an agent not in the session, `TransportError` when no memory
    /// can be loaned (e.g. a frame of this agent loaned earlier is still held).
    fn loan(&mut self, py: Python<'_>, agent_id: i64) -> PyResult<PyHostFrame> {
        let id = self::agent_id(agent_id)?;
        let token = self.token;
        let frame = self.host(py)?.loan_frame(id);
        match frame {
            Ok(f) => {
                let names = self.names_of(&f);
                Ok(PyHostFrame::new(f, token, names))
            }
            Err(e @ HostCycleError::Transport(HostTransportError::Loan { .. })) => Err(error(
                py,
                "TransportError",
                format!(
                    "session {:?}: {e} (is a frame loaned earlier for agent {id} still \
                         alive, neither published nor dropped? The shared-memory transport \
                         lends one at a time)",
                    self.session
                ),
                &[
                    ("session", obj(py, &self.session)),
                    ("agent_id", obj(py, id)),
                ],
            )),
            Err(e) => Err(self.cycle_error(py, e)),
        }
    }

    /// Publishes `frame` to its agent (in sync mode the agent is then awaited this
    /// cycle). A frame for an agent that is not connected is dropped and counted
    /// (`stats()["frames_undelivered"]`). Afterwards the frame's memory is the agent's:
    /// the frame exports no views any more.
    ///
    /// Raises `FrameInUseError` (a `BufferError`) while numpy views of the frame are alive
    /// (nothing is published; `del` them and call again), `UsageError` for a frame
    /// published already, loaned by another host or in an earlier cycle.
    fn publish(&mut self, py: Python<'_>, frame: &Bound<'_, PyHostFrame>) -> PyResult<()> {
        let token = self.token;
        // A closed host keeps the frame as it is (not taken, not dropped).
        self.host(py)?;
        let loan = frame.try_borrow_mut()?.take(py, token)?;
        let result = self.host(py)?.publish(loan);
        result.map_err(|e| self.cycle_error(py, e))
    }

    /// Signals *start* to every agent: call once per cycle, after every frame of the
    /// cycle is published.
    fn start(&mut self, py: Python<'_>) -> PyResult<()> {
        let result = self.host(py)?.start();
        result.map_err(|e| self.cycle_error(py, e))
    }

    /// Ends the cycle and returns its `CycleReport`. Sync mode: waits until every agent
    /// whose frame was published this cycle sent its stop (as long as it lives, or up to
    /// `stop_timeout` for agents with `wait_for_stop = "timeout"`); async mode: waits
    /// until the next tick. Then the cycle number and simulated time advance. The GIL is
    /// released while waiting; Ctrl-C raises `KeyboardInterrupt` within 50 ms. The cycle
    /// does not end then: calling `collect` again finishes it, with the stops and the
    /// commands that came before the interrupt.
    ///
    /// Raises `AgentLostError` (an agent was lost and `on_agent_lost` is `"abort"`, or
    /// `"wait"` and it did not come back), `TransportError`.
    fn collect(&mut self, py: Python<'_>) -> PyResult<PyCycleReport> {
        let host = SameThread(self.host(py)?);
        let result = py.detach(move || {
            let host = host;
            SameThread(host.0.collect())
        });
        match result.0 {
            Ok(report) => PyCycleReport::new(py, report),
            Err(e) => Err(self.cycle_error(py, e)),
        }
    }

    /// Records how many of agent `agent_id`'s commands of this cycle the simulator
    /// rejected; the agent reads it in its next frame (`Frame.previous_rejected`).
    fn set_rejected(&mut self, py: Python<'_>, agent_id: i64, rejected: u32) -> PyResult<()> {
        let id = self::agent_id(agent_id)?;
        self.host(py)?.set_rejected(id, rejected);
        Ok(())
    }

    /// Whether agent `agent_id` is connected now; a TCP agent whose link was lost counts as
    /// connected while its place is held for its return (`[sync] resume_window`).
    fn is_connected(&mut self, py: Python<'_>, agent_id: i64) -> PyResult<bool> {
        let id = self::agent_id(agent_id)?;
        Ok(self.host(py)?.is_connected(id))
    }

    /// The counters since the host was created, by name (`cycles`, `stop_timeouts`,
    /// `frames_delivered`, `commands_received`, `evictions`, ...).
    fn stats<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let s = self.host(py)?.stats().clone();
        let d = PyDict::new(py);
        for (k, v) in [
            ("cycles", s.cycles),
            ("stop_timeouts", s.stop_timeouts),
            ("agent_timeouts", s.agent_timeouts),
            ("slow_stops", s.slow_stops),
            ("late_batches", s.late_batches),
            ("future_batches", s.future_batches),
            ("commands_received", s.commands_received),
            ("commands_overflowed", s.commands_overflowed),
            ("frames_undelivered", s.frames_undelivered),
            ("frames_delivered", s.frames_delivered),
            ("frames_read", s.frames_read),
            ("statuses_dropped", s.statuses_dropped),
            ("collisions_dropped", s.collisions_dropped),
            ("rejoins", s.rejoins),
            ("leaves", s.leaves),
            ("resumes", s.resumes),
            ("evictions", s.evictions),
            ("peers_refused", s.peers_refused),
            ("actions_rejected", s.actions_rejected),
        ] {
            d.set_item(k, v)?;
        }
        Ok(d)
    }

    /// The cameras of agent `agent_id` as configured, in image order (names, sizes and
    /// formats of what `HostFrame.image` returns). Raises `KeyError` for an unknown agent.
    fn cameras(&self, agent_id: i64) -> PyResult<Vec<PyCamera>> {
        self.cameras
            .iter()
            .find(|(id, _)| i64::from(*id) == agent_id)
            .map(|(_, c)| c.clone())
            .ok_or_else(|| {
                PyKeyError::new_err(format!(
                    "agent {agent_id} is not part of session {:?}",
                    self.session
                ))
            })
    }

    /// Ends the session: agents see the host close (their `frames()` loops end). Frames
    /// still held stay valid memory but cannot be published. Idempotent.
    fn close(&mut self) {
        self.host = None;
    }

    fn __enter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    #[pyo3(signature = (*_args))]
    fn __exit__(&mut self, _args: &Bound<'_, pyo3::types::PyTuple>) -> bool {
        self.close();
        false
    }

    /// Agent ids, ascending.
    #[getter]
    fn agent_ids(&self) -> Vec<u32> {
        self.cameras.iter().map(|(id, _)| *id).collect()
    }

    /// The session name.
    #[getter]
    fn session(&self) -> &str {
        &self.session
    }

    /// The config file the host was created from.
    #[getter]
    fn config_path(&self) -> PathBuf {
        self.config_path.clone()
    }

    /// Whether the session runs in lock-step (sync) mode.
    #[getter]
    fn sync_mode(&self) -> bool {
        self.sync_mode
    }

    /// Simulated seconds per cycle (in async mode also the real time between two).
    #[getter]
    fn simulation_time_per_frame(&self) -> f64 {
        self.simulation_time_per_frame.as_secs_f64()
    }

    /// The current cycle number (advanced by `collect`).
    #[getter]
    fn cycle(&mut self, py: Python<'_>) -> PyResult<u64> {
        Ok(self.host(py)?.cycle())
    }

    /// Simulated time at the start of the current cycle, in nanoseconds.
    #[getter]
    fn sim_time_ns(&mut self, py: Python<'_>) -> PyResult<u64> {
        Ok(self.host(py)?.sim_time_ns())
    }

    /// `"host:port"` where TCP agents connect (the bound port when the config's
    /// `tcp_listen` has port 0), or `None` when no agent uses TCP.
    #[getter]
    fn tcp_address(&mut self, py: Python<'_>) -> PyResult<Option<String>> {
        Ok(self.host(py)?.tcp_local_addr().map(|a| a.to_string()))
    }

    /// Whether `close()` was called.
    #[getter]
    fn closed(&self) -> bool {
        self.host.is_none()
    }

    fn __repr__(&self) -> String {
        let cycle = self
            .host
            .as_ref()
            .map_or_else(|| "closed".to_owned(), |h| format!("cycle={}", h.cycle()));
        format!(
            "<vrsync.Host session={:?} agents={:?} {} {cycle}>",
            self.session,
            self.agent_ids(),
            if self.sync_mode { "sync" } else { "async" }
        )
    }
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyHost>()?;
    m.add_class::<PyHostFrame>()?;
    m.add_class::<PyCycleReport>()?;
    m.add_class::<PyAgentReport>()?;
    Ok(())
}
