//! `[transport.legacy]`: the original protocol's config section — its typed form, what
//! serde reads, its checks and its text. Here, beside the registry's legacy entry, because
//! the config reads it in every build; the host that serves it is the `vrsync-legacy`
//! crate.

use serde::Deserialize;
use toml::Spanned;

use crate::config::ctx::{Ctx, MAX_AGENT_ID};
use crate::config::error::ConfigLoadError;

/// Which generation of the original protocol a legacy agent speaks
/// (`[transport.legacy] dialect`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum LegacyDialect {
    /// Told from each connection's version check (default).
    #[default]
    Auto,
    /// The older (Python 2) clients: version check in field 28.
    Vrnew,
    /// The later (Python 3) client: version check in field 29, a third "main" image.
    Burkhardt,
}

impl LegacyDialect {
    /// The config spelling.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Auto => "auto",
            Self::Vrnew => "vrnew",
            Self::Burkhardt => "burkhardt",
        }
    }
}

/// PNG compression of the legacy transport's images (`[transport.legacy] png_compression`),
/// the `png` crate's levels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum PngCompression {
    /// The fastest (default): the images are encoded every cycle.
    #[default]
    Fastest,
    /// Fast, a better ratio.
    Fast,
    /// Balanced.
    Balanced,
    /// Smallest, slowest.
    High,
}

impl PngCompression {
    /// The config spelling.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Fastest => "fastest",
            Self::Fast => "fast",
            Self::Balanced => "balanced",
            Self::High => "high",
        }
    }
}

/// `[transport.legacy]` section: the original system's protobuf/TCP protocol.
#[derive(Debug, Clone, PartialEq)]
pub struct LegacyConfig {
    /// The environment socket's port (`local_port`, alias `LocalPort`); agent `id` listens
    /// on `local_port + 1 + id`. Default 1337.
    pub local_port: u16,
    /// The address the sockets bind to (`bind`). Default loopback.
    pub bind: std::net::IpAddr,
    /// The dialect (`dialect`). Default auto.
    pub dialect: LegacyDialect,
    /// PNG compression (`png_compression`). Default fastest.
    pub png_compression: PngCompression,
    /// Send EyePosition every cycle (`send_eye_position`). Default false, as the original.
    pub send_eye_position: bool,
    /// Send HeadMotion every cycle (`send_head_motion`). Default false, as the original.
    pub send_head_motion: bool,
}

impl Default for LegacyConfig {
    fn default() -> Self {
        Self {
            local_port: 1337,
            bind: std::net::IpAddr::from([127, 0, 0, 1]),
            dialect: LegacyDialect::Auto,
            png_compression: PngCompression::Fastest,
            send_eye_position: false,
            send_head_motion: false,
        }
    }
}

impl LegacyConfig {
    /// Checks `[transport.legacy]` as read (`l`), with its defaults.
    pub(crate) fn check(ctx: &Ctx<'_>, l: RawLegacy) -> Result<Self, ConfigLoadError> {
        let d = LegacyConfig::default();
        let local_port = match l.local_port {
            None => d.local_port,
            Some(v) => {
                let p = *v.get_ref();
                // The highest agent port must exist too: local_port + 1 + MAX_AGENT_ID.
                let max = i64::from(u16::MAX) - 1 - i64::from(MAX_AGENT_ID);
                if !(1..=max).contains(&p) {
                    return Err(ctx.invalid(
                        v.span(),
                        "transport.legacy.local_port",
                        format!("must be 1..={max} (agent ports follow it), found {p}"),
                    ));
                }
                p as u16
            }
        };
        let bind = match l.bind {
            None => d.bind,
            Some(s) => s.get_ref().parse().map_err(|e| {
                ctx.invalid(
                    s.span(),
                    "transport.legacy.bind",
                    format!(
                        "{:?} is not an IP address like 127.0.0.1 ({e})",
                        s.get_ref()
                    ),
                )
            })?,
        };
        Ok(Self {
            local_port,
            bind,
            dialect: l.dialect.unwrap_or(d.dialect),
            png_compression: l.png_compression.unwrap_or(d.png_compression),
            send_eye_position: l.send_eye_position.unwrap_or(d.send_eye_position),
            send_head_motion: l.send_head_motion.unwrap_or(d.send_head_motion),
        })
    }

    /// The section has no secrets (for `TransportConfig::forget_secrets`).
    pub(crate) fn forget_secrets(&mut self) {}

    /// `[transport.legacy]` as TOML, appended to `s`.
    pub(crate) fn write_toml(&self, s: &mut String) {
        use std::fmt::Write;
        let l = self;
        let _ = writeln!(
            s,
            "\n[transport.legacy]\nlocal_port = {}\nbind = \"{}\"\ndialect = {:?}\npng_compression = {:?}\nsend_eye_position = {}\nsend_head_motion = {}",
            l.local_port,
            l.bind,
            l.dialect.as_str(),
            l.png_compression.as_str(),
            l.send_eye_position,
            l.send_head_motion
        );
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawLegacy {
    #[serde(alias = "LocalPort")]
    pub(crate) local_port: Option<Spanned<i64>>,
    pub(crate) bind: Option<Spanned<String>>,
    pub(crate) dialect: Option<LegacyDialect>,
    pub(crate) png_compression: Option<PngCompression>,
    pub(crate) send_eye_position: Option<bool>,
    pub(crate) send_head_motion: Option<bool>,
}
