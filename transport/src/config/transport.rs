//! `[transport]`: which transport agents use by default, TCP's keys, and the sections of
//! the transports that have one (`[transport.legacy]`, `[transport.zenoh]`), each defined,
//! checked and written by its transport (`legacy/section.rs`, `zenoh/section.rs`).

use std::fmt::Write;
use std::net::SocketAddr;

use serde::Deserialize;
use toml::Spanned;

use super::ctx::{Ctx, toml_string};
use super::error::ConfigLoadError;
use crate::TransportKind;
use crate::legacy::section::{LegacyConfig, RawLegacy};
use crate::wire::MAX_TOKEN;
use crate::zenoh::section::{RawZenoh, ZenohConfig};

/// `[transport]` section.
#[derive(Debug, Clone, PartialEq)]
pub struct TransportConfig {
    /// Which transport.
    pub kind: TransportKind,
    /// TCP listen address of the host (and the address agents connect to).
    pub tcp_listen: SocketAddr,
    /// Most commands an agent may send in one cycle.
    pub max_commands_per_cycle: u32,
    /// Shared secret TCP agents must present in their hello (`tcp_token`); `None`: none.
    pub tcp_token: Option<String>,
    /// `[transport.zenoh]`.
    pub zenoh: ZenohConfig,
    /// `[transport.legacy]`: the original system's protocol.
    pub legacy: LegacyConfig,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub(super) struct RawTransport {
    pub(super) kind: Option<TransportKind>,
    pub(super) tcp_listen: Option<Spanned<String>>,
    pub(super) max_commands_per_cycle: Option<Spanned<i64>>,
    pub(super) tcp_token: Option<Spanned<String>>,
    pub(super) legacy: Option<RawLegacy>,
    pub(super) zenoh: Option<RawZenoh>,
}

impl TransportConfig {
    /// Forgets the shared secrets (`tcp_token`, `[transport.zenoh] token`): for a config
    /// that is written where others read it (a run's record).
    pub fn forget_secrets(&mut self) {
        self.tcp_token = None;
        self.zenoh.token = None;
    }
}

impl Ctx<'_> {
    /// The `[transport]` section with `[transport.legacy]` and `[transport.zenoh]`, with
    /// their defaults.
    pub(super) fn transport(
        &self,
        rt: Option<RawTransport>,
    ) -> Result<TransportConfig, ConfigLoadError> {
        let rt = rt.unwrap_or_default();
        let tcp_listen = match rt.tcp_listen {
            None => SocketAddr::from(([127, 0, 0, 1], 7400)),
            Some(s) => s.get_ref().parse().map_err(|e| {
                self.invalid(
                    s.span(),
                    "transport.tcp_listen",
                    format!(
                        "{:?} is not an address like 127.0.0.1:7400 ({e})",
                        s.get_ref()
                    ),
                )
            })?,
        };
        let max_commands_per_cycle = match rt.max_commands_per_cycle {
            None => 64,
            Some(v) => {
                let n = *v.get_ref();
                if !(1..=4096).contains(&n) {
                    return Err(self.invalid(
                        v.span(),
                        "transport.max_commands_per_cycle",
                        format!("must be 1..=4096, found {n}"),
                    ));
                }
                n as u32
            }
        };
        let tcp_token = match rt.tcp_token {
            None => None,
            Some(t) => {
                let len = t.get_ref().len();
                if len == 0 || len > MAX_TOKEN {
                    return Err(self.invalid(
                        t.span(),
                        "transport.tcp_token",
                        format!("must be 1..={} bytes, found {len}", MAX_TOKEN),
                    ));
                }
                Some(t.into_inner())
            }
        };
        let legacy = match rt.legacy {
            None => LegacyConfig::default(),
            Some(l) => LegacyConfig::check(self, l)?,
        };
        let zenoh = match rt.zenoh {
            None => ZenohConfig::default(),
            Some(rz) => ZenohConfig::check(self, rz)?,
        };
        Ok(TransportConfig {
            kind: rt.kind.unwrap_or_default(),
            tcp_listen,
            max_commands_per_cycle,
            tcp_token,
            legacy,
            zenoh,
        })
    }
}

/// `[transport]`, `[transport.legacy]` and `[transport.zenoh]`.
pub(super) fn write_transport(s: &mut String, transport: &TransportConfig) {
    let _ = writeln!(
        s,
        "\n[transport]\nkind = {:?}\ntcp_listen = \"{}\"\nmax_commands_per_cycle = {}",
        transport.kind.as_str(),
        transport.tcp_listen,
        transport.max_commands_per_cycle
    );
    if let Some(token) = &transport.tcp_token {
        let _ = writeln!(s, "tcp_token = {}", toml_string(token));
    }
    transport.legacy.write_toml(s);
    transport.zenoh.write_toml(s);
}
