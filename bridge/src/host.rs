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
use crate::config::{AgentLostPolicy, Config, WaitForStop};
use crate::events::PendingEvents;
use crate::rounded::Rounded;
use crate::signal::SignalHandling;
use crate::transport::mixed::{AnyLoan, Transports, TransportsCreateError};
use crate::transport::shm::ShmHostCreateError;
use crate::transport::tcp::TcpHostCreateError;
use crate::transport::{FrameLoanMut, HostTransport, HostTransportError, PeerRefusal};
use crate::wire::{
    ActionState, ImageDesc, MAX_CAMERAS, MotorCommand, PROTOCOL_VERSION, SENSOR_FLAG_SYNC_MODE,
    SensorHeader, WireOutcome,
};

/// One writable image of a loaned sensor frame.
#[derive(Debug)]
pub struct ImageMut<'a> {
    /// Where and what the image is.
    pub desc: ImageDesc,
    /// The pixels, in shared memory on the shm transport.
    pub data: &'a mut [u8],
}

/// Iterator over the writable images of a [`SensorFrameMut`].
#[derive(Debug)]
pub struct ImagesMut<'a> {
    rest: &'a mut [u8],
    consumed: usize,
    descs: &'a [ImageDesc],
}

impl<'a> Iterator for ImagesMut<'a> {
    type Item = ImageMut<'a>;

    fn next(&mut self) -> Option<Self::Item> {
        let (desc, tail) = self.descs.split_first()?;
        self.descs = tail;
        let skip = (desc.offset as usize).checked_sub(self.consumed)?;
        let rest = core::mem::take(&mut self.rest);
        if rest.len() < skip + desc.len as usize {
            return None;
        }
        let (_, rest) = rest.split_at_mut(skip);
        let (data, rest) = rest.split_at_mut(desc.len as usize);
        self.rest = rest;
        self.consumed = desc.offset as usize + desc.len as usize;
        Some(ImageMut { desc: *desc, data })
    }
}

/// A sensor frame loaned for one agent: write the header and the images, then hand it to
/// [`Host::publish`]. Dropping it instead returns the memory unpublished.
#[derive(Debug)]
pub struct SensorFrameMut<L = AnyLoan> {
    slot: usize,
    agent_id: u32,
    cycle: u64,
    loan: L,
    descs: [ImageDesc; MAX_CAMERAS],
    image_count: usize,
}

impl<L: FrameLoanMut> SensorFrameMut<L> {
    /// The agent this frame is for.
    pub fn agent_id(&self) -> u32 {
        self.agent_id
    }

    /// The header (pre-filled with cycle, time, agent id and image table).
    pub fn header(&self) -> &SensorHeader {
        self.loan.header()
    }

    /// The header, writable: pose, sensors, statuses, collisions, reward.
    pub fn header_mut(&mut self) -> &mut SensorHeader {
        self.loan.parts_mut().0
    }

    /// The images, writable, in camera order.
    pub fn images_mut(&mut self) -> ImagesMut<'_> {
        self.parts_mut().1
    }

    /// Header and images at once (to render while reading the pose from the header).
    pub fn parts_mut(&mut self) -> (&mut SensorHeader, ImagesMut<'_>) {
        let (header, payload) = self.loan.parts_mut();
        (
            header,
            ImagesMut {
                rest: payload,
                consumed: 0,
                descs: &self.descs[..self.image_count],
            },
        )
    }
}

/// The commands and outcome of one agent in one cycle.
#[derive(Debug, Clone)]
pub struct AgentReport {
    /// Agent id.
    pub agent_id: u32,
    /// How its cycle ended.
    pub outcome: AgentOutcome,
    /// The newest cycle whose frame the agent acknowledged having read (its batches say
    /// so), `None` before its first acknowledgement (and again after an eviction). A frame
    /// delivered to it and older than this, and never acknowledged, was skipped.
    pub read_cycle: Option<u64>,
    /// The agent was evicted during this cycle (lost: its process died or it
    /// disconnected), also when its stop had arrived first (then `outcome` stays
    /// [`AgentOutcome::Stopped`]).
    pub evicted: bool,
    /// The agent rejoined in this cycle: its first frame since an eviction or a leave
    /// reached it.
    pub rejoined: bool,
    /// The agent left the session gracefully during this cycle (its SDK's `close()` or
    /// drop said so): not a fault, not evicted; its id is free for a new connection, which
    /// takes part from the next cycle. If its stop had arrived first, `outcome` stays
    /// [`AgentOutcome::Stopped`].
    pub left: bool,
    /// The host waited for its stop past `stop_timeout` (its `wait_for_stop` is `"alive"`
    /// and it stayed connected): a slow agent, reported, not timed out.
    pub slow: bool,
    commands: Vec<MotorCommand>,
}

impl AgentReport {
    /// Commands received this cycle, in the order the agent sent them. Decode each with
    /// [`MotorCommand::decode`]; the simulator decides what is out of range.
    pub fn commands(&self) -> &[MotorCommand] {
        &self.commands
    }
}

/// The result of one cycle.
#[derive(Debug, Clone)]
pub struct CycleReport {
    /// Cycle number.
    pub cycle: u64,
    /// Simulated time at the start of the cycle, ns.
    pub sim_time_ns: u64,
    /// Whether the cycle ended by the stop timeout.
    pub timed_out: bool,
    /// Batches for earlier cycles (or after a stop) dropped during this cycle.
    pub late_batches: u32,
    agents: Vec<AgentReport>,
}

impl CycleReport {
    /// Every agent's report, in the config's agent order.
    pub fn agents(&self) -> &[AgentReport] {
        &self.agents
    }

    /// The report of agent `id` (`None`: not an agent of this session).
    pub fn agent(&self, id: u32) -> Option<&AgentReport> {
        self.agents.iter().find(|a| a.agent_id == id)
    }

    /// Ids of agents evicted during this cycle ([`AgentReport::evicted`]).
    pub fn evicted_agents(&self) -> impl Iterator<Item = u32> + '_ {
        self.agents.iter().filter(|a| a.evicted).map(|a| a.agent_id)
    }

    /// Ids of agents that rejoined in this cycle ([`AgentReport::rejoined`]).
    pub fn rejoined_agents(&self) -> impl Iterator<Item = u32> + '_ {
        self.agents
            .iter()
            .filter(|a| a.rejoined)
            .map(|a| a.agent_id)
    }

    /// Ids of agents that left gracefully during this cycle ([`AgentReport::left`]).
    pub fn left_agents(&self) -> impl Iterator<Item = u32> + '_ {
        self.agents.iter().filter(|a| a.left).map(|a| a.agent_id)
    }

    /// Ids of agents waited for past `stop_timeout` this cycle ([`AgentReport::slow`]).
    pub fn slow_agents(&self) -> impl Iterator<Item = u32> + '_ {
        self.agents.iter().filter(|a| a.slow).map(|a| a.agent_id)
    }

    /// Ids of agents that timed out this cycle.
    pub fn timed_out_agents(&self) -> impl Iterator<Item = u32> + '_ {
        self.agents
            .iter()
            .filter(|a| a.outcome == AgentOutcome::TimedOut)
            .map(|a| a.agent_id)
    }
}

