//! The host API: what a simulator (vr-sim, or Unity through the C ABI) calls.
//!
//! One cycle, in order:
//! 1. [`Host::loan_frame`] for each agent → write the header fields and render the images
//!    straight into [`SensorFrameMut`] → [`Host::publish`];
//! 2. [`Host::start`]: one broadcast *start*;
//! 3. [`Host::collect`]: in sync mode block until every agent whose frame was published
//!    sent its stop for this cycle, or `stop_timeout` passed; in async mode wait until the
//!    next tick, taking commands as they arrive. The returned [`CycleReport`] lists each
//!    agent's outcome and commands in (agent id, order sent) order; the cycle number then
//!    advances and simulated time with it, by exactly `simulation_time_per_frame`.

use std::time::{Duration, Instant};

use tracing::{debug, info, warn};

use crate::barrier::{AgentOutcome, BatchVerdict, CycleBarrier};
use crate::events::PendingEvents;
use crate::transport::mixed::{AnyLoan, Transports};
use crate::transport::{FrameLoanMut, HostTransport, HostTransportError, PeerRefusal};
use crate::wire::{
    ActionDesc, ActionState, ImageDesc, MAX_ACTIONS, MAX_CAMERAS, MAX_VECTORS, MotorCommand,
    PROTOCOL_VERSION, SENSOR_FLAG_SYNC_MODE, SensorHeader, VectorDesc, WireOutcome,
};
use vrsync_transport::Rounded;
use vrsync_transport::SignalHandling;
use vrsync_transport::{AgentLostPolicy, Config, WaitForStop};

mod actions;
mod collect;
mod errors;
mod frame;
mod report;
#[cfg(test)]
mod tests;

pub use actions::ActionValue;
use actions::AgentActions;
pub use errors::*;
pub use frame::*;
pub use report::*;

/// Builds a [`Host`] from a [`Config`].
#[derive(Debug)]
pub struct HostBuilder<'c> {
    config: &'c Config,
    signals: SignalHandling,
}

impl<'c> HostBuilder<'c> {
    /// A builder for `config`.
    pub fn new(config: &'c Config) -> Self {
        Self {
            config,
            signals: SignalHandling::default(),
        }
    }

    /// Whether the host installs SIGINT/SIGTERM handlers. Default:
    /// [`SignalHandling::Leave`] (the embedding process keeps its own handlers, and
    /// [`HostCycleError::Terminated`] is never returned); programs that own their process
    /// choose [`SignalHandling::Install`]. No config key.
    pub fn signal_handling(mut self, signals: SignalHandling) -> Self {
        self.signals = signals;
        self
    }

    /// Creates the transport's services and the host's ports.
    ///
    /// # Errors
    /// [`HostCreateError`].
    pub fn create(self) -> Result<Host, HostCreateError> {
        let backend = Transports::create(self.config, self.signals)?;
        Ok(Host::over(self.config, backend, self.signals))
    }
}

