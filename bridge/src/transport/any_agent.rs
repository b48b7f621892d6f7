//! The agent side over whichever transport the config names: the SDK's `Agent` drives this
//! one [`AgentTransport`] and knows no transport by name (the host side's counterpart is
//! `mixed.rs`).

use std::time::Duration;

use super::shm::{ShmAgent, ShmFrame};
use super::tcp::{TcpAgent, TcpFrame};
use super::zenoh::{ZenohAgent, ZenohFrame};
use super::{
    AgentConnectError, AgentFrame, AgentReceiveError, AgentSendError, AgentTransport, HostLiveness,
};
use crate::config::{Config, TransportKind};
use crate::signal::SignalHandling;
use crate::wire::{MotorCommand, MotorHeader, SensorHeader};

/// A frame of whichever transport brought it.
// The TCP variant carries its 784-byte header by value (a frame is moved once, from the
// transport to the caller); boxing it would allocate every cycle.
#[allow(clippy::large_enum_variant)]
#[derive(Debug)]
pub enum AnyFrame {
    /// Shared memory (the host's sample itself).
    Shm(ShmFrame),
    /// TCP.
    Tcp(TcpFrame),
    /// zenoh.
    Zenoh(ZenohFrame),
}

impl AgentFrame for AnyFrame {
    fn header(&self) -> &SensorHeader {
        match self {
            Self::Shm(f) => AgentFrame::header(f),
            Self::Tcp(f) => AgentFrame::header(f),
            Self::Zenoh(f) => AgentFrame::header(f),
        }
    }

    fn payload(&self) -> &[u8] {
        match self {
            Self::Shm(f) => AgentFrame::payload(f),
            Self::Tcp(f) => AgentFrame::payload(f),
            Self::Zenoh(f) => AgentFrame::payload(f),
        }
    }
}

/// An agent connection over the transport its config names (`[[agent]] transport`, else
/// `[transport] kind`).
#[derive(Debug)]
pub enum AnyAgent {
    /// Shared memory.
    Shm(Box<ShmAgent>),
    /// TCP.
    Tcp(TcpAgent),
    /// zenoh.
    Zenoh(Box<ZenohAgent>),
}

impl AgentTransport for AnyAgent {
    type Frame = AnyFrame;

    /// Connects over agent `id`'s transport. The original protocol's transport serves
    /// programs written for the original system, not this SDK: a clear error.
    fn connect(
        config: &Config,
        id: u32,
        timeout: Duration,
        signals: SignalHandling,
    ) -> Result<Self, AgentConnectError> {
        let kind = config
            .agent(id)
            .map_or(config.transport.kind, |a| a.transport);
        Ok(match kind {
            TransportKind::Shm => {
                Self::Shm(Box::new(ShmAgent::connect(config, id, timeout, signals)?))
            }
            TransportKind::Tcp => Self::Tcp(TcpAgent::connect(config, id, timeout, signals)?),
            TransportKind::Zenoh => {
                Self::Zenoh(Box::new(ZenohAgent::connect(config, id, timeout, signals)?))
            }
            TransportKind::Legacy => {
                return Err(AgentConnectError::Transport {
                    session: config.session.clone(),
                    agent: id,
                    detail: "its [[agent]] transport is \"legacy\": the host serves it the \
                             original system's protocol for agents written for that system; \
                             use \"shm\", \"tcp\" or \"zenoh\" for a vrsync agent"
                        .into(),
                });
            }
        })
    }

    fn try_receive_newest(&mut self) -> Result<Option<AnyFrame>, AgentReceiveError> {
        Ok(match self {
            Self::Shm(t) => t.try_receive_newest()?.map(AnyFrame::Shm),
            Self::Tcp(t) => t.try_receive_newest()?.map(AnyFrame::Tcp),
            Self::Zenoh(t) => t.try_receive_newest()?.map(AnyFrame::Zenoh),
        })
    }

    fn wait_readable(&mut self, timeout: Duration) {
        match self {
            Self::Shm(t) => t.wait_readable(timeout),
            Self::Tcp(t) => t.wait_readable(timeout),
            Self::Zenoh(t) => t.wait_readable(timeout),
        }
    }

    fn discard_wakeups(&mut self) {
        match self {
            Self::Shm(t) => t.discard_wakeups(),
            Self::Tcp(t) => t.discard_wakeups(),
            Self::Zenoh(t) => t.discard_wakeups(),
        }
    }

    fn host_liveness(&mut self, check_process: bool) -> HostLiveness {
        match self {
            Self::Shm(t) => t.host_liveness(check_process),
            Self::Tcp(t) => t.host_liveness(check_process),
            Self::Zenoh(t) => t.host_liveness(check_process),
        }
    }

    fn send_batch(
        &mut self,
        header: &MotorHeader,
        commands: &[MotorCommand],
    ) -> Result<(), AgentSendError> {
        match self {
            Self::Shm(t) => t.send_batch(header, commands),
            Self::Tcp(t) => t.send_batch(header, commands),
            Self::Zenoh(t) => t.send_batch(header, commands),
        }
    }

    fn termination_requested(&self) -> bool {
        match self {
            Self::Shm(t) => t.termination_requested(),
            Self::Tcp(t) => t.termination_requested(),
            Self::Zenoh(t) => t.termination_requested(),
        }
    }
}
