//! Transports: how sensor frames, motor batches, *start* and *stop* move between the host
//! and its agents.
//!
//! # The contract every transport keeps
//!
//! Host side: [`HostTransport`]; agent side: [`AgentTransport`]. Each trait's documentation
//! is its half of the contract (what every implementation guarantees, what callers may rely
//! on); the conformance suite (`agent-sdk/tests/conformance.rs`) checks it for every
//! transport, and a fake transport in `host.rs`'s tests drives the host's logic over it.
//!
//! What is written once, over the contract, for every transport: [`wait_for_newer_frame`]
//! (the newest frame newer than cycle *f* until a deadline, the host's liveness every
//! [`HOST_LIVENESS_PERIOD`]), and [`retry_until`] (connect-retry with back-off while the
//! host is not there yet).

use std::time::{Duration, Instant};

use tracing::debug;
use vrsync_protocol::channel_layout::{ChannelDifference, ChannelLayout};

use crate::refusal::PeerRefusal;
use crate::wait;
use crate::wire::{MotorCommand, MotorHeader, SensorHeader};
use vrsync_protocol::record;

/// Writable memory for one sensor frame, loaned from a transport
/// ([`HostTransport::Loan`]).
pub trait FrameLoanMut {
    /// The header and the image bytes, both writable.
    fn parts_mut(&mut self) -> (&mut SensorHeader, &mut [u8]);
    /// The header.
    fn header(&self) -> &SensorHeader;
}

/// Errors of the host side of a transport.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum HostTransportError {
    /// The sensor sample could not be loaned.
    #[error("cannot loan the sensor frame of agent {agent}: {reason}")]
    Loan {
        /// Agent id.
        agent: u32,
        /// Transport detail.
        reason: String,
    },
    /// Sending data or a signal failed.
    #[error("cannot send {what}: {reason}")]
    Send {
        /// What was being sent.
        what: String,
        /// Transport detail.
        reason: String,
    },
    /// Receiving failed.
    #[error("cannot receive from agent {agent}: {reason}")]
    Receive {
        /// Agent id.
        agent: u32,
        /// Transport detail.
        reason: String,
    },
    /// The host asked for a slot the transport does not have (a bug in the caller).
    #[error("the transport has no agent slot {slot}")]
    NoSuchSlot {
        /// The slot asked for.
        slot: usize,
    },
    /// Waiting for agents' batches failed.
    #[error("cannot wait for the agents' batches: {reason}")]
    Wait {
        /// Transport detail.
        reason: String,
    },
    /// Connecting the host's ports to an agent's failed.
    #[error("cannot connect the host's ports to agent {agent}: {reason}")]
    Connect {
        /// Agent id.
        agent: u32,
        /// Transport detail.
        reason: String,
    },
    /// SIGINT / SIGTERM arrived.
    #[error("termination requested")]
    Terminated,
}