/// Counters since the host was created.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct HostStats {
    /// Cycles completed.
    pub cycles: u64,
    /// Cycles that ended by the stop timeout.
    pub stop_timeouts: u64,
    /// Agent-cycles that timed out (one cycle with two missing agents counts 2).
    pub agent_timeouts: u64,
    /// Cycles in which the host waited past `stop_timeout` for an agent whose
    /// `wait_for_stop` is `"alive"` (it was busy, not lost: nothing was dropped).
    pub slow_stops: u64,
    /// Batches dropped because they named an earlier cycle or followed the stop.
    pub late_batches: u64,
    /// Batches dropped because they named a cycle that had not started.
    pub future_batches: u64,
    /// Commands received and handed over.
    pub commands_received: u64,
    /// Commands dropped because an agent exceeded `max_commands_per_cycle`.
    pub commands_overflowed: u64,
    /// Frames that reached no agent (not connected, or async TCP with a full socket).
    pub frames_undelivered: u64,
    /// Frames delivered to an agent.
    pub frames_delivered: u64,
    /// Frames an agent acknowledged having read (see [`AgentReport::read_cycle`]).
    /// `frames_delivered - frames_read` frames were skipped by their agent (a newer one
    /// was read first) or are still being read.
    pub frames_read: u64,
    /// Action statuses dropped because an agent's table of unacknowledged events was full
    /// (it did not acknowledge frames for a while): superseded statuses first, so the
    /// newest status of every action is kept as long as there is room (see
    /// `MAX_STATUSES`).
    pub statuses_dropped: u64,
    /// Collisions dropped because an agent's table of unacknowledged collisions was full
    /// (the oldest goes; see `MAX_COLLISIONS`).
    pub collisions_dropped: u64,
    /// Agents evicted at least once (process died or disconnected), ascending.
    pub evicted_agents: Vec<u32>,
    /// Times an evicted agent, or one that left, came back.
    pub rejoins: u64,
    /// Graceful leaves: an agent's SDK said it leaves (`close()`, drop). Not evictions.
    pub leaves: u64,
    /// Evictions (an agent evicted twice counts 2).
    pub evictions: u64,
    /// Peers refused or dropped before they were admitted as agents (see
    /// [`Host::on_peer_refused`]).
    pub peers_refused: u64,
}

/// Why the host could not be created.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum HostCreateError {
    /// The shared-memory transport failed.
    #[error(transparent)]
    Shm(#[from] ShmHostCreateError),
    /// The TCP transport failed.
    #[error(transparent)]
    Tcp(#[from] TcpHostCreateError),
    /// The legacy transport (the original protocol) failed.
    #[error(transparent)]
    Legacy(#[from] crate::transport::legacy::LegacyHostCreateError),
    /// The zenoh transport failed.
    #[error(transparent)]
    Zenoh(#[from] crate::transport::zenoh::ZenohHostCreateError),
    /// The one wait over several transports could not be set up (an epoll set).
    #[error("cannot wait on several transports at once: epoll: {0}")]
    Wait(std::io::Error),
}

/// Why waiting for agents failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum HostWaitError {
    /// Some agents are not connected after the timeout: they never connected, or they
    /// connected and left again.
    #[error("{}", agents_missing_message(session, missing, left, *waited))]
    AgentsMissing {
        /// The session.
        session: String,
        /// Ids not connected, ascending (also those in `left`).
        missing: Vec<u32>,
        /// Those of `missing` that had connected during the wait and left again.
        left: Vec<u32>,
        /// How long we waited (this call).
        waited: Duration,
    },
    /// SIGINT/SIGTERM.
    #[error("termination requested while waiting for agents")]
    Terminated,
    /// Transport failure.
    #[error(transparent)]
    Transport(#[from] HostTransportError),
}

fn agents_missing_message(
    session: &str,
    missing: &[u32],
    left: &[u32],
    waited: Duration,
) -> String {
    let never: Vec<u32> = missing
        .iter()
        .copied()
        .filter(|id| !left.contains(id))
        .collect();
    let mut text = format!("session {session:?}: ");
    if !never.is_empty() {
        text += &format!(
            "agents {never:?} did not connect within {}",
            Rounded(waited)
        );
    }
    if !left.is_empty() {
        if !never.is_empty() {
            text += "; ";
        }
        text += &format!(
            "agents {left:?} connected and left again (their process ended or dropped the \
             connection)"
        );
    }
    text + ": start those agents with this session's config (same session, transport and \
            address), or raise sync.connect_timeout"
}

/// Why a cycle operation failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum HostCycleError {
    /// The agent id is not in the config.
    #[error("agent {0} is not part of this session")]
    UnknownAgent(u32),
    /// The frame was loaned in another cycle.
    #[error(
        "frame for agent {agent} was loaned in cycle {loaned}, but the host is in cycle {current}"
    )]
    StaleFrame {
        /// Agent id.
        agent: u32,
        /// The frame's cycle.
        loaned: u64,
        /// The host's cycle.
        current: u64,
    },
    /// SIGINT/SIGTERM.
    #[error("termination requested")]
    Terminated,
    /// An agent was lost and `on_agent_lost = "abort"`.
    #[error(
        "agent {agent} was lost in cycle {cycle} (its process died or disconnected); on_agent_lost = \"abort\""
    )]
    AgentLost {
        /// Agent id.
        agent: u32,
        /// Cycle.
        cycle: u64,
    },
    /// An agent was lost, `on_agent_lost = "wait"`, and it did not come back.
    #[error(
        "agent {agent} was lost and did not reconnect within {} (on_agent_lost = \"wait\")",
        Rounded(*.waited)
    )]
    AgentNotBack {
        /// Agent id.
        agent: u32,
        /// How long we waited.
        waited: Duration,
    },
    /// Transport failure.
    #[error(transparent)]
    Transport(HostTransportError),
}

impl From<HostTransportError> for HostCycleError {
    fn from(e: HostTransportError) -> Self {
        match e {
            HostTransportError::Terminated => Self::Terminated,
            other => Self::Transport(other),
        }
    }
}

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
        let backend = Transports::create(self.config, self.signals).map_err(|e| match e {
            TransportsCreateError::Shm(e) => HostCreateError::Shm(e),
            TransportsCreateError::Tcp(e) => HostCreateError::Tcp(e),
            TransportsCreateError::Legacy(e) => HostCreateError::Legacy(e),
            TransportsCreateError::Zenoh(e) => HostCreateError::Zenoh(e),
            TransportsCreateError::Wait(e) => HostCreateError::Wait(e),
        })?;
        Ok(Host::over(self.config, backend))
    }
}

