//! `[transport.zenoh]`: the zenoh transport's config section — its typed form, what serde
//! reads, its checks and its text. Compiled with and without the `zenoh` feature: a config
//! reads the same in every build.

use std::ops::Range;
use std::path::{Path, PathBuf};
use std::time::Duration;

use serde::Deserialize;
use toml::Spanned;

use crate::config::ctx::{Ctx, toml_string};
use crate::config::error::ConfigLoadError;
use crate::wire::MAX_TOKEN;

/// Default of `[transport.zenoh] listen` and `connect`.
pub const DEFAULT_ZENOH_ENDPOINT: &str = "tcp/127.0.0.1:7447";

/// `[transport.zenoh]` section: how the host and its zenoh agents find each other.
#[derive(Debug, Clone, PartialEq)]
pub struct ZenohConfig {
    /// Endpoints the host listens on (`listen`), e.g. `tcp/0.0.0.0:7447`.
    pub listen: Vec<String>,
    /// Endpoints agents connect to (`connect`; default: `listen`).
    pub connect: Vec<String>,
    /// How long a silent link lives before zenoh closes it (`lease`): bounds how fast a
    /// pulled cable evicts an agent, and how fast an agent notices its host is gone.
    pub lease: Duration,
    /// Multicast and gossip scouting (`scouting`; default off: only explicit endpoints).
    pub scouting: bool,
    /// Shared secret zenoh agents present in their hello (`token`); `None`: none.
    pub token: Option<String>,
    /// TLS of `tls/` endpoints (`tls_ca`, `tls_cert`, `tls_key`, `mtls`); all unset and
    /// false by default.
    pub tls: ZenohTls,
}

/// Certificates of the zenoh transport's `tls/` endpoints. Paths are resolved against
/// the config file's folder at load and checked to exist.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ZenohTls {
    /// PEM certificate of the CA that signed the host's certificate (and, with `mtls`,
    /// the agents'): agents check the host against it, the host checks agents (`tls_ca`).
    pub ca: Option<PathBuf>,
    /// PEM certificate of this side (`tls_cert`): the host's, served to agents; an
    /// agent's, shown to the host with `mtls`.
    pub cert: Option<PathBuf>,
    /// PEM private key of `cert` (`tls_key`).
    pub key: Option<PathBuf>,
    /// Mutual TLS (`mtls`): the host admits only peers with a certificate signed by `ca`.
    pub mtls: bool,
}

impl Default for ZenohConfig {
    fn default() -> Self {
        Self {
            listen: vec![DEFAULT_ZENOH_ENDPOINT.into()],
            connect: vec![DEFAULT_ZENOH_ENDPOINT.into()],
            lease: Duration::from_secs(2),
            scouting: false,
            token: None,
            tls: ZenohTls::default(),
        }
    }
}

impl ZenohConfig {
    /// Checks `[transport.zenoh]` as read (`rz`), with its defaults.
    pub(crate) fn check(ctx: &Ctx<'_>, mut rz: RawZenoh) -> Result<Self, ConfigLoadError> {
        let tls_raw = RawTls {
            ca: rz.tls_ca.take(),
            cert: rz.tls_cert.take(),
            key: rz.tls_key.take(),
            mtls: rz.mtls.take(),
            listen: rz.listen.as_ref().map(Spanned::span),
            connect: rz.connect.as_ref().map(Spanned::span),
        };
        let endpoints = |v: Spanned<Vec<String>>, key: &str| {
            let span = v.span();
            let list = v.into_inner();
            if list.is_empty() || list.len() > 16 {
                return Err(ctx.invalid(
                    span.clone(),
                    key,
                    format!("must list 1 to 16 endpoints, found {}", list.len()),
                ));
            }
            for e in &list {
                if let Err(reason) = check_zenoh_endpoint(e) {
                    return Err(ctx.invalid(span.clone(), key, reason));
                }
            }
            Ok(list)
        };
        let listen = match rz.listen {
            Some(v) => endpoints(v, "transport.zenoh.listen")?,
            None => vec![DEFAULT_ZENOH_ENDPOINT.into()],
        };
        let connect = match rz.connect {
            Some(v) => endpoints(v, "transport.zenoh.connect")?,
            None => listen.clone(),
        };
        let lease = ctx.seconds(rz.lease, "transport.zenoh.lease", 2.0)?;
        if !(0.1..=3600.0).contains(&lease.as_secs_f64()) {
            return Err(ConfigLoadError::Invalid {
                path: ctx.path.to_path_buf(),
                line: 1,
                key: "transport.zenoh.lease".into(),
                reason: format!(
                    "must be 0.1..=3600 seconds, found {:?}",
                    lease.as_secs_f64()
                ),
            });
        }
        let token = match rz.token {
            None => None,
            Some(t) => {
                let len = t.get_ref().len();
                if len == 0 || len > MAX_TOKEN {
                    return Err(ctx.invalid(
                        t.span(),
                        "transport.zenoh.token",
                        format!("must be 1..={MAX_TOKEN} bytes, found {len}"),
                    ));
                }
                Some(t.into_inner())
            }
        };
        let tls = tls(ctx, tls_raw, &listen, &connect)?;
        Ok(Self {
            listen,
            connect,
            lease,
            scouting: rz.scouting.unwrap_or(false),
            token,
            tls,
        })
    }