/// Why an agent could not connect to its host, whatever the transport.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum AgentConnectError {
    /// No host answered for the session before the connect timeout.
    #[error(
        "no host for session {session:?} within {}: {looked_for} (agent {agent} \
         connects only after the session's host side, the simulator, has started; start it \
         first or raise sync.connect_timeout)",
        crate::rounded::Rounded(*.waited)
    )]
    HostNotFound {
        /// The session.
        session: String,
        /// The agent id that tried to connect.
        agent: u32,
        /// How long the agent waited.
        waited: Duration,
        /// What was missing: the service or address looked for, and the last error.
        looked_for: String,
    },
    /// The session's host is running but does not serve this agent id.
    #[error(
        "the host of session {session:?} serves agents {served:?}, not agent {agent}: use one \
         of those ids, or add agent {agent} to the host's config"
    )]
    IdNotServed {
        /// The session.
        session: String,
        /// The agent id that tried to connect.
        agent: u32,
        /// The ids the host serves, ascending.
        served: Vec<u32>,
    },
    /// Host and agent were built with different wire layouts.
    #[error(
        "protocol mismatch in session {session:?}: the host speaks vrsync protocol \
         {host_protocol} (layout {host_layout}), this agent speaks protocol {agent_protocol} \
         (layout {agent_layout}); rebuild the agent against the host's version"
    )]
    VersionMismatch {
        /// The session.
        session: String,
        /// The host's protocol version (as the host announced it).
        host_protocol: String,
        /// The host's layout hash (hex).
        host_layout: String,
        /// This agent's protocol version.
        agent_protocol: u32,
        /// This agent's layout hash (hex).
        agent_layout: String,
    },
    /// The host's config declares other channels (`[[agent.vector]]`, `[[agent.action]]`)
    /// for this agent than the agent's config does.
    #[error(
        "the host of session {session:?} refused agent {agent}: {difference}; use the same \
         config file on both sides"
    )]
    ChannelMismatch {
        /// The session.
        session: String,
        /// The agent id.
        agent: u32,
        /// The first channel that differs, and what each side declares of it.
        difference: ChannelDifference,
    },
    /// Another process already is this agent.
    #[error("agent {agent} of session {session:?} is already connected by another process")]
    IdInUse {
        /// The session.
        session: String,
        /// The agent id.
        agent: u32,
    },
    /// The host refused the agent (e.g. a missing or wrong `tcp_token`).
    #[error("the host of session {session:?} refused agent {agent}: {reason}")]
    Refused {
        /// The session.
        session: String,
        /// The agent id.
        agent: u32,
        /// The host's reason.
        reason: String,
    },
    /// The transport failed in another way.
    #[error("agent {agent} of session {session:?} cannot connect: {detail}")]
    Transport {
        /// The session.
        session: String,
        /// The agent id.
        agent: u32,
        /// The transport's detail.
        detail: String,
    },
}

impl AgentConnectError {
    /// [`AgentConnectError::ChannelMismatch`] if the `host`'s channel layout for this agent
    /// differs from `ours`.
    pub(crate) fn channel_mismatch(
        session: &str,
        agent: u32,
        host: &ChannelLayout,
        ours: &ChannelLayout,
    ) -> Option<Self> {
        host.difference(ours)
            .map(|difference| Self::ChannelMismatch {
                session: session.to_owned(),
                agent,
                difference,
            })
    }

    /// What an agent whose channels are `ours` reports when it got the refusal `reject`;
    /// `mismatch(host protocol, host layout)` builds the error of a version refusal.
    pub(crate) fn from_reject(
        reject: record::Reject,
        session: &str,
        agent: u32,
        ours: &ChannelLayout,
        mismatch: impl FnOnce(u32, u64) -> Self,
    ) -> Self {
        use record::reject as code;
        let session = session.to_owned();
        if let (code::CHANNELS, Some(host)) = (reject.code, &reject.host_channels)
            && let Some(e) = Self::channel_mismatch(&session, agent, host, ours)
        {
            return e;
        }
        match reject.code {
            code::VERSION => mismatch(reject.host_protocol, reject.host_layout),
            code::UNKNOWN_AGENT => Self::IdNotServed {
                session,
                agent,
                served: reject.served,
            },
            code::ID_IN_USE => Self::IdInUse { session, agent },
            _ => Self::Refused {
                session,
                agent,
                reason: reject.message,
            },
        }
    }
}

/// A sink for received motor batches: `(slot, header, commands)`.
pub type BatchSink<'a> = dyn FnMut(usize, &MotorHeader, &[MotorCommand]) + 'a;

