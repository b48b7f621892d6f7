//! Why creating the host, waiting for agents or a cycle failed.

use super::*;

/// Why the host could not be created: one variant per transport (its own create error,
/// shown as it is), and `Wait` when the one wait over several transports could not be set
/// up (an epoll set). Generated from the transport registry, with the transport mix.
pub type HostCreateError = crate::transport::mixed::TransportsCreateError;

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
