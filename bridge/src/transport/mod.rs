//! Transports: how sensor frames, motor batches, *start* and *stop* move between the host
//! and its agents.
//!
//! # The contract every transport keeps
//!
//! Host side ([`HostTransport`]):
//! - [`HostTransport::loan`] hands out writable memory for one agent's sensor frame
//!   (header + images). On shared memory this *is* the memory the agent will read: the
//!   simulator renders straight into it. [`HostTransport::publish`] makes it visible to that
//!   agent; a published frame is never modified again.
//! - [`HostTransport::signal_start`] wakes every agent at once. It is called after every
//!   frame of the cycle has been published, so an agent woken by *start* finds its frame.
//!   (On TCP the frame record itself is the start.)
//! - [`HostTransport::drain`] hands every motor batch that arrived since the last call to
//!   the sink, per agent in the order the agent sent them, without blocking.
//! - [`HostTransport::wait_activity`] blocks until a batch may have arrived or the timeout
//!   passed. It may wake spuriously; it never spins (unless the transport is asked to) and
//!   never loses a wake-up: a batch published before or during the call ends the wait.
//!   Notifications merge, so callers never count wake-ups — they read cycle numbers from
//!   the batches.
//! - [`HostTransport::is_connected`] tells whether an agent's receiving side is attached, so
//!   the host can refuse to start cycle 0 before every agent can see it.
//!
//! Agent side (e.g. [`shm::ShmAgent`]):
//! - `receive_newest` returns the newest sensor frame not yet seen and drops older ones
//!   (a slow agent never works through a backlog);
//! - `wait_start` blocks until *start* may have been signalled;
//! - `send_batch` publishes a motor batch; with the stop flag it also signals *stop*,
//!   after the batch is visible to the host.

pub mod shm;
pub mod tcp;

use std::time::Duration;

use crate::wire::{MotorCommand, MotorHeader, SensorHeader};

/// Writable memory for one sensor frame, loaned from a transport.
#[derive(Debug)]
pub enum FrameLoan {
    /// A loaned iceoryx2 sample.
    Shm(shm::ShmFrameLoan),
    /// A TCP record buffer.
    Tcp(tcp::TcpFrameLoan),
}

impl FrameLoan {
    /// The header and the image bytes, both writable.
    pub fn parts_mut(&mut self) -> (&mut SensorHeader, &mut [u8]) {
        match self {
            Self::Shm(s) => s.parts_mut(),
            Self::Tcp(t) => t.parts_mut(),
        }
    }

    /// The header.
    pub fn header(&self) -> &SensorHeader {
        match self {
            Self::Shm(s) => s.header(),
            Self::Tcp(t) => t.header(),
        }
    }
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
        "no host for session {session:?} within {waited:?}: {looked_for} (agent {agent} \
         connects only after the session's host side, the simulator, has started; start it \
         first or raise sync.connect_timeout)"
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

/// A sink for received motor batches: `(slot, header, commands)`.
pub type BatchSink<'a> = dyn FnMut(usize, &MotorHeader, &[MotorCommand]) + 'a;

/// Host side of a transport. Agents are addressed by *slot*: their index in the config's
/// agent list.
pub trait HostTransport {
    /// Whether agent `slot` has attached its receiving side.
    fn is_connected(&self, slot: usize) -> bool;
    /// Loans writable memory for agent `slot`'s next sensor frame.
    ///
    /// # Errors
    /// [`HostTransportError::Loan`].
    fn loan(&mut self, slot: usize) -> Result<FrameLoan, HostTransportError>;
    /// Publishes a loaned frame to agent `slot`. Returns whether it was delivered: `false`
    /// when the agent is not connected (any more), or — async mode on TCP — its socket is
    /// full and it misses this frame.
    ///
    /// # Errors
    /// [`HostTransportError::Send`].
    fn publish(&mut self, slot: usize, frame: FrameLoan) -> Result<bool, HostTransportError>;
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
    /// Blocks until a batch may have arrived, or `timeout` passed.
    ///
    /// # Errors
    /// [`HostTransportError::Terminated`] on SIGINT/SIGTERM.
    fn wait_activity(&mut self, timeout: Duration) -> Result<(), HostTransportError>;
    /// Re-establishes connections after agents joined.
    fn update_connections(&mut self);
    /// Whether SIGINT/SIGTERM was received.
    fn termination_requested(&self) -> bool;
    /// Finds agents whose process died (iceoryx2 reports their node dead), removes their
    /// stale resources, and appends their slots to `dead`. Called a few times per second
    /// while the host waits; transports that see disconnects directly (TCP) need nothing.
    fn reap_dead_agents(&mut self, dead: &mut Vec<usize>) {
        let _ = dead;
    }

    /// The network address agents connect to, for network transports.
    fn local_addr(&self) -> Option<std::net::SocketAddr> {
        None
    }
}