/// Host side of a transport: its data path. Agents are addressed by *slot*: their index in
/// the config's agent list. The contract is three traits, each a concern of its own: the
/// data path (this one), the readiness the host waits on ([`HostReadiness`]) and the
/// connections ([`HostConnections`]); a transport implements all three. Termination is not
/// the transport's business: the host reads the process's termination flag
/// ([`SignalHandling`](crate::SignalHandling)) itself.
///
/// The contract:
/// - [`HostTransport::loan`] hands out writable memory for one agent's sensor frame
///   (header + images). On shared memory this *is* the memory the agent will read: the
///   simulator renders straight into it. [`HostTransport::publish`] makes it visible to that
///   agent; a published frame is never modified again.
/// - [`HostTransport::signal_start`] wakes every agent at once. It is called after every
///   frame of the cycle has been published, so an agent woken by *start* finds its frame.
///   (On TCP the frame record itself is the start.)
/// - [`HostTransport::drain`] hands every motor batch that arrived since the last call to
///   the sink, per agent in the order the agent sent them, without blocking. (Over shared
///   memory a batch arrives with the notification its agent sends after it — or, while
///   the host polls, with the host's look — so a drain need not look at every queue.)
/// - [`HostReadiness::wait_activity`] blocks until a batch may have arrived or the timeout
///   passed. It may wake spuriously; it never spins (unless the transport is asked to) and
///   never loses a wake-up: a batch published before or during the call ends the wait.
///   Notifications merge, so callers never count wake-ups — they read cycle numbers from
///   the batches.
/// - [`HostConnections::is_connected`] tells whether an agent's receiving side is
///   attached, so the host can refuse to start cycle 0 before every agent can see it. A new
///   connection that replaced the one the last frame went to is not the same agent: until
///   the host [forgets](HostConnections::forget_connection) the old one it is not
///   connected.
/// - A batch with [`crate::wire::MOTOR_FLAG_LEAVE`] is handed to the sink like any other;
///   a network transport then drops that connection at once, so the id is free for a new
///   one.
/// - Each transport has its own loan type ([`HostTransport::Loan`]); a host serving agents
///   over several transports routes each agent's slot to its transport and waits for all
///   of them at once ([`HostReadiness::activity_fd`]): one wait, whoever answers.
pub trait HostTransport: HostReadiness + HostConnections {
    /// A loaned sensor frame of this transport: only this transport's own loans come back
    /// to [`HostTransport::publish`], so no backend checks at run time what it got.
    type Loan: FrameLoanMut;
    /// Loans writable memory for agent `slot`'s next sensor frame.
    ///
    /// # Errors
    /// [`HostTransportError::Loan`].
    fn loan(&mut self, slot: usize) -> Result<Self::Loan, HostTransportError>;
    /// Publishes a loaned frame to agent `slot`. Returns whether it was delivered: `false`
    /// when the agent is not connected (any more), or — async mode on TCP — its socket is
    /// full and it misses this frame.
    ///
    /// # Errors
    /// [`HostTransportError::Send`].
    fn publish(&mut self, slot: usize, frame: Self::Loan) -> Result<bool, HostTransportError>;
    /// Wakes every agent.
    ///
    /// # Errors
    /// [`HostTransportError::Send`].
    fn signal_start(&mut self) -> Result<(), HostTransportError>;
    /// Hands every batch received since the last call to `sink`, without blocking.
    ///
    /// # Errors
    /// [`HostTransportError::Receive`].
    fn drain(&mut self, sink: &mut BatchSink<'_>) -> Result<(), HostTransportError>;
}

/// How the host waits for a transport: one descriptor, a deadline, work already read, and
/// what a wake-up means (part of the transport contract, see [`HostTransport`]).
pub trait HostReadiness {
    /// Blocks until a batch may have arrived, or `timeout` passed. The default is the one
    /// wait every transport shares: its [`activity_fd`] until readable, bounded by its
    /// [`next_deadline`], then [`after_wait`].
    ///
    /// # Errors
    /// [`HostTransportError::Wait`] when waiting fails; [`HostTransportError::Terminated`]
    /// when a transport that watches the termination flag in its own wait (shared memory,
    /// spinning) saw it.
    ///
    /// [`activity_fd`]: HostReadiness::activity_fd
    /// [`next_deadline`]: HostReadiness::next_deadline
    /// [`after_wait`]: HostReadiness::after_wait
    fn wait_activity(&mut self, timeout: Duration) -> Result<(), HostTransportError> {
        wait_for_activity(self, timeout)
    }

