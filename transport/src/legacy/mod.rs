//! The agent side of the original protocol, for the transport registry: there is none in
//! this SDK. Agents on this transport are programs written for the original system (its
//! Python and C++ clients), which speak the protocol themselves; a vrsync agent asked to
//! connect over it gets an error saying so. The types are uninhabited: no value of them
//! exists, so every method but `connect` is unreachable by construction.

use crate::{TransportKind, absent_agent};

pub(crate) mod section;
pub use section::{LegacyConfig, LegacyDialect, PngCompression};

absent_agent!(
    /// No vrsync agent connects over the original protocol: [`AgentTransport::connect`]
    /// says why. Uninhabited.
    ///
    /// [`AgentTransport::connect`]: crate::AgentTransport::connect
    LegacyAgent,
    LegacyFrame,
    format!(
        "its [[agent]] transport is \"legacy\": the host serves it the original system's \
         protocol for agents written for that system; use {} for a vrsync agent",
        vrsync_transports()
    )
);

/// The transports a vrsync agent can connect over, as a config spells them: `"a", "b" or
/// "c"` (every transport of the registry but this one).
fn vrsync_transports() -> String {
    let names: Vec<String> = (TransportKind::ALL.iter())
        .filter(|k| **k != TransportKind::Legacy)
        .map(|k| format!("{:?}", k.as_str()))
        .collect();
    match names.split_last() {
        Some((last, [])) => last.clone(),
        Some((last, rest)) => format!("{} or {last}", rest.join(", ")),
        None => String::new(),
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use std::time::Duration;

    use crate::AgentTransport;
    use crate::any_agent::AnyAgent;
    use crate::config::{Config, TransportKind};
    use crate::signal::SignalHandling;

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
