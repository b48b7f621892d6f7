//! `[transport]`: which transport agents use by default, TCP's keys, and the sections of
//! the transports that have one (`[transport.<name>]`), each defined, checked and written
//! by its transport (`<module>/section.rs`) and named in its registry entry: the fields
//! and the code over them are generated from the registry (`transport_sections!`).

use std::fmt::Write;
use std::net::SocketAddr;

use serde::Deserialize;
use toml::Spanned;

use super::ctx::{Ctx, toml_string};
use super::error::ConfigLoadError;
use crate::TransportKind;
use crate::wire::MAX_TOKEN;

/// `TransportConfig` and `RawTransport` with a field per transport section of the
/// registry, and what goes through every section: read and check, write, forget secrets.
macro_rules! transport_sections {
    ($(
        $(#[$attr:meta])*
        $kind:ident $name:literal $module:ident:
            $host:ident, $loan:ident, $create_error:ident, $agent:ident, $frame:ident
            [channels: $channels:literal, wait_for_stop: $wait:ident
             $(, section: $section:ident $raw:ident)?];
    )*) => {
        /// `[transport]` section.
        #[derive(Debug, Clone, PartialEq)]
        pub struct TransportConfig {
            /// Which transport.
            pub kind: TransportKind,
            /// TCP listen address of the host (and the address agents connect to).
            pub tcp_listen: SocketAddr,
            /// Most commands an agent may send in one cycle.
            pub max_commands_per_cycle: u32,
            /// Shared secret TCP agents must present in their hello (`tcp_token`); `None`:
            /// none.
            pub tcp_token: Option<String>,
            $($(
                #[doc = concat!("`[transport.", $name, "]`.")]
                pub $module: crate::$module::section::$section,
            )?)*
        }

        #[derive(Deserialize, Default)]
        #[serde(deny_unknown_fields)]
        pub(super) struct RawTransport {
            pub(super) kind: Option<TransportKind>,
            pub(super) tcp_listen: Option<Spanned<String>>,
            pub(super) max_commands_per_cycle: Option<Spanned<i64>>,
            pub(super) tcp_token: Option<Spanned<String>>,
            $($(
                #[serde(rename = $name)]
                pub(super) $module: Option<crate::$module::section::$raw>,
            )?)*
        }

        impl TransportConfig {
            /// Forgets the shared secrets (`tcp_token`, and those of the transports'
            /// sections, e.g. `[transport.zenoh] token`): for a config that is written
            /// where others read it (a run's record).
            pub fn forget_secrets(&mut self) {
                self.tcp_token = None;
                $($( crate::$module::section::$section::forget_secrets(&mut self.$module); )?)*
            }

            /// The transports' sections, as TOML.
            fn write_sections(&self, s: &mut String) {
                $($( crate::$module::section::$section::write_toml(&self.$module, s); )?)*
            }
        }

        impl Ctx<'_> {
            /// The `[transport]` section with the transports' sections, with their
            /// defaults.
            pub(super) fn transport(
                &self,
                rt: Option<RawTransport>,
            ) -> Result<TransportConfig, ConfigLoadError> {
                let rt = rt.unwrap_or_default();
                Ok(TransportConfig {
                    kind: rt.kind.unwrap_or_default(),
                    tcp_listen: self.tcp_listen(rt.tcp_listen)?,
                    max_commands_per_cycle: self.max_commands_per_cycle(rt.max_commands_per_cycle)?,
                    tcp_token: self.tcp_token(rt.tcp_token)?,
                    $($(
                        $module: match rt.$module {
                            None => crate::$module::section::$section::default(),
                            Some(raw) => crate::$module::section::$section::check(self, raw)?,
                        },
                    )?)*
                })
            }
        }
    };
}

crate::transports!(transport_sections);

impl Ctx<'_> {
    /// `tcp_listen` (default `127.0.0.1:7400`).
    fn tcp_listen(&self, raw: Option<Spanned<String>>) -> Result<SocketAddr, ConfigLoadError> {
        match raw {
            None => Ok(SocketAddr::from(([127, 0, 0, 1], 7400))),
            Some(s) => s.get_ref().parse().map_err(|e| {
                self.invalid(
                    s.span(),
                    "transport.tcp_listen",
                    format!(
                        "{:?} is not an address like 127.0.0.1:7400 ({e})",
                        s.get_ref()
                    ),
                )
            }),
        }
    }

    /// `max_commands_per_cycle` (default 64).
    fn max_commands_per_cycle(&self, raw: Option<Spanned<i64>>) -> Result<u32, ConfigLoadError> {
        let Some(v) = raw else {
            return Ok(64);
        };
        let n = *v.get_ref();
        if !(1..=4096).contains(&n) {
            return Err(self.invalid(
                v.span(),
                "transport.max_commands_per_cycle",
                format!("must be 1..=4096, found {n}"),
            ));
        }
        Ok(n as u32)
    }

    /// `tcp_token` (default: none).
    fn tcp_token(&self, raw: Option<Spanned<String>>) -> Result<Option<String>, ConfigLoadError> {
        let Some(t) = raw else {
            return Ok(None);
        };
        let len = t.get_ref().len();
        if len == 0 || len > MAX_TOKEN {
            return Err(self.invalid(
                t.span(),
                "transport.tcp_token",
                format!("must be 1..={} bytes, found {len}", MAX_TOKEN),
            ));
        }
        Ok(Some(t.into_inner()))
    }
}

/// `[transport]` and the transports' sections.
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
    transport.write_sections(s);
}