    /// The transport's readiness: a descriptor that is readable whenever something may
    /// have arrived (a batch, a connection, a hello) — an epoll set of its sockets, an
    /// iceoryx2 listener, an eventfd its callbacks write. Level-triggered: it stays
    /// readable until [`HostReadiness::after_wait`] or a drain consumed what it stands
    /// for. A host serving agents over several transports waits once on all of theirs.
    fn activity_fd(&self) -> std::os::fd::RawFd;

    /// When the transport next needs [`HostReadiness::after_wait`] although its descriptor
    /// stays quiet (a hello or a record that must complete by then, a keep-alive due):
    /// every wait ends by then.
    fn next_deadline(&self) -> Option<std::time::Instant> {
        None
    }

    /// Whether there is work a wait must not sleep over although the descriptor is quiet
    /// (batches already read from the sockets, a connection ready to admit).
    fn has_work(&self) -> bool {
        false
    }

    /// Called after every wait (whether the descriptor was readable or the time passed):
    /// services what the wake-up means without blocking (accepts, hellos, timers) and
    /// forgets wake-ups already seen. Batches are left for the next drain.
    fn after_wait(&mut self) {}
}

/// A transport's connections as the host sees them: who is attached, who joined, left,
/// died, was refused or came back (part of the transport contract, see [`HostTransport`]).
pub trait HostConnections {
    /// Whether agent `slot` has attached its receiving side. A slot a network transport
    /// holds for its agent's return after a lost link (TCP's `[sync] resume_window`) counts
    /// as connected: a frame published to it is delivered when the agent is back.
    fn is_connected(&self, slot: usize) -> bool;

    /// Re-establishes connections after agents joined.
    ///
    /// # Errors
    /// [`HostTransportError::Connect`] naming the agent.
    fn update_connections(&mut self) -> Result<(), HostTransportError>;

    /// Hands the peers refused since the last call to `sink`; returns how many more were
    /// refused without details (see [`Refusals`](crate::Refusals)). Transports without
    /// strangers (shared memory) keep the default: none.
    fn take_refusals(&mut self, sink: &mut dyn FnMut(&PeerRefusal)) -> u64 {
        let _ = sink;
        0
    }

    /// How many agents held after a lost link came back within the resume window
    /// (`[sync] resume_window`) since the last call. Transports without a resume window
    /// keep the default: none.
    fn take_resumes(&mut self) -> u64 {
        0
    }

    /// Finds agents whose process died (iceoryx2 reports their node dead), removes their
    /// stale resources, and appends their slots to `dead`. Called a few times per second
    /// while the host waits; transports that see disconnects directly (TCP) need nothing.
    fn reap_dead_agents(&mut self, dead: &mut Vec<usize>) {
        let _ = dead;
    }

    /// The host stopped serving agent `slot`'s connection: it left (a batch with
    /// [`crate::wire::MOTOR_FLAG_LEAVE`]) or was evicted. A transport that tells an agent's
    /// connections apart by identity (shared memory: the subscriber that got the last
    /// frame) forgets the old one, so the next connection for the id counts as connected.
    /// It must not drop a connection admitted after the one the host served. Network
    /// transports close a leaving agent's connection themselves when they read its leave
    /// batch, and need nothing here.
    fn forget_connection(&mut self, slot: usize) {
        let _ = slot;
    }