impl<T: HostTransport> Host<T> {
    /// A host of `config` over `backend` (the builder's transports, or a test's fake).
    pub(crate) fn over(config: &Config, backend: T) -> Self {
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

/// How often the host looks for dead agent processes while it waits.
pub const REAP_PERIOD: Duration = Duration::from_millis(100);

/// The host side of a vrsync session, over the transports its agents use (`T` is only
/// replaced in the crate's own tests, by a fake transport).
pub struct Host<T: HostTransport = Transports> {
    config: Config,
    backend: T,
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

    /// Whether agent `id` is connected (its receiving side is attached).
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
    }

    /// The address TCP agents connect to (the bound port when `tcp_listen` has port 0);
    /// `None` on shared memory.
    pub fn tcp_local_addr(&self) -> Option<std::net::SocketAddr> {
        self.backend.local_addr()
    }

    /// Whether SIGINT/SIGTERM was received.
    pub fn termination_requested(&self) -> bool {
        self.backend.termination_requested()
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
            match self
                .backend
                .wait_activity((deadline - now).min(Duration::from_secs(1)))
            {
                Ok(()) => self.take_refusals(),
                Err(HostTransportError::Terminated) => return Err(HostWaitError::Terminated),
                Err(e) => return Err(e.into()),
            }
        }
    }