impl<T: HostTransport> Host<T> {
    /// A host of `config` over `backend` (the builder's transports, or a test's fake);
    /// `signals` says whether a termination request ends its waits.
    pub(crate) fn over(config: &Config, backend: T, signals: SignalHandling) -> Self {
        let config = config.clone();
        let n = config.agents.len();
        let cap = config.transport.max_commands_per_cycle as usize * 2;
        let slots = config
            .agents
            .iter()
            .map(|a| {
                let (descs, _) = a.image_layout();
                SlotState {
                    id: a.id,
                    descs,
                    image_count: a.cameras.len().min(MAX_CAMERAS),
                    vectors: a.vector_layout().0,
                    vector_count: a.vectors.len().min(MAX_VECTORS),
                    actions: a.action_table(),
                    action_count: a.actions.len().min(MAX_ACTIONS),
                    last_outcome: WireOutcome::None,
                    last_rejected: 0,
                    evicted: false,
                    seen: false,
                    events: PendingEvents::new(),
                    read_cycle: None,
                    evicted_in: None,
                    rejoined_in: None,
                    connected_once: false,
                    wait_for_stop: a.wait_for_stop,
                    left: false,
                    left_in: None,
                }
            })
            .collect();
        let agents = config
            .agents
            .iter()
            .map(|a| AgentReport {
                agent_id: a.id,
                outcome: AgentOutcome::NotAwaited,
                read_cycle: None,
                evicted: false,
                rejoined: false,
                left: false,
                slow: false,
                commands: Vec::with_capacity(cap),
                actions: AgentActions::new(&a.actions),
            })
            .collect();
        let dt_ns = config.sync.simulation_time_per_frame.as_nanos() as u64;
        info!(
            session = %config.session,
            agents = n,
            mode = if config.sync.sync_mode { "sync" } else { "async" },
            transport = config.transport.kind.as_str(),
            "host created"
        );
        Host {
            backend,
            signals,
            slots,
            barrier: CycleBarrier::new(n),
            cycle: 0,
            dt_ns,
            report: CycleReport {
                cycle: 0,
                sim_time_ns: 0,
                timed_out: false,
                late_batches: 0,
                agents,
            },
            stats: HostStats::default(),
            next_tick: None,
            dead: Vec::with_capacity(n),
            leaving: Vec::with_capacity(n),
            lost_this_cycle: Vec::with_capacity(n),
            evicted_hook: None,
            refused_hook: None,
            slow_hook: None,
            interrupt: None,
            collecting: None,
            wait_started: None,
            config,
        }
    }
}

#[derive(Debug)]
struct SlotState {
    id: u32,
    descs: [ImageDesc; MAX_CAMERAS],
    image_count: usize,
    vectors: [VectorDesc; MAX_VECTORS],
    vector_count: usize,
    actions: [ActionDesc; MAX_ACTIONS],
    action_count: usize,
    last_outcome: WireOutcome,
    last_rejected: u32,
    /// Evicted and not yet back.
    evicted: bool,
    /// A frame reached it since it was last evicted (so losing it now is news).
    seen: bool,
    /// Its statuses and collisions not acknowledged yet, repeated in every frame.
    events: PendingEvents,
    /// The newest cycle it acknowledged having read.
    read_cycle: Option<u64>,
    /// The cycle of its latest eviction.
    evicted_in: Option<u64>,
    /// The cycle it latest rejoined in.
    rejoined_in: Option<u64>,
    /// Seen connected while the host waited for its agents.
    connected_once: bool,
    /// Its effective `wait_for_stop`.
    wait_for_stop: WaitForStop,
    /// Out because it left gracefully (with `evicted` set: out until a frame reaches a
    /// new connection).
    left: bool,
    /// The cycle of its latest graceful leave.
    left_in: Option<u64>,
}

/// The longest the host waits between two calls of its interrupt hook
/// ([`Host::set_interrupt`]).
pub const INTERRUPT_PERIOD: Duration = Duration::from_millis(50);

/// How often the host looks for dead agent processes while it waits.
pub const REAP_PERIOD: Duration = Duration::from_millis(100);

/// How often, at most, the host asks its transports whether each awaited agent is still
/// connected while it waits for stops (besides the first look of each wait and every
/// [`REAP_PERIOD`]). With many agents the host wakes up for each stop; asking about every
/// agent on each wake-up cost more than the rest of the wait (64 agents: ~70 µs a
/// cycle). A wait that skipped the question ends by the time it is due again.
pub const CONNECTION_CHECK_PERIOD: Duration = Duration::from_millis(1);