    /// The network address agents connect to, for network transports.
    fn local_addr(&self) -> Option<std::net::SocketAddr> {
        None
    }
}

/// The wait of one transport: its [`HostReadiness::activity_fd`] until readable or
/// `timeout` (shortened to its [`HostReadiness::next_deadline`], zero when it
/// [has work](HostReadiness::has_work)), then [`HostReadiness::after_wait`]. A signal ends
/// the wait early (the handlers are installed without `SA_RESTART`); the caller reads the
/// termination flag.
///
/// # Errors
/// [`HostTransportError::Wait`] when waiting fails.
pub fn wait_for_activity<T: HostReadiness + ?Sized>(
    t: &mut T,
    timeout: Duration,
) -> Result<(), HostTransportError> {
    let timeout = bounded_timeout(timeout, t.has_work(), t.next_deadline());
    wait::poll_one(t.activity_fd(), libc::POLLIN, timeout).map_err(|e| {
        HostTransportError::Wait {
            reason: format!("poll: {e}"),
        }
    })?;
    t.after_wait();
    Ok(())
}

/// `timeout`, zero with work to do, and no later than `deadline`.
pub(crate) fn bounded_timeout(
    timeout: Duration,
    has_work: bool,
    deadline: Option<std::time::Instant>,
) -> Duration {
    if has_work {
        return Duration::ZERO;
    }
    match deadline {
        Some(d) => timeout.min(d.saturating_duration_since(std::time::Instant::now())),
        None => timeout,
    }
}

// ---------------------------------------------------------------------------------------
// Agent side
// ---------------------------------------------------------------------------------------

/// Frames an agent may hold at once, on every transport: the current one and one more.
pub const AGENT_MAX_HELD_FRAMES: usize = 2;

/// How often a waiting agent checks that the host process is still alive.
pub const HOST_LIVENESS_PERIOD: Duration = Duration::from_millis(250);

/// A received sensor frame: header and image bytes, read-only, valid while held.
pub trait AgentFrame {
    /// The header.
    fn header(&self) -> &SensorHeader;
    /// The image bytes (the header's image table points into them).
    fn payload(&self) -> &[u8];
}

/// What an agent knows of its host.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum HostLiveness {
    /// Running, as far as this check can tell.
    Alive,
    /// The host closed the session cleanly.
    Closed,
    /// The host's process died, or the connection broke without a close.
    Gone {
        /// What was seen.
        reason: String,
    },
}

/// Why [`AgentTransport::try_receive_newest`] failed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum AgentReceiveError {
    /// The caller still holds `max` frames.
    #[error("the agent holds {max} frames already")]
    TooManyFramesHeld {
        /// How many frames an agent may hold at once.
        max: usize,
    },
    /// The host sent something that violates the protocol.
    #[error("protocol violation: {0}")]
    Protocol(String),
    /// The transport failed otherwise.
    #[error("{0}")]
    Transport(String),
}

/// Why [`AgentTransport::send_batch`] failed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum AgentSendError {
    /// The host closed the session before the batch could be sent.
    #[error("the host closed the session")]
    HostClosed,
    /// The transport failed.
    #[error("{0}")]
    Transport(String),
}

