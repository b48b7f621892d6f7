//! The host's view of the transports (from `vrsync-transport`, the original protocol's host
//! from `vrsync-legacy`), and the routing of one host over several of them ([`mixed`]).
//! The registry's callers name each transport's module as `crate::transport::<module>`:
//! these re-exports are those modules here.

pub(crate) mod mixed;

// Every module of the registry (`shm`, `tcp`, `zenoh`; `legacy` is below) and the
// contract, as the routing names them.
pub(crate) use vrsync_transport::*;

/// The original protocol's entry of the registry: its host (the `vrsync-legacy` crate, with
/// the `legacy` feature; a stand-in whose `create` names the feature without it).
pub mod legacy {
    #[cfg(feature = "legacy")]
    pub use vrsync_legacy::*;

    #[cfg(not(feature = "legacy"))]
    vrsync_transport::absent_host!(
        LegacyHost,
        LegacyFrameLoan,
        LegacyHostCreateError,
        "legacy",
        "legacy"
    );
}

/// Creating a host for legacy agents in a build without the `legacy` feature says so (the
/// zenoh stand-in's own test is in `vrsync-transport`, whose feature decides it).
#[cfg(all(test, not(feature = "legacy")))]
mod absent_tests {
    #![allow(clippy::unwrap_used)]

    use vrsync_transport::{Config, SignalHandling, TransportKind};

    #[test]
    fn a_host_with_legacy_agents_is_told_the_build_has_no_legacy() {
        let mut config = Config::embedded_default().unwrap();
        config.session = format!("absent-legacy-{}", std::process::id());
        for a in &mut config.agents {
            a.transport = TransportKind::Legacy;
        }
        let err = match super::mixed::Transports::create(&config, SignalHandling::Leave) {
            Ok(_) => panic!("a host for legacy agents was created"),
            Err(e) => e.to_string(),
        };
        assert!(err.contains("the legacy transport"), "{err}");
        assert!(err.contains("`legacy` cargo feature"), "{err}");
    }
}
