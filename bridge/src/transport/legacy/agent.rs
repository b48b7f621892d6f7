//! The agent side of the original protocol, for the transport registry: there is none in
//! this SDK. Agents on this transport are programs written for the original system (its
//! Python and C++ clients), which speak the protocol themselves; a vrsync agent asked to
//! connect over it gets an error saying so. The types are uninhabited: no value of them
//! exists, so every method but `connect` is unreachable by construction.

use std::time::Duration;

use crate::config::Config;
use crate::signal::SignalHandling;
use crate::transport::{
    AgentConnectError, AgentFrame, AgentReceiveError, AgentSendError, AgentTransport, HostLiveness,
};
use crate::wire::{MotorCommand, MotorHeader, SensorHeader};

/// No vrsync agent connects over the original protocol: [`AgentTransport::connect`] says
/// why. Uninhabited.
#[derive(Debug)]
pub enum LegacyAgent {}

/// The frame of a [`LegacyAgent`]. Uninhabited.
#[derive(Debug)]
pub enum LegacyFrame {}

impl AgentFrame for LegacyFrame {
    fn header(&self) -> &SensorHeader {
        match *self {}
    }

    fn payload(&self) -> &[u8] {
        match *self {}
    }
}

impl AgentTransport for LegacyAgent {
    type Frame = LegacyFrame;

    /// Always fails: the host serves this transport to programs written for the original
    /// system, not to this SDK's agents.
    fn connect(
        config: &Config,
        id: u32,
        _timeout: Duration,
        _signals: SignalHandling,
    ) -> Result<Self, AgentConnectError> {
        Err(AgentConnectError::Transport {
            session: config.session.clone(),
            agent: id,
            detail: "its [[agent]] transport is \"legacy\": the host serves it the original \
                     system's protocol for agents written for that system; use \"shm\", \
                     \"tcp\" or \"zenoh\" for a vrsync agent"
                .into(),
        })
    }

    fn try_receive_newest(&mut self) -> Result<Option<LegacyFrame>, AgentReceiveError> {
        match *self {}
    }

    fn wait_readable(&mut self, _timeout: Duration) {
        match *self {}
    }

    fn discard_wakeups(&mut self) {
        match *self {}
    }

    fn host_liveness(&mut self, _check_process: bool) -> HostLiveness {
        match *self {}
    }

    fn send_batch(
        &mut self,
        _header: &MotorHeader,
        _commands: &[MotorCommand],
    ) -> Result<(), AgentSendError> {
        match *self {}
    }

    fn termination_requested(&self) -> bool {
        match *self {}
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use crate::config::TransportKind;
    use crate::transport::any_agent::AnyAgent;

    #[test]
    fn a_vrsync_agent_on_the_legacy_transport_is_told_why_it_cannot_connect() {
        let mut config = Config::embedded_default().unwrap();
        config.agents[0].transport = TransportKind::Legacy;
        let id = config.agents[0].id;
        let err = AnyAgent::connect(&config, id, Duration::from_secs(1), SignalHandling::Leave)
            .unwrap_err();
        assert_eq!(
            err.to_string(),
            format!(
                "agent {id} of session {:?} cannot connect: its [[agent]] transport is \
                 \"legacy\": the host serves it the original system's protocol for agents \
                 written for that system; use \"shm\", \"tcp\" or \"zenoh\" for a vrsync agent",
                config.session
            )
        );
    }
}