/// Agent side of a transport.
///
/// The contract:
/// - [`AgentTransport::try_receive_newest`] returns, without blocking, the newest sensor
///   frame that arrived since the last call and drops older ones (a slow agent never works
///   through a backlog). The frame keeps its memory until dropped (on shared memory it *is*
///   the host's sample); an agent holds at most [`AGENT_MAX_HELD_FRAMES`] frames at once,
///   beyond that the call fails with [`AgentReceiveError::TooManyFramesHeld`].
/// - [`AgentTransport::wait_readable`] blocks until a frame may have arrived, the host's
///   state may have changed, or the timeout passed. It may wake spuriously and never loses
///   a wake-up: a frame published before or during the call (after the last
///   [`AgentTransport::discard_wakeups`]) ends the wait.
/// - [`AgentTransport::host_liveness`]: [`HostLiveness::Closed`] once the host closed the
///   session cleanly (after the frames it sent before), [`HostLiveness::Gone`] when its
///   process died or the connection broke without a close. A cheap check every call; the
///   expensive one (the host's process) only when asked.
/// - [`AgentTransport::send_batch`] publishes a motor batch; with the stop flag it also
///   signals *stop*, which becomes visible to the host only after its batch.
/// - [`AgentTransport::termination_requested`]: SIGINT/SIGTERM arrived (see
///   [`crate::SignalHandling`]).
pub trait AgentTransport {
    /// A received frame.
    type Frame: AgentFrame;
    /// Connects as agent `id` of `config`'s session, retrying until the host answers or
    /// `timeout` passes, with the credentials `config` names (`tcp_token`, zenoh's
    /// `token`); `signals` says whether SIGINT/SIGTERM handlers are installed (see
    /// [`crate::SignalHandling`]).
    ///
    /// # Errors
    /// [`AgentConnectError`].
    fn connect(
        config: &crate::config::Config,
        id: u32,
        timeout: Duration,
        signals: crate::signal::SignalHandling,
    ) -> Result<Self, AgentConnectError>
    where
        Self: Sized;
    /// The newest frame that arrived since the last call, older ones dropped; never blocks
    /// for a frame (a record already arriving is read to its end).
    ///
    /// # Errors
    /// [`AgentReceiveError`].
    fn try_receive_newest(&mut self) -> Result<Option<Self::Frame>, AgentReceiveError>;
    /// Blocks until a frame may have arrived, the host's state may have changed, or
    /// `timeout` passed.
    fn wait_readable(&mut self, timeout: Duration);
    /// Forgets pending wake-ups, so that the next [`AgentTransport::wait_readable`] waits
    /// for something new (a frame arriving later always brings its own).
    fn discard_wakeups(&mut self);
    /// The host's state; `check_process` asks for the expensive check of the host's
    /// process too (made every [`HOST_LIVENESS_PERIOD`] by [`wait_for_newer_frame`]).
    fn host_liveness(&mut self, check_process: bool) -> HostLiveness;
    /// Sends a motor batch; with the stop flag in `header`, also signals *stop* (visible to
    /// the host only after the batch).
    ///
    /// # Errors
    /// [`AgentSendError`].
    fn send_batch(
        &mut self,
        header: &MotorHeader,
        commands: &[MotorCommand],
    ) -> Result<(), AgentSendError>;
    /// Whether SIGINT/SIGTERM arrived (never, with [`crate::SignalHandling::Leave`]).
    fn termination_requested(&self) -> bool;
    /// Starts closing the connection without waiting for it; dropping the transport then
    /// waits for the close (bounded). A transport whose close waits for the host (zenoh's)
    /// starts it here, so that closing many agents waits for all their closes at once,
    /// not one after another. Nothing is sent after it. The default does nothing.
    fn begin_close(&mut self) {}
}

/// Why [`wait_for_newer_frame`] returned without a frame.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum AgentWaitError {
    /// No newer frame before the deadline.
    #[error("timeout")]
    Timeout,
    /// The host closed the session.
    #[error("the host closed the session")]
    HostClosed,
    /// The host is gone.
    #[error("the host is gone: {reason}")]
    HostGone {
        /// What was seen.
        reason: String,
    },
    /// Receiving failed.
    #[error(transparent)]
    Receive(#[from] AgentReceiveError),
    /// SIGINT/SIGTERM.
    #[error("termination requested")]
    Terminated,
}