    /// Forgets the shared secret, `token` (for `TransportConfig::forget_secrets`).
    pub(crate) fn forget_secrets(&mut self) {
        self.token = None;
    }

    /// `[transport.zenoh]` as TOML, appended to `s`.
    pub(crate) fn write_toml(&self, s: &mut String) {
        use std::fmt::Write;
        let z = self;
        let list = |l: &[String]| {
            l.iter()
                .map(|e| toml_string(e))
                .collect::<Vec<_>>()
                .join(", ")
        };
        let _ = writeln!(
            s,
            "\n[transport.zenoh]\nlisten = [{}]\nconnect = [{}]\nlease = {:?}\nscouting = {}",
            list(&z.listen),
            list(&z.connect),
            z.lease.as_secs_f64(),
            z.scouting
        );
        if let Some(token) = &z.token {
            let _ = writeln!(s, "token = {}", toml_string(token));
        }
        for (name, path) in [
            ("tls_ca", &z.tls.ca),
            ("tls_cert", &z.tls.cert),
            ("tls_key", &z.tls.key),
        ] {
            if let Some(p) = path {
                let _ = writeln!(s, "{name} = {}", toml_string(&p.to_string_lossy()));
            }
        }
        let _ = writeln!(s, "mtls = {}", z.tls.mtls);
    }
}

