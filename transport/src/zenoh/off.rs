//! The zenoh transport's place in the registry in a build without the `zenoh` feature.
//!
//! zenoh and its async runtime are the largest part of a build, and a Rust agent that
//! talks to a host on its own machine (shm, tcp) has no use for them: the feature is off
//! unless a crate turns it on (vr-sim, vr-agent, the C ABIs and the Python package do).
//! The config keeps its `"zenoh"` spelling and `[transport.zenoh]` section either way, so
//! one config file works with every build; what fails is creating a host or connecting an
//! agent for which the config names zenoh, with an error naming the feature (stand-ins of
//! [`super::absent`]).
//!
//! Not a module of `zenoh/mod.rs`: the crate root (`lib.rs`) takes this file as the whole
//! `zenoh` module in a build without the feature (kept in the transport's folder; the
//! legacy host's stand-in is in `vrsync-bridge`, which has the `legacy` feature).

use crate::{absent_agent, absent_host};

#[path = "section.rs"]
pub(crate) mod section;
pub use section::{DEFAULT_ZENOH_ENDPOINT, ZenohConfig, ZenohTls};

absent_host!(
    ZenohHost,
    ZenohFrameLoan,
    ZenohHostCreateError,
    "zenoh",
    "zenoh"
);

absent_agent!(
    /// The zenoh agent of a build without the `zenoh` feature: `connect` says why there is
    /// none. Uninhabited.
    ZenohAgent,
    ZenohFrame,
    "its [[agent]] transport is \"zenoh\", but this build has no zenoh transport (it was \
     compiled without the `zenoh` cargo feature of vrsync-bridge; a Rust agent turns it on \
     with the `zenoh` feature of vrsync-agent)"
        .into()
);

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use std::time::Duration;

    use super::ZenohHost;
    use crate::AgentTransport;
    use crate::any_agent::AnyAgent;
    use crate::config::TransportKind;
    use crate::signal::SignalHandling;

    /// The embedded default config with every agent on `kind`, in a session of this test
    /// process.
    fn config_all_on(kind: TransportKind) -> crate::config::Config {
        let mut config = crate::config::Config::embedded_default().unwrap();
        config.session = format!("absent-{}-{}", kind.as_str(), std::process::id());
        for a in &mut config.agents {
            a.transport = kind;
        }
        config
    }

    #[test]
    fn an_agent_on_zenoh_is_told_the_build_has_no_zenoh() {
        let config = config_all_on(TransportKind::Zenoh);
        let id = config.agents[0].id;
        let err = AnyAgent::connect(&config, id, Duration::from_secs(1), SignalHandling::Leave)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("its [[agent]] transport is \"zenoh\""),
            "{err}"
        );
        assert!(err.contains("`zenoh` cargo feature"), "{err}");
    }

    #[test]
    fn a_host_with_zenoh_agents_is_told_the_build_has_no_zenoh() {
        let err = ZenohHost::create(&config_all_on(TransportKind::Zenoh), SignalHandling::Leave)
            .unwrap_err()
            .to_string();
        assert!(err.contains("the zenoh transport"), "{err}");
        assert!(err.contains("`zenoh` cargo feature"), "{err}");
    }
}