/// Waits for the newest frame newer than `last_cycle` until `deadline` (`None`: no
/// limit), checking the host's liveness every [`HOST_LIVENESS_PERIOD`] (`next_liveness`
/// persists across calls, so zero-timeout polls notice a dead host too). Older frames are
/// dropped; a frame that arrived is taken even past the deadline.
///
/// # Errors
/// [`AgentWaitError`].
pub fn wait_for_newer_frame<T: AgentTransport>(
    transport: &mut T,
    last_cycle: Option<u64>,
    deadline: Option<Instant>,
    next_liveness: &mut Instant,
) -> Result<T::Frame, AgentWaitError> {
    // Pending wake-ups carry nothing we rely on: the frame itself tells whether it is new.
    // Forgetting them first means a stale wake-up cannot end a wait early, and a frame
    // published after this point always comes with a fresh one.
    transport.discard_wakeups();
    loop {
        // Checked before taking a frame too: in a fast run a frame is always waiting.
        if transport.termination_requested() {
            return Err(AgentWaitError::Terminated);
        }
        if let Some(frame) = transport.try_receive_newest()? {
            let cycle = frame.header().cycle;
            if last_cycle.is_none_or(|last| cycle > last) {
                return Ok(frame);
            }
            debug!(cycle, "old frame ignored");
        }
        let now = Instant::now();
        let check_process = now >= *next_liveness;
        match transport.host_liveness(check_process) {
            HostLiveness::Alive => {}
            HostLiveness::Closed => return Err(AgentWaitError::HostClosed),
            HostLiveness::Gone { reason } => return Err(AgentWaitError::HostGone { reason }),
        }
        if check_process {
            *next_liveness = now + HOST_LIVENESS_PERIOD;
        }
        let mut slice = next_liveness.saturating_duration_since(now);
        if let Some(d) = deadline {
            if now >= d {
                return Err(AgentWaitError::Timeout);
            }
            slice = slice.min(d - now);
        }
        transport.wait_readable(slice);
    }
}

/// What one connection attempt of [`retry_until`] found.
#[derive(Debug)]
pub enum Attempt<T, E> {
    /// Connected.
    Done(T),
    /// The host is not there (yet): try again; the text says what was missing.
    NotYet(String),
    /// A final answer: give up.
    Failed(E),
}

/// Runs `attempt` with a short back-off (5 ms doubling to 100 ms) until it is done or
/// failed, or `deadline` passed or a termination was requested: then returns the last
/// "not yet" text. The host may start after its agents; there is nothing to wait on but
/// time.
///
/// # Errors
/// `Err(Ok(missing))` when the deadline passed, `Err(Err(e))` when an attempt failed.
pub fn retry_until<T, E>(
    deadline: Instant,
    terminated: impl Fn() -> bool,
    mut attempt: impl FnMut() -> Attempt<T, E>,
) -> Result<T, Result<String, E>> {
    let mut backoff = Duration::from_millis(5);
    loop {
        match attempt() {
            Attempt::Done(t) => return Ok(t),
            Attempt::Failed(e) => return Err(Err(e)),
            Attempt::NotYet(missing) => {
                let now = Instant::now();
                if now >= deadline || terminated() {
                    return Err(Ok(missing));
                }
                std::thread::sleep(backoff.min(deadline - now));
                backoff = (backoff * 2).min(Duration::from_millis(100));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{MAX_KEPT_REFUSALS, RefusalKind, Refusals};

    fn refusal(i: usize) -> PeerRefusal {
        PeerRefusal {
            kind: RefusalKind::Silent,
            agent: None,
            peer: format!("127.0.0.1:{i}"),
            reason: "sent nothing".into(),
        }
    }

    #[test]
    fn refusals_keep_a_bounded_number_of_details_and_count_the_rest() {
        let mut r = Refusals::default();
        for i in 0..MAX_KEPT_REFUSALS + 5 {
            r.push(refusal(i));
        }
        r.count(3);
        let mut seen = Vec::new();
        let unkept = r.take(&mut |p| seen.push(p.peer.clone()));
        assert_eq!(seen.len(), MAX_KEPT_REFUSALS);
        assert_eq!(seen[0], "127.0.0.1:0");
        assert_eq!(unkept, 5 + 3);
        // Taken: nothing is handed out twice.
        assert_eq!(r.take(&mut |_| panic!("handed out twice")), 0);
    }
}