/// The host side of a vrsync session, over the transports its agents use (`T` is only
/// replaced in the crate's own tests, by a fake transport).
pub struct Host<T: HostTransport = Transports> {
    config: Config,
    backend: T,
    /// Whether SIGINT/SIGTERM end the waits (read here, not by the transports).
    signals: SignalHandling,
    slots: Vec<SlotState>,
    barrier: CycleBarrier,
    cycle: u64,
    dt_ns: u64,
    report: CycleReport,
    stats: HostStats,
    next_tick: Option<Instant>,
    dead: Vec<usize>,
    /// Slots whose leave batch the last drain brought.
    leaving: Vec<usize>,
    lost_this_cycle: Vec<usize>,
    evicted_hook: Option<Box<dyn FnMut(u32, u64)>>,
    refused_hook: Option<RefusedHook>,
    slow_hook: Option<SlowHook>,
    interrupt: Option<Box<dyn FnMut() -> bool>>,
    /// The cycle whose collect began and did not finish (it is finished by the next).
    collecting: Option<u64>,
    /// When the current wait for agents began (a caller may wait in slices).
    wait_started: Option<Instant>,
}

/// What [`Host::on_peer_refused`] installs.
type RefusedHook = Box<dyn FnMut(&PeerRefusal)>;

/// What [`Host::on_slow`] installs.
type SlowHook = Box<dyn FnMut(u32, u64, Duration)>;

impl<T: HostTransport> core::fmt::Debug for Host<T> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Host")
            .field("session", &self.config.session)
            .field("cycle", &self.cycle)
            .field("stats", &self.stats)
            .finish()
    }
}

impl Host {
    /// A builder for `config`.
    pub fn builder(config: &Config) -> HostBuilder<'_> {
        HostBuilder::new(config)
    }
}

impl<T: HostTransport> Host<T> {
    /// The configuration the host runs with.
    pub fn config(&self) -> &Config {
        &self.config
    }