    /// Loans agent `id`'s sensor frame for the current cycle, header pre-filled (protocol
    /// version, agent id, cycle, simulated time, mode, image table, previous outcome).
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
        h.previous_outcome = s.last_outcome as u32;
        h.previous_rejected = s.last_rejected;
        // The simulator adds this cycle's events; publish adds the unacknowledged ones.
        h.status_count = 0;
        h.collision_count = 0;
        Ok(SensorFrameMut {
            slot,
            agent_id: id,
            cycle: self.cycle,
            loan,
            descs: s.descs,
            image_count: s.image_count,
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
        self.report.cycle = cycle;
        self.report.sim_time_ns = self.sim_time_ns();
        self.report.timed_out = false;
        self.report.late_batches = 0;
        for a in &mut self.report.agents {
            a.commands.clear();
            a.outcome = AgentOutcome::NotAwaited;
        }
        if self.config.sync.sync_mode {
            self.collect_sync()?;
        } else {
            self.collect_async()?;
        }
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

    fn drain(&mut self, sync: bool) -> Result<(), HostCycleError> {
        let barrier = &mut self.barrier;
        let report = &mut self.report;
        let stats = &mut self.stats;
        let slots = &mut self.slots;
        let leaving = &mut self.leaving;
        let cycle = self.cycle;
        self.backend.drain(&mut |slot, header, commands| {
            // Any batch may acknowledge a frame, a late one too; never one not yet sent.
            if let Some(read) = header.acknowledged().filter(|&c| c <= cycle)
                && let Some(s) = slots.get_mut(slot)
                && s.read_cycle.is_none_or(|r| read > r)
            {
                s.read_cycle = Some(read);
                s.events.acknowledge(read);
                stats.frames_read += 1;
            }
            if header.is_leave() {
                // Not part of any cycle: the agent is gone (see `check_lost`).
                if !leaving.contains(&slot) {
                    leaving.push(slot);
                }
                return;
            }
            let verdict = if sync {
                barrier.on_batch(slot, header.cycle, header.is_stop())
            } else {
                BatchVerdict::Accept { stop: false }
            };
            // Commands from this index on are dropped.
            let applied = match verdict {
                BatchVerdict::Accept { .. } => {
                    let Some(a) = report.agents.get_mut(slot) else {
                        return;
                    };
                    let room = a.commands.capacity() - a.commands.len();
                    let take = commands.len().min(room);
                    a.commands.extend_from_slice(&commands[..take]);
                    stats.commands_received += take as u64;
                    if take < commands.len() {
                        stats.commands_overflowed += (commands.len() - take) as u64;
                        warn!(
                            agent = a.agent_id,
                            dropped = commands.len() - take,
                            "too many commands in one cycle"
                        );
                    }
                    take
                }
                BatchVerdict::Late => {
                    report.late_batches += 1;
                    stats.late_batches += 1;
                    debug!(slot, batch_cycle = header.cycle, "late batch dropped");
                    0
                }
                BatchVerdict::Future => {
                    stats.future_batches += 1;
                    // A misbehaving agent must not flood the log: warn at the 1st, 2nd,
                    // 4th, 8th … such batch (the count is in the stats either way).
                    if stats.future_batches.is_power_of_two() {
                        warn!(
                            slot,
                            batch_cycle = header.cycle,
                            total = stats.future_batches,
                            "batch for a future cycle dropped"
                        );
                    }
                    0
                }
                BatchVerdict::NotAwaited => 0,
            };
            // A dropped command never runs: its agent learns so from an `Aborted` status in
            // its next frame (an agent that waits for its action's end must not wait in
            // vain, e.g. after its batch came late).
            if let Some(s) = slots.get_mut(slot) {
                for c in commands.get(applied..).unwrap_or(&[]) {
                    if s.events
                        .push_status(c.action_id, ActionState::Aborted as u32, cycle + 1)
                    {
                        stats.statuses_dropped += 1;
                    }
                }
            }
        })?;
        Ok(())
    }

    /// Lets agents that said they leave go (see [`AgentReport::left`]).
    fn handle_leaves(&mut self) {
        for i in 0..self.leaving.len() {
            let slot = self.leaving[i];
            let s = &self.slots[slot];
            let id = s.id;
            self.backend.forget_connection(slot);
            // An agent that never took part (or is out already) has nothing to leave.
            let pending = self.barrier.leave(slot);
            if !pending && (!s.seen || s.evicted) {
                continue;
            }
            info!(agent = id, cycle = self.cycle, "agent left the session");
            let s = &mut self.slots[slot];
            s.evicted = true;
            s.left = true;
            s.left_in = Some(self.cycle);
            s.seen = false;
            // A new connection starts afresh, as after an eviction.
            s.events.clear();
            s.read_cycle = None;
            self.stats.leaves += 1;
        }
        self.leaving.clear();
    }

    /// Evicts awaited agents that disconnected or whose process died; lets those that said
    /// they leave go.
    fn check_lost(&mut self, sync: bool, reap: bool) -> Result<(), HostCycleError> {
        self.take_refusals();
        self.handle_leaves();
        self.dead.clear();
        if reap {
            self.backend.reap_dead_agents(&mut self.dead);
        }
        // Awaited agents that disconnected, and agents that left between cycles.
        let mut disconnected = false;
        for slot in 0..self.slots.len() {
            let pending = self.barrier.outcome(slot) == AgentOutcome::TimedOut;
            let known = pending || (self.slots[slot].seen && !self.slots[slot].evicted);
            if known && !self.backend.is_connected(slot) && !self.dead.contains(&slot) {
                self.dead.push(slot);
                disconnected = true;
            }
        }
        if disconnected {
            // An agent that leaves sends its leave batch, then closes: the batch may have
            // come in since the last drain. A leave is not a loss (a slot that left is out
            // already, so the loop below passes it by).
            self.drain(sync)?;
            self.handle_leaves();
        }
        for i in 0..self.dead.len() {
            let slot = self.dead[i];
            let pending = self.barrier.evict(slot);
            if pending || !self.slots[slot].evicted {
                let id = self.slots[slot].id;
                self.backend.forget_connection(slot);
                warn!(
                    agent = id,
                    cycle = self.cycle,
                    "agent lost (process died or disconnected): evicted"
                );
                self.slots[slot].evicted = true;
                self.slots[slot].evicted_in = Some(self.cycle);
                self.stats.evictions += 1;
                self.slots[slot].seen = false;
                // A process that rejoins starts afresh: its events were for the old one.
                self.slots[slot].events.clear();
                self.slots[slot].read_cycle = None;
                if let Some(hook) = &mut self.evicted_hook {
                    hook(id, self.cycle);
                }
                self.lost_this_cycle.push(slot);
                if let Err(pos) = self.stats.evicted_agents.binary_search(&id) {
                    self.stats.evicted_agents.insert(pos, id);
                }
            }
        }
        Ok(())
    }

    /// Drains batches and watches for lost agents until `until` — in sync mode only until
    /// every awaited agent stopped; there `until` is the stop timeout, after which agents
    /// with `wait_for_stop = "timeout"` are given up and the others waited for as long as
    /// they are connected (reported as slow) — then applies `on_agent_lost`.
    fn wait_cycle(&mut self, sync: bool, until: Instant) -> Result<(), HostCycleError> {
        let started = Instant::now();
        let timeout = until.saturating_duration_since(started);
        let mut next_reap = started + REAP_PERIOD;
        // Past the stop timeout (sync mode): when the next slow report is due.
        let mut past_timeout = false;
        let mut next_report = until;
        let mut reports = 0u32;
        self.lost_this_cycle.clear();
        loop {
            self.drain(sync)?;
            let now = Instant::now();
            let reap = now >= next_reap;
            if reap {
                next_reap = now + REAP_PERIOD;
            }
            self.check_lost(sync, reap)?;
            if sync && self.barrier.is_complete() {
                break;
            }
            let mut wake = until;
            if now >= until {
                if !sync {
                    break;
                }
                if !past_timeout {
                    past_timeout = true;
                    for slot in 0..self.slots.len() {
                        if self.slots[slot].wait_for_stop == WaitForStop::Timeout {
                            self.barrier.give_up(slot);
                        }
                    }
                    if self.barrier.is_complete() {
                        break;
                    }
                }
                if now >= next_report {
                    self.report_slow(now.saturating_duration_since(started));
                    reports = reports.saturating_add(1);
                    // 1×, 2×, 4×, … the stop timeout into the cycle.
                    next_report = started + timeout.saturating_mul(1u32 << reports.min(20));
                }
                wake = next_report;
            }
            self.backend
                .wait_activity(wake.min(next_reap).saturating_duration_since(now))?;
        }
        self.handle_lost()
    }

    /// Reports every agent still awaited past the stop timeout (all have `wait_for_stop =
    /// "alive"` and are connected: the lost ones were evicted) as slow.
    fn report_slow(&mut self, waited: Duration) {
        if (0..self.slots.len()).all(|slot| !self.barrier.is_slow(slot)) {
            self.stats.slow_stops += 1;
        }
        for slot in 0..self.slots.len() {
            if !self.barrier.is_pending(slot) {
                continue;
            }
            self.barrier.mark_slow(slot);
            let agent = self.slots[slot].id;
            warn!(
                agent,
                cycle = self.cycle,
                waited_s = waited.as_secs_f64(),
                "agent is slow: still waiting for its stop past stop_timeout (it is alive; \
                 wait_for_stop = \"alive\")"
            );
            if let Some(hook) = &mut self.slow_hook {
                hook(agent, self.cycle, waited);
            }
        }
    }

    fn collect_sync(&mut self) -> Result<(), HostCycleError> {
        self.wait_cycle(true, Instant::now() + self.config.sync.stop_timeout)?;
        let mut timed_out = 0u64;
        for (slot, a) in self.report.agents.iter_mut().enumerate() {
            a.outcome = self.barrier.outcome(slot);
            self.slots[slot].last_outcome = match a.outcome {
                AgentOutcome::Stopped => WireOutcome::Stopped,
                AgentOutcome::TimedOut => WireOutcome::TimedOut,
                _ => WireOutcome::None,
            };
            if a.outcome == AgentOutcome::TimedOut {
                timed_out += 1;
            }
        }
        if timed_out > 0 {
            self.report.timed_out = true;
            self.stats.stop_timeouts += 1;
            self.stats.agent_timeouts += timed_out;
            let missing: Vec<u32> = self.report.timed_out_agents().collect();
            warn!(
                cycle = self.cycle,
                ?missing,
                timeout_s = self.config.sync.stop_timeout.as_secs_f64(),
                "stop timeout: cycle ends without these agents"
            );
        }
        Ok(())
    }

    /// Applies `on_agent_lost` to the agents lost this cycle.
    fn handle_lost(&mut self) -> Result<(), HostCycleError> {
        let Some(&slot) = self.lost_this_cycle.first() else {
            return Ok(());
        };
        let agent = self.slots[slot].id;
        match self.config.sync.on_agent_lost {
            AgentLostPolicy::Evict => Ok(()),
            AgentLostPolicy::Abort => Err(HostCycleError::AgentLost {
                agent,
                cycle: self.cycle,
            }),
            AgentLostPolicy::Wait => {
                let timeout = self.config.sync.connect_timeout;
                let started = Instant::now();
                for i in 0..self.lost_this_cycle.len() {
                    let slot = self.lost_this_cycle[i];
                    let agent = self.slots[slot].id;
                    warn!(
                        agent,
                        "pausing until the agent reconnects (on_agent_lost = \"wait\")"
                    );
                    while !self.backend.is_connected(slot) {
                        let left = timeout.saturating_sub(started.elapsed());
                        if left.is_zero() {
                            return Err(HostCycleError::AgentNotBack {
                                agent,
                                waited: started.elapsed(),
                            });
                        }
                        self.backend
                            .wait_activity(left.min(Duration::from_secs(1)))?;
                    }
                }
                self.backend.update_connections()?;
                Ok(())
            }
        }
    }

    fn collect_async(&mut self) -> Result<(), HostCycleError> {
        let period = self.config.sync.simulation_time_per_frame;
        let now = Instant::now();
        let tick = match self.next_tick {
            // Keep a fixed rate; if we fell behind by more than a period, resynchronise
            // instead of bursting to catch up.
            Some(t) if t + period > now => t,
            _ => now + period,
        };
        self.wait_cycle(false, tick)?;
        self.next_tick = Some(tick + period);
        for a in &mut self.report.agents {
            a.outcome = AgentOutcome::Async;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    //! The host's logic over a fake transport: no processes, no shared memory, no sockets.
    //! The fake's "agents" answer at the host's waits, as real ones would while it blocks.

    use std::cell::RefCell;
    use std::path::Path;
    use std::rc::Rc;

    use super::*;
    use crate::transport::BatchSink;
    use crate::wire::{ActionState, Command, MOTOR_FLAG_ACK, MOTOR_FLAG_STOP, MotorHeader};

    /// What the fake's agents do; shared between the test and the host's transport.
    #[derive(Default)]
    struct Agents {
        connected: Vec<bool>,
        /// Slots whose process "died" (reported by `reap_dead_agents`).
        dead: Vec<usize>,
        /// Whether a slot answers each frame it gets with one command and a stop.
        answers: Vec<bool>,
        /// Slots that reconnect at the next wait.
        reconnect: Vec<usize>,
        /// Slots that answer only from this instant on (a busy agent), if any.
        busy_until: Vec<Option<Instant>>,
        /// Frames delivered and not answered yet: (slot, cycle).
        delivered: Vec<(usize, u64)>,
        /// Batches waiting for the host's next drain.
        inbox: Vec<(usize, MotorHeader, Vec<MotorCommand>)>,
        /// Every header published: (slot, header).
        published: Vec<(usize, SensorHeader)>,
    }

    impl Agents {
        fn batch(&mut self, slot: usize, cycle: u64, stop: bool, commands: Vec<MotorCommand>) {
            let header = MotorHeader {
                protocol_version: PROTOCOL_VERSION,
                agent_id: 0,
                cycle,
                flags: if stop { MOTOR_FLAG_STOP } else { 0 },
                command_count: commands.len() as u32,
                ack_cycle: 0,
            };
            self.inbox.push((slot, header, commands));
        }
    }

    #[derive(Debug)]
    struct FakeLoan {
        header: SensorHeader,
        payload: Vec<u8>,
    }

    impl FrameLoanMut for FakeLoan {
        fn parts_mut(&mut self) -> (&mut SensorHeader, &mut [u8]) {
            (&mut self.header, &mut self.payload)
        }
        fn header(&self) -> &SensorHeader {
            &self.header
        }
    }

    struct Fake(Rc<RefCell<Agents>>);

    impl HostTransport for Fake {
        type Loan = FakeLoan;

        fn is_connected(&self, slot: usize) -> bool {
            self.0
                .borrow()
                .connected
                .get(slot)
                .copied()
                .unwrap_or(false)
        }
        fn loan(&mut self, _slot: usize) -> Result<FakeLoan, HostTransportError> {
            Ok(FakeLoan {
                header: SensorHeader::default(),
                payload: vec![0; 64],
            })
        }
        fn publish(&mut self, slot: usize, frame: FakeLoan) -> Result<bool, HostTransportError> {
            let mut a = self.0.borrow_mut();
            if !a.connected[slot] {
                return Ok(false);
            }
            a.delivered.push((slot, frame.header.cycle));
            a.published.push((slot, frame.header));
            Ok(true)
        }
        fn signal_start(&mut self) -> Result<(), HostTransportError> {
            Ok(())
        }
        fn drain(&mut self, sink: &mut BatchSink<'_>) -> Result<(), HostTransportError> {
            let inbox = std::mem::take(&mut self.0.borrow_mut().inbox);
            for (slot, header, commands) in &inbox {
                sink(*slot, header, commands);
            }
            Ok(())
        }
        fn activity_fd(&self) -> std::os::fd::RawFd {
            // Never polled: the fake's wait is its own (below).
            -1
        }

        fn wait_activity(&mut self, timeout: Duration) -> Result<(), HostTransportError> {
            let mut a = self.0.borrow_mut();
            for slot in std::mem::take(&mut a.reconnect) {
                a.connected[slot] = true;
            }
            let delivered = std::mem::take(&mut a.delivered);
            for (slot, cycle) in delivered {
                let busy = a
                    .busy_until
                    .get(slot)
                    .copied()
                    .flatten()
                    .is_some_and(|t| Instant::now() < t);
                if busy {
                    a.delivered.push((slot, cycle));
                    continue;
                }
                if a.answers[slot] && a.connected[slot] {
                    let command = Command::Turn { angle_deg: 1.0 }.encode(cycle as u32);
                    a.batch(slot, cycle, true, vec![command]);
                    // An answer acknowledges the frame it answers, as the SDK's stop does.
                    if let Some((_, header, _)) = a.inbox.last_mut() {
                        header.flags |= MOTOR_FLAG_ACK;
                        header.ack_cycle = cycle;
                    }
                }
            }
            if a.inbox.is_empty() {
                // Nothing will answer: let the time the host waits for pass (briefly).
                drop(a);
                std::thread::sleep(timeout.min(Duration::from_millis(2)));
            }
            Ok(())
        }
        fn update_connections(&mut self) -> Result<(), HostTransportError> {
            Ok(())
        }
        fn termination_requested(&self) -> bool {
            false
        }
        fn reap_dead_agents(&mut self, dead: &mut Vec<usize>) {
            dead.extend(std::mem::take(&mut self.0.borrow_mut().dead));
        }
    }

    /// A host of agents 3 and 7 (ids are not slots) over the fake, both connected and
    /// answering, with `wait_for_stop = "timeout"` (the original semantics).
    fn host(policy: &str) -> (Host<Fake>, Rc<RefCell<Agents>>) {
        host_waiting(policy, "timeout", 0.2)
    }

    /// [`host`] with `wait_for_stop = wait` and `stop_timeout = stop_timeout_s`.
    fn host_waiting(
        policy: &str,
        wait: &str,
        stop_timeout_s: f64,
    ) -> (Host<Fake>, Rc<RefCell<Agents>>) {
        let text = format!(
            "session = \"fake\"\n[sync]\nstop_timeout = {stop_timeout_s}\nconnect_timeout = 0.2\n\
             on_agent_lost = {policy:?}\nwait_for_stop = {wait:?}\n[[agent]]\nid = 3\n\
             [[agent]]\nid = 7\n"
        );
        let config = Config::from_toml_str(&text, Path::new("fake.toml")).unwrap();
        let agents = Rc::new(RefCell::new(Agents {
            connected: vec![true, true],
            answers: vec![true, true],
            ..Agents::default()
        }));
        let mut host = Host::over(&config, Fake(agents.clone()));
        host.wait_for_agents(Duration::from_secs(1)).unwrap();
        (host, agents)
    }

    fn publish_all(host: &mut Host<Fake>) {
        for id in [3, 7] {
            let frame = host.loan_frame(id).unwrap();
            assert_eq!(frame.header().cycle, host.cycle());
            assert_eq!(frame.header().agent_id, id);
            host.publish(frame).unwrap();
        }
        host.start().unwrap();
    }

    fn outcomes(report: &CycleReport) -> Vec<(u32, AgentOutcome)> {
        report
            .agents()
            .iter()
            .map(|a| (a.agent_id, a.outcome))
            .collect()
    }

    #[test]
    fn a_cycle_ends_when_every_awaited_agent_stopped_with_its_commands() {
        let (mut host, _agents) = host("evict");
        publish_all(&mut host);
        let report = host.collect().unwrap();
        assert_eq!(report.cycle, 0);
        assert!(!report.timed_out);
        assert_eq!(
            outcomes(report),
            [(3, AgentOutcome::Stopped), (7, AgentOutcome::Stopped)]
        );
        assert!(report.agents().iter().all(|a| a.commands().len() == 1));
        assert_eq!(host.cycle(), 1);
    }

    #[test]
    fn a_late_stop_never_completes_the_next_cycle_and_the_timeout_names_the_agent() {
        let (mut host, agents) = host("evict");
        publish_all(&mut host);
        host.collect().unwrap();
        // Cycle 1: agent 3 is silent; its stop for cycle 0 arrives again (late), and
        // agent 7 sends a batch for cycle 5 (future) besides its stop.
        {
            let mut a = agents.borrow_mut();
            a.answers[0] = false;
            a.batch(0, 0, true, Vec::new());
            a.batch(1, 5, true, Vec::new());
        }
        publish_all(&mut host);
        let report = host.collect().unwrap();
        assert_eq!(report.cycle, 1);
        assert!(report.timed_out);
        assert_eq!(report.timed_out_agents().collect::<Vec<_>>(), [3]);
        assert_eq!(
            outcomes(report),
            [(3, AgentOutcome::TimedOut), (7, AgentOutcome::Stopped)]
        );
        assert_eq!(report.late_batches, 1);
        let stats = host.stats();
        assert_eq!((stats.late_batches, stats.future_batches), (1, 1));
        assert_eq!((stats.stop_timeouts, stats.agent_timeouts), (1, 1));
    }

    /// The slow reports a test's `on_slow` hook recorded: (agent, cycle, waited).
    type SlowReports = Rc<RefCell<Vec<(u32, u64, Duration)>>>;

    /// A host with `wait_for_stop = "alive"` (stop_timeout 50 ms) whose agent 3 is busy
    /// for `busy`, recording the slow reports.
    fn busy_agent_3(busy: Duration) -> (Host<Fake>, Rc<RefCell<Agents>>, SlowReports) {
        let (mut host, agents) = host_waiting("evict", "alive", 0.05);
        let slow = Rc::new(RefCell::new(Vec::new()));
        let seen = slow.clone();
        host.on_slow(move |agent, cycle, waited| seen.borrow_mut().push((agent, cycle, waited)));
        publish_all(&mut host);
        host.collect().unwrap();
        agents.borrow_mut().busy_until = vec![Some(Instant::now() + busy), None];
        (host, agents, slow)
    }

    #[test]
    fn a_live_busy_agent_is_waited_for_and_reported_slow_not_timed_out() {
        let (mut host, _agents, slow) = busy_agent_3(Duration::from_millis(260));
        publish_all(&mut host);
        let report = host.collect().unwrap();
        assert!(!report.timed_out);
        assert_eq!(
            outcomes(report),
            [(3, AgentOutcome::Stopped), (7, AgentOutcome::Stopped)]
        );
        assert!(report.agents().iter().all(|a| a.commands().len() == 1));
        assert_eq!(report.slow_agents().collect::<Vec<_>>(), [3]);
        assert!(report.agent(3).unwrap().slow && !report.agent(7).unwrap().slow);
        // Reported at 1×, 2× and 4× the stop timeout (0.05, 0.1, 0.2 s) as it waited.
        let slow = slow.borrow();
        assert!(slow.len() >= 3, "{slow:?}");
        assert!(
            slow.iter()
                .all(|&(agent, cycle, _)| (agent, cycle) == (3, 1))
        );
        assert!(slow[0].2 >= Duration::from_millis(50), "{slow:?}");
        assert!(slow[2].2 >= Duration::from_millis(200), "{slow:?}");
        let stats = host.stats();
        assert_eq!((stats.stop_timeouts, stats.agent_timeouts), (0, 0));
        assert_eq!((stats.slow_stops, stats.late_batches), (1, 0));
        // The next cycle is an ordinary one again.
        publish_all(&mut host);
        let report = host.collect().unwrap();
        assert_eq!(report.slow_agents().count(), 0);
        assert_eq!(host.stats().slow_stops, 1);
    }

    #[test]
    fn a_busy_agent_that_dies_is_evicted_and_the_others_go_on() {
        let (mut host, agents, slow) = busy_agent_3(Duration::from_secs(3600));
        publish_all(&mut host);
        // The fake's agent 3 dies after the host reported it slow once.
        let dying = agents.clone();
        let seen = slow.clone();
        host.on_slow(move |agent, cycle, waited| {
            seen.borrow_mut().push((agent, cycle, waited));
            dying.borrow_mut().dead.push(0);
        });
        let report = host.collect().unwrap();
        assert_eq!(
            outcomes(report),
            [(3, AgentOutcome::Evicted), (7, AgentOutcome::Stopped)]
        );
        assert!(!report.timed_out);
        // Evicted at the next reap (100 ms), not waited for on.
        assert!(slow.borrow().len() <= 2, "{:?}", slow.borrow());
        assert_eq!(host.stats().evicted_agents, [3]);
        assert_eq!(host.stats().stop_timeouts, 0);
    }

    #[test]
    fn per_agent_policies_a_timeout_agent_times_out_while_the_cycle_waits_for_a_live_one() {
        let text = "session = \"fake\"\n[sync]\nstop_timeout = 0.05\nconnect_timeout = 0.2\n\
                    [[agent]]\nid = 3\nwait_for_stop = \"timeout\"\n[[agent]]\nid = 7\n";
        let config = Config::from_toml_str(text, Path::new("fake.toml")).unwrap();
        let agents = Rc::new(RefCell::new(Agents {
            connected: vec![true, true],
            answers: vec![false, true],
            busy_until: vec![None, Some(Instant::now() + Duration::from_millis(200))],
            ..Agents::default()
        }));
        let mut host = Host::over(&config, Fake(agents.clone()));
        host.wait_for_agents(Duration::from_secs(1)).unwrap();
        publish_all(&mut host);
        // Agent 3's stop comes after its timeout, while the cycle still waits for 7.
        agents.borrow_mut().busy_until[0] = Some(Instant::now() + Duration::from_millis(100));
        agents.borrow_mut().answers[0] = true;
        let report = host.collect().unwrap();
        assert_eq!(
            outcomes(report),
            [(3, AgentOutcome::TimedOut), (7, AgentOutcome::Stopped)]
        );
        assert!(report.timed_out);
        assert_eq!(report.slow_agents().collect::<Vec<_>>(), [7]);
        assert!(report.agent(3).unwrap().commands().is_empty());
        assert_eq!(report.late_batches, 1, "its stop came after its timeout");
        let stats = host.stats();
        assert_eq!((stats.stop_timeouts, stats.agent_timeouts), (1, 1));
        assert_eq!(stats.slow_stops, 1);
    }

    #[test]
    fn a_leaving_agent_is_not_waited_for_counts_a_leave_and_its_id_takes_part_again() {
        let (mut host, agents) = host_waiting("abort", "alive", 0.05);
        publish_all(&mut host);
        host.collect().unwrap();
        // Cycle 1: agent 7 reads its frame and leaves without a stop.
        {
            let mut a = agents.borrow_mut();
            a.answers[1] = false;
            a.inbox.push((
                1,
                MotorHeader {
                    protocol_version: PROTOCOL_VERSION,
                    agent_id: 7,
                    cycle: 1,
                    flags: crate::wire::MOTOR_FLAG_LEAVE,
                    command_count: 0,
                    ack_cycle: 0,
                },
                Vec::new(),
            ));
        }
        publish_all(&mut host);
        let report = host.collect().unwrap();
        assert_eq!(
            outcomes(report),
            [(3, AgentOutcome::Stopped), (7, AgentOutcome::Left)]
        );
        assert_eq!(report.left_agents().collect::<Vec<_>>(), [7]);
        assert_eq!(report.evicted_agents().count(), 0);
        assert!(!report.timed_out && report.slow_agents().count() == 0);
        assert!(host.has_left(7) && !host.is_evicted(7));
        // Not lost: on_agent_lost = "abort" does not apply. Cycle 2: a new connection
        // of id 7 answers again.
        {
            let mut a = agents.borrow_mut();
            a.answers[1] = true;
            // The new connection never saw cycle 1's frame.
            a.delivered.retain(|&(slot, _)| slot != 1);
        }
        publish_all(&mut host);
        let report = host.collect().unwrap();
        assert_eq!(
            outcomes(report),
            [(3, AgentOutcome::Stopped), (7, AgentOutcome::Stopped)]
        );
        assert_eq!(report.rejoined_agents().collect::<Vec<_>>(), [7]);
        assert!(!host.has_left(7));
        let stats = host.stats();
        assert_eq!((stats.leaves, stats.rejoins, stats.evictions), (1, 1, 0));
        assert!(stats.evicted_agents.is_empty());
        assert_eq!((stats.stop_timeouts, stats.late_batches), (0, 0));
    }

    #[test]
    fn a_disconnected_agent_is_evicted_then_rejoins() {
        let (mut host, agents) = host("evict");
        let evicted = Rc::new(RefCell::new(Vec::new()));
        let seen = evicted.clone();
        host.on_evicted(move |id, cycle| seen.borrow_mut().push((id, cycle)));
        publish_all(&mut host);
        host.collect().unwrap();
        // Cycle 1: agent 7's frame reaches it, then it disconnects without a stop.
        agents.borrow_mut().answers[1] = false;
        publish_all(&mut host);
        agents.borrow_mut().connected[1] = false;
        let report = host.collect().unwrap();
        assert!(!report.timed_out, "a lost agent is evicted, not waited for");
        assert_eq!(
            outcomes(report),
            [(3, AgentOutcome::Stopped), (7, AgentOutcome::Evicted)]
        );
        assert_eq!(report.evicted_agents().collect::<Vec<_>>(), [7]);
        assert!(report.agent(7).unwrap().evicted && !report.agent(3).unwrap().evicted);
        assert_eq!(*evicted.borrow(), [(7, 1)]);
        assert!(host.is_evicted(7));
        // Cycle 2: its frame is not delivered; cycle 3: it is back.
        publish_all(&mut host);
        let report = host.collect().unwrap();
        assert_eq!(
            outcomes(report),
            [(3, AgentOutcome::Stopped), (7, AgentOutcome::NotAwaited)]
        );
        assert_eq!(report.evicted_agents().count(), 0);
        assert_eq!(report.rejoined_agents().count(), 0);
        {
            let mut a = agents.borrow_mut();
            a.connected[1] = true;
            a.answers[1] = true;
        }
        publish_all(&mut host);
        let report = host.collect().unwrap();
        assert_eq!(
            outcomes(report),
            [(3, AgentOutcome::Stopped), (7, AgentOutcome::Stopped)]
        );
        assert_eq!(report.rejoined_agents().collect::<Vec<_>>(), [7]);
        assert!(report.agent(7).unwrap().rejoined);
        assert!(report.agent(5).is_none());
        assert!(!host.is_evicted(7));
        let stats = host.stats();
        assert_eq!(stats.evicted_agents, [7]);
        assert_eq!((stats.evictions, stats.rejoins), (1, 1));
        assert_eq!(stats.frames_undelivered, 1);
    }

    #[test]
    fn a_dead_agent_process_is_evicted() {
        let (mut host, agents) = host("evict");
        agents.borrow_mut().answers[0] = false;
        publish_all(&mut host);
        agents.borrow_mut().dead.push(0);
        let report = host.collect().unwrap();
        assert_eq!(
            outcomes(report),
            [(3, AgentOutcome::Evicted), (7, AgentOutcome::Stopped)]
        );
        assert_eq!(host.stats().evicted_agents, [3]);
    }

    fn lose_agent_7(host: &mut Host<Fake>, agents: &Rc<RefCell<Agents>>) {
        agents.borrow_mut().answers[1] = false;
        publish_all(host);
        agents.borrow_mut().connected[1] = false;
    }

    #[test]
    fn on_agent_lost_abort_names_the_agent_and_cycle() {
        let (mut host, agents) = host("abort");
        lose_agent_7(&mut host, &agents);
        let err = host.collect().unwrap_err();
        assert!(
            matches!(err, HostCycleError::AgentLost { agent: 7, cycle: 0 }),
            "{err:?}"
        );
    }

    #[test]
    fn on_agent_lost_wait_pauses_until_the_agent_is_back() {
        let (mut host, agents) = host("wait");
        lose_agent_7(&mut host, &agents);
        agents.borrow_mut().reconnect.push(1);
        let report = host.collect().unwrap();
        assert_eq!(
            outcomes(report),
            [(3, AgentOutcome::Stopped), (7, AgentOutcome::Evicted)]
        );
        assert!(host.is_connected(7));
    }

    #[test]
    fn on_agent_lost_wait_gives_up_after_the_connect_timeout() {
        let (mut host, agents) = host("wait");
        lose_agent_7(&mut host, &agents);
        let err = host.collect().unwrap_err();
        assert!(
            matches!(err, HostCycleError::AgentNotBack { agent: 7, .. }),
            "{err:?}"
        );
    }

    /// Publishes agent 3's and 7's frames, agent 3's with `statuses` as the simulator's
    /// new events, and collects; returns the (action id, state, seq) agent 3 got.
    fn cycle_with_statuses(
        host: &mut Host<Fake>,
        agents: &Rc<RefCell<Agents>>,
        statuses: &[(u32, ActionState)],
    ) -> Vec<(u32, u32, u64)> {
        for id in [3, 7] {
            let mut frame = host.loan_frame(id).unwrap();
            assert_eq!(
                frame.header().status_count,
                0,
                "a loaned frame starts empty"
            );
            if id == 3 {
                for &(action, state) in statuses {
                    frame.header_mut().push_status(action, state);
                }
            }
            host.publish(frame).unwrap();
        }
        host.start().unwrap();
        let got = {
            let a = agents.borrow();
            let (_, h) = a
                .published
                .iter()
                .rev()
                .find(|(slot, _)| *slot == 0)
                .unwrap();
            h.statuses()
                .iter()
                .map(|s| (s.action_id, s.state, s.seq))
                .collect()
        };
        host.collect().unwrap();
        got
    }

    #[test]
    fn events_repeat_until_a_batch_acknowledges_a_frame_that_carried_them() {
        let (mut host, agents) = host("evict");
        let (fin, walk) = (ActionState::Finished as u32, ActionState::Walking as u32);
        // Agent 3 answers: each frame's events are acknowledged by its stop.
        assert_eq!(
            cycle_with_statuses(&mut host, &agents, &[(1, ActionState::Finished)]),
            [(1, fin, 1)]
        );
        assert_eq!(host.report.agent(3).unwrap().read_cycle, Some(0));
        assert!(cycle_with_statuses(&mut host, &agents, &[]).is_empty());
        // Agent 3 stalls for two cycles: its events pile up and repeat.
        agents.borrow_mut().answers[0] = false;
        let two = [(2, ActionState::Walking)];
        assert_eq!(
            cycle_with_statuses(&mut host, &agents, &two),
            [(2, walk, 2)]
        );
        let three = [(2, ActionState::Finished)];
        assert_eq!(
            cycle_with_statuses(&mut host, &agents, &three),
            [(2, walk, 2), (2, fin, 3)]
        );
        // It is back: the frame it reads still carries both, then they are gone.
        agents.borrow_mut().answers[0] = true;
        assert_eq!(
            cycle_with_statuses(&mut host, &agents, &[]),
            [(2, walk, 2), (2, fin, 3)]
        );
        assert_eq!(host.report.agent(3).unwrap().read_cycle, Some(4));
        assert!(cycle_with_statuses(&mut host, &agents, &[]).is_empty());
        let stats = host.stats();
        assert_eq!(stats.frames_delivered, 12);
        // Agent 3 read 4 of its 6 frames (and skipped 2); agent 7 all 6.
        assert_eq!(stats.frames_read, 10);
        assert_eq!(stats.statuses_dropped, 0);
    }

    #[test]
    fn the_commands_of_a_dropped_batch_are_reported_aborted() {
        let (mut host, agents) = host("evict");
        agents.borrow_mut().answers[0] = false;
        cycle_with_statuses(&mut host, &agents, &[]);
        // Agent 3's batch for cycle 0 arrives in cycle 1: late, its command never runs.
        agents
            .borrow_mut()
            .batch(0, 0, true, vec![Command::CancelMove.encode(42)]);
        cycle_with_statuses(&mut host, &agents, &[]);
        let abort = ActionState::Aborted as u32;
        assert_eq!(
            cycle_with_statuses(&mut host, &agents, &[]),
            [(42, abort, 1)]
        );
        assert_eq!(host.stats().late_batches, 1);
    }

    #[test]
    fn an_evicted_agent_does_not_inherit_its_old_events() {
        let (mut host, agents) = host("evict");
        agents.borrow_mut().answers[0] = false;
        cycle_with_statuses(&mut host, &agents, &[(1, ActionState::Finished)]);
        // Gone during cycle 1, back for cycle 2: a new process starts afresh.
        agents.borrow_mut().connected[0] = false;
        cycle_with_statuses(&mut host, &agents, &[]);
        assert!(host.is_evicted(3));
        {
            let mut a = agents.borrow_mut();
            a.connected[0] = true;
            a.answers[0] = true;
        }
        let fin = ActionState::Finished as u32;
        assert_eq!(
            cycle_with_statuses(&mut host, &agents, &[(9, ActionState::Finished)]),
            [(9, fin, 2)]
        );
    }

    #[test]
    fn waiting_for_agents_names_the_missing_ones_and_the_session() {
        let text = "session = \"fake\"\n[[agent]]\nid = 3\n[[agent]]\nid = 7\n";
        let config = Config::from_toml_str(text, Path::new("fake.toml")).unwrap();
        let agents = Rc::new(RefCell::new(Agents {
            connected: vec![true, false],
            answers: vec![true, true],
            ..Agents::default()
        }));
        let mut host = Host::over(&config, Fake(agents));
        let err = host.wait_for_agents(Duration::from_millis(20)).unwrap_err();
        match &err {
            HostWaitError::AgentsMissing {
                session, missing, ..
            } => {
                assert_eq!(session, "fake");
                assert_eq!(missing, &[7]);
            }
            other => panic!("{other:?}"),
        }
        assert!(!err.to_string().contains("vr-agent"), "{err}");
    }

    #[test]
    fn an_agent_that_connected_and_left_is_named_as_such() {
        let text = "session = \"fake\"\n[[agent]]\nid = 3\n[[agent]]\nid = 7\n";
        let config = Config::from_toml_str(text, Path::new("fake.toml")).unwrap();
        let agents = Rc::new(RefCell::new(Agents {
            connected: vec![false, true],
            answers: vec![true, true],
            ..Agents::default()
        }));
        let mut host = Host::over(&config, Fake(agents.clone()));
        assert!(host.wait_for_agents(Duration::from_millis(5)).is_err());
        agents.borrow_mut().connected[1] = false;
        let err = host.wait_for_agents(Duration::from_millis(5)).unwrap_err();
        let HostWaitError::AgentsMissing { missing, left, .. } = &err else {
            panic!("{err:?}");
        };
        assert_eq!(
            (missing.as_slice(), left.as_slice()),
            (&[3, 7][..], &[7][..])
        );
        let message = err.to_string();
        assert!(
            message.contains("agents [3] did not connect within ")
                && message.contains("agents [7] connected and left again"),
            "{message}"
        );
    }
}