/// `tls_ca`, `tls_cert`, `tls_key` and `mtls`: each file exists; a `tls/` listen
/// endpoint has a certificate and key (and the CA with `mtls`), a `tls/` connect
/// endpoint the CA (and a certificate and key with `mtls`); TLS settings without any
/// `tls/` endpoint are refused (the traffic would be in the clear).
fn tls(
    ctx: &Ctx<'_>,
    rz: RawTls,
    listen: &[String],
    connect: &[String],
) -> Result<ZenohTls, ConfigLoadError> {
    let base = ctx.path.parent().unwrap_or(Path::new(""));
    let file = |v: &Option<Spanned<String>>, name: &str| -> Result<_, ConfigLoadError> {
        let Some(v) = v else { return Ok(None) };
        let key = format!("transport.zenoh.{name}");
        let given = v.get_ref();
        if given.is_empty() {
            return Err(ctx.invalid(v.span(), &key, "must name a PEM file, found \"\""));
        }
        let path = base.join(given);
        // Absolute: a config written back (`to_toml_string`) elsewhere names the same file.
        let path = std::path::absolute(&path).unwrap_or(path);
        if !path.is_file() {
            return Err(ctx.invalid(
                v.span(),
                &key,
                format!(
                    "{} is not a readable file (relative paths are resolved against the \
                     config file's folder)",
                    path.display()
                ),
            ));
        }
        Ok(Some(path))
    };
    let tls = ZenohTls {
        ca: file(&rz.ca, "tls_ca")?,
        cert: file(&rz.cert, "tls_cert")?,
        key: file(&rz.key, "tls_key")?,
        mtls: rz.mtls.as_ref().is_some_and(|m| *m.get_ref()),
    };
    let is_tls = |l: &[String]| l.iter().any(|e| e.starts_with("tls/"));
    let (tls_listen, tls_connect) = (is_tls(listen), is_tls(connect));
    // The span of the endpoint list that needs a file, for the line of the error.
    let span = |v: &Option<Range<usize>>| v.clone().unwrap_or(0..0);
    let need = |has: bool, name: &str, side: &str, why: &str| {
        if has {
            return Ok(());
        }
        let (key, at) = if side == "listen" {
            ("transport.zenoh.listen", span(&rz.listen))
        } else if rz.connect.is_some() {
            ("transport.zenoh.connect", span(&rz.connect))
        } else {
            ("transport.zenoh.listen", span(&rz.listen))
        };
        Err(ctx.invalid(
            at,
            key,
            format!(
                "a tls/ {side} endpoint needs `{name}` in [transport.zenoh] ({why}); \
                 see the README's \"Agents on other machines\" for making them"
            ),
        ))
    };
    if tls_listen {
        let cert = "the host's PEM certificate, signed by tls_ca";
        need(tls.cert.is_some(), "tls_cert", "listen", cert)?;
        need(
            tls.key.is_some(),
            "tls_key",
            "listen",
            "the host's PEM private key",
        )?;
        if tls.mtls {
            let ca = "with mtls the CA the agents' certificates are checked against";
            need(tls.ca.is_some(), "tls_ca", "listen", ca)?;
        }
    }
    if tls_connect {
        let ca = "the PEM certificate of the CA that signed the host's certificate";
        need(tls.ca.is_some(), "tls_ca", "connect", ca)?;
        if tls.mtls {
            let cert = "with mtls the agent's PEM certificate, signed by tls_ca";
            need(tls.cert.is_some(), "tls_cert", "connect", cert)?;
            let key = "with mtls the agent's PEM private key";
            need(tls.key.is_some(), "tls_key", "connect", key)?;
        }
    }
    if !tls_listen && !tls_connect {
        let set = [
            ("tls_ca", rz.ca.as_ref().map(Spanned::span)),
            ("tls_cert", rz.cert.as_ref().map(Spanned::span)),
            ("tls_key", rz.key.as_ref().map(Spanned::span)),
            (
                "mtls",
                rz.mtls.as_ref().filter(|m| *m.get_ref()).map(Spanned::span),
            ),
        ];
        if let Some((name, Some(at))) = set.into_iter().find(|(_, s)| s.is_some()) {
            return Err(ctx.invalid(
                at,
                &format!("transport.zenoh.{name}"),
                "is set, but no listen or connect endpoint is tls/: the traffic would \
                 be in the clear; use endpoints like \"tls/192.168.1.10:7447\"",
            ));
        }
    }
    Ok(tls)
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawZenoh {
    pub(crate) listen: Option<Spanned<Vec<String>>>,
    pub(crate) connect: Option<Spanned<Vec<String>>>,
    pub(crate) lease: Option<Spanned<f64>>,
    pub(crate) scouting: Option<bool>,
    pub(crate) token: Option<Spanned<String>>,
    pub(crate) tls_ca: Option<Spanned<String>>,
    pub(crate) tls_cert: Option<Spanned<String>>,
    pub(crate) tls_key: Option<Spanned<String>>,
    pub(crate) mtls: Option<Spanned<bool>>,
}

/// The TLS keys of `[transport.zenoh]`, and where its endpoint lists are (for errors).
struct RawTls {
    ca: Option<Spanned<String>>,
    cert: Option<Spanned<String>>,
    key: Option<Spanned<String>>,
    mtls: Option<Spanned<bool>>,
    listen: Option<Range<usize>>,
    connect: Option<Range<usize>>,
}

/// Checks a zenoh endpoint of this build: `tcp/<host>:<port>` or `tls/<host>:<port>`
/// (only TCP and TLS links are compiled in), port 1..=65535.
fn check_zenoh_endpoint(e: &str) -> Result<(), String> {
    let hint = "use an endpoint like \"tcp/192.168.1.10:7447\" or \"tls/192.168.1.10:7447\" \
                (only tcp/ and tls/ links are built in)";
    let Some(addr) = e.strip_prefix("tcp/").or_else(|| e.strip_prefix("tls/")) else {
        return Err(format!("{e:?} is not a tcp/ or tls/ endpoint: {hint}"));
    };
    let addr = addr.split('#').next().unwrap_or(addr);
    let port = addr
        .rsplit_once(':')
        .map(|(host, port)| (host, port.parse::<u16>()));
    match port {
        Some((host, Ok(p))) if !host.is_empty() && p != 0 => Ok(()),
        _ => Err(format!("{e:?} has no host and port 1..=65535: {hint}")),
    }
}