    /// Agent ids, ascending.
    pub fn agent_ids(&self) -> impl Iterator<Item = u32> + '_ {
        self.slots.iter().map(|s| s.id)
    }

    fn slot_of(&self, id: u32) -> Option<usize> {
        self.slots.iter().position(|s| s.id == id)
    }

    /// The current cycle number.
    pub fn cycle(&self) -> u64 {
        self.cycle
    }

    /// Simulated time at the start of the current cycle: `cycle × simulation_time_per_frame`.
    pub fn sim_time_ns(&self) -> u64 {
        self.cycle.saturating_mul(self.dt_ns)
    }

    /// Counters so far.
    pub fn stats(&self) -> &HostStats {
        &self.stats
    }

    /// Whether agent `id` is connected (its receiving side is attached), or its link was
    /// lost and the host holds its place for its return (`[sync] resume_window`): frames
    /// published to it reach it when it is back, and in sync mode the cycle waits for it.
    pub fn is_connected(&self, id: u32) -> bool {
        self.slot_of(id)
            .is_some_and(|s| self.backend.is_connected(s))
    }

    /// Whether agent `id` is evicted: it was lost (process died or disconnected) and no
    /// frame has reached it since. It rejoins when one does (see [`Host::publish`]).
    pub fn is_evicted(&self, id: u32) -> bool {
        self.slot_of(id)
            .is_some_and(|s| self.slots[s].evicted && !self.slots[s].left)
    }

    /// Whether agent `id` left the session gracefully and no frame has reached a new
    /// connection of that id since (it rejoins when one does, as an evicted agent).
    pub fn has_left(&self, id: u32) -> bool {
        self.slot_of(id)
            .is_some_and(|s| self.slots[s].evicted && self.slots[s].left)
    }

    /// Calls `hook(agent, cycle)` each time an agent is evicted, as it happens: also while
    /// [`Host::collect`] blocks (e.g. when `on_agent_lost = "wait"` pauses for the agent).
    pub fn on_evicted(&mut self, hook: impl FnMut(u32, u64) + 'static) {
        self.evicted_hook = Some(Box::new(hook));
    }

    /// Calls `hook(agent, cycle, waited)` while [`Host::collect`] waits past `stop_timeout`
    /// for a live agent whose `wait_for_stop` is `"alive"`: at 1×, 2×, 4×, … `stop_timeout`
    /// into the cycle, as it happens (so a stuck but alive agent is visible while the
    /// host waits for it).
    pub fn on_slow(&mut self, hook: impl FnMut(u32, u64, Duration) + 'static) {
        self.slow_hook = Some(Box::new(hook));
    }

    /// Calls `hook(refusal)` for each peer a transport refused or dropped before admitting
    /// it as an agent (garbage, a wrong token or version, an unknown or taken id, a silent
    /// connection), as the host notices it: while it waits for agents and for stops.
    /// [`HostStats::peers_refused`] counts them all, also the ones a flood left without
    /// details.
    pub fn on_peer_refused(&mut self, hook: impl FnMut(&PeerRefusal) + 'static) {
        self.refused_hook = Some(Box::new(hook));
    }

    /// Lets `hook` end the host's waits: while [`Host::wait_for_agents`] and
    /// [`Host::collect`] block, the host calls it at least every [`INTERRUPT_PERIOD`], and
    /// when it returns `true` the wait ends with the `Terminated` error, as after SIGINT
    /// with [`SignalHandling::Install`]. For embedders that keep their own signal
    /// handling (a Python interpreter checks for Ctrl-C here). An interrupted collect does
    /// not end its cycle: the next `collect` finishes it, with the stops and commands that
    /// came before the interrupt.
    pub fn set_interrupt(&mut self, hook: impl FnMut() -> bool + 'static) {
        self.interrupt = Some(Box::new(hook));
    }

    /// Waits for transport activity for up to `timeout`, in slices of
    /// [`INTERRUPT_PERIOD`] when an interrupt hook is set (see [`Host::set_interrupt`]).
    fn wait_activity(&mut self, timeout: Duration) -> Result<(), HostTransportError> {
        let Some(hook) = &mut self.interrupt else {
            self.backend.wait_activity(timeout)?;
            return self.check_termination();
        };
        if hook() {
            return Err(HostTransportError::Terminated);
        }
        self.backend.wait_activity(timeout.min(INTERRUPT_PERIOD))?;
        let interrupted = self.interrupt.as_mut().is_some_and(|hook| hook());
        if interrupted {
            return Err(HostTransportError::Terminated);
        }
        self.check_termination()
    }

    /// `Terminated` once SIGINT/SIGTERM arrived (with [`SignalHandling::Install`]): a
    /// signal ends the transport's wait early, and the host reads the flag after it.
    fn check_termination(&self) -> Result<(), HostTransportError> {
        if self.signals.termination_requested() {
            return Err(HostTransportError::Terminated);
        }
        Ok(())
    }

    /// Takes the transports' refusals into the stats and the hook.
    fn take_refusals(&mut self) {
        let stats = &mut self.stats;
        let hook = &mut self.refused_hook;
        let unkept = self.backend.take_refusals(&mut |r| {
            stats.peers_refused += 1;
            if let Some(hook) = hook {
                hook(r);
            }
        });
        stats.peers_refused += unkept;
        self.stats.resumes += self.backend.take_resumes();
    }

    /// The address TCP agents connect to (the bound port when `tcp_listen` has port 0);
    /// `None` on shared memory.
    pub fn tcp_local_addr(&self) -> Option<std::net::SocketAddr> {
        self.backend.local_addr()
    }

    /// Whether SIGINT/SIGTERM was received.
    pub fn termination_requested(&self) -> bool {
        self.signals.termination_requested()
    }

    /// Records how many of agent `id`'s commands the simulator rejected this cycle; the
    /// agent sees the number in its next frame (`previous_rejected`).
    pub fn set_rejected(&mut self, id: u32, rejected: u32) {
        if let Some(s) = self.slot_of(id) {
            self.slots[s].last_rejected = rejected;
        }
    }

    /// Blocks until every configured agent is connected, logging which are still missing.
    /// Notifications sent before an agent's listener exists are lost, so cycle 0 must not
    /// start earlier.
    ///
    /// # Errors
    /// [`HostWaitError::AgentsMissing`] naming the ids after `timeout`.
    pub fn wait_for_agents(&mut self, timeout: Duration) -> Result<(), HostWaitError> {
        let started = Instant::now();
        // Callers may wait in slices (vr-sim does, to report progress): the log counts
        // from the first slice.
        let first_started = *self.wait_started.get_or_insert(started);
        let deadline = started + timeout;
        let mut next_log = started + Duration::from_secs(2);
        let mut logged_once = false;
        loop {
            let mut missing = Vec::new();
            for (slot, s) in self.slots.iter_mut().enumerate() {
                if self.backend.is_connected(slot) {
                    s.connected_once = true;
                } else {
                    missing.push(s.id);
                }
            }
            if missing.is_empty() {
                self.backend.update_connections()?;
                self.wait_started = None;
                info!(
                    agents = self.slots.len(),
                    waited_ms = first_started.elapsed().as_millis() as u64,
                    "all agents connected"
                );
                return Ok(());
            }
            let now = Instant::now();
            if now >= deadline {
                let left = self
                    .slots
                    .iter()
                    .filter(|s| s.connected_once && missing.contains(&s.id))
                    .map(|s| s.id)
                    .collect();
                return Err(HostWaitError::AgentsMissing {
                    session: self.config.session.clone(),
                    missing,
                    left,
                    waited: started.elapsed(),
                });
            }
            if !logged_once || now >= next_log {
                info!(?missing, session = %self.config.session, "waiting for agents");
                logged_once = true;
                next_log = now + Duration::from_secs(2);
            }
            // Agents notify the stop event once their ports exist; the 1 s cap only paces
            // the log line above.
            match self.wait_activity((deadline - now).min(Duration::from_secs(1))) {
                Ok(()) => self.take_refusals(),
                Err(HostTransportError::Terminated) => return Err(HostWaitError::Terminated),
                Err(e) => return Err(e.into()),
            }
        }
    }

    /// Loans agent `id`'s sensor frame for the current cycle, header pre-filled (protocol
    /// version, agent id, cycle, simulated time, mode, image, vector and action tables,
    /// previous outcome); its vectors are zeros until written, its images hold whatever the
    /// recycled sample held (write every pixel).
    ///
    /// # Errors
    /// [`HostCycleError`].
    pub fn loan_frame(&mut self, id: u32) -> Result<SensorFrameMut<T::Loan>, HostCycleError> {
        let slot = self.slot_of(id).ok_or(HostCycleError::UnknownAgent(id))?;
        let mut loan = self.backend.loan(slot)?;
        let s = &self.slots[slot];
        let h = loan.parts_mut().0;
        h.protocol_version = PROTOCOL_VERSION;
        h.agent_id = id;
        h.cycle = self.cycle;
        h.sim_time_ns = self.sim_time_ns();
        h.flags = if self.config.sync.sync_mode {
            SENSOR_FLAG_SYNC_MODE
        } else {
            0
        };
        h.image_count = s.image_count as u32;
        h.images = s.descs;
        h.vector_count = s.vector_count as u32;
        h.vectors = s.vectors;
        h.action_count = s.action_count as u32;
        h.actions = s.actions;
        h.previous_outcome = s.last_outcome as u32;
        h.previous_rejected = s.last_rejected;
        // The simulator adds this cycle's events; publish adds the unacknowledged ones.
        h.status_count = 0;
        h.collision_count = 0;
        // A vector the simulator does not write is zeros, never a value of an older
        // cycle that the recycled sample still holds.
        let payload = loan.parts_mut().1;
        for d in &s.vectors[..s.vector_count] {
            if let Some(values) = d.values_mut(payload) {
                values.fill(0.0);
            }
        }
        Ok(SensorFrameMut {
            slot,
            agent_id: id,
            cycle: self.cycle,
            loan,
            descs: s.descs,
            image_count: s.image_count,
            vectors: s.vectors,
            vector_count: s.vector_count,
        })
    }

    /// Publishes a frame; if it reached its agent, that agent is awaited this cycle (sync
    /// mode). A frame for an agent that is not connected is dropped and counted.
    ///
    /// The statuses and collisions the simulator wrote into the header are this cycle's
    /// new events; publish adds every earlier event the agent has not acknowledged yet
    /// (see [`SensorHeader::statuses`]), so the simulator reports each event once and the
    /// agent gets it even if it skips frames.
    ///
    /// # Errors
    /// [`HostCycleError`].
    pub fn publish(&mut self, mut frame: SensorFrameMut<T::Loan>) -> Result<(), HostCycleError> {
        if frame.cycle != self.cycle {
            return Err(HostCycleError::StaleFrame {
                agent: frame.agent_id,
                loaned: frame.cycle,
                current: self.cycle,
            });
        }
        let slot = frame.slot;
        let dropped = self.slots[slot]
            .events
            .merge_into(frame.loan.parts_mut().0, self.cycle);
        if dropped.statuses + dropped.collisions > 0 {
            self.stats.statuses_dropped += u64::from(dropped.statuses);
            self.stats.collisions_dropped += u64::from(dropped.collisions);
            debug!(
                agent = frame.agent_id,
                statuses = dropped.statuses,
                collisions = dropped.collisions,
                "unacknowledged events dropped: the agent's table is full"
            );
        }
        if self.backend.publish(slot, frame.loan)? {
            self.stats.frames_delivered += 1;
            self.barrier.await_slot(slot);
            self.slots[slot].seen = true;
            if self.slots[slot].evicted {
                self.slots[slot].evicted = false;
                self.slots[slot].left = false;
                self.slots[slot].rejoined_in = Some(self.cycle);
                self.stats.rejoins += 1;
                info!(agent = frame.agent_id, cycle = self.cycle, "agent rejoined");
            }
        } else {
            self.stats.frames_undelivered += 1;
            debug!(
                agent = frame.agent_id,
                cycle = self.cycle,
                "frame not delivered: agent not connected"
            );
        }
        Ok(())
    }

    /// Signals *start* to every agent. Call after all frames of the cycle are published.
    ///
    /// # Errors
    /// [`HostCycleError`].
    pub fn start(&mut self) -> Result<(), HostCycleError> {
        self.backend.signal_start()?;
        Ok(())
    }

    /// Ends the cycle. Sync mode: blocks until every agent whose frame was published this
    /// cycle sent its stop, or `stop_timeout` passed (missing agents are logged and
    /// counted). Async mode: waits until the next tick of `simulation_time_per_frame` real
    /// time, taking every batch that arrives. Then advances the cycle number.
    ///
    /// # Errors
    /// [`HostCycleError::Terminated`] on SIGINT/SIGTERM; transport failures.
    pub fn collect(&mut self) -> Result<&CycleReport, HostCycleError> {
        let cycle = self.cycle;
        // A collect that ended early (an interrupt, a transport error) left this cycle's
        // report half filled: the next collect goes on with it.
        if self.collecting != Some(cycle) {
            self.collecting = Some(cycle);
            self.report.cycle = cycle;
            self.report.sim_time_ns = self.sim_time_ns();
            self.report.timed_out = false;
            self.report.late_batches = 0;
            for a in &mut self.report.agents {
                a.commands.clear();
                a.actions.begin_cycle();
                a.outcome = AgentOutcome::NotAwaited;
            }
        }
        if self.config.sync.sync_mode {
            self.collect_sync()?;
        } else {
            self.collect_async()?;
        }
        self.collecting = None;
        for (a, s) in self.report.agents.iter_mut().zip(&self.slots) {
            a.read_cycle = s.read_cycle;
            a.evicted = s.evicted_in == Some(cycle);
            a.rejoined = s.rejoined_in == Some(cycle);
            a.left = s.left_in == Some(cycle);
        }
        for (slot, a) in self.report.agents.iter_mut().enumerate() {
            a.slow = self.barrier.is_slow(slot);
        }
        self.stats.cycles += 1;
        self.cycle += 1;
        self.barrier.begin(self.cycle);
        Ok(&self.report)
    }
}
