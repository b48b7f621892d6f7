//! Checks: the raw values of a config file into a typed [`Config`](super::Config), one
//! step per section; every error names the file, the line and the dotted key.

use std::collections::BTreeSet;
use std::net::SocketAddr;
use std::ops::Range;
use std::path::Path;
use std::time::Duration;

use toml::Spanned;

use super::raw::{RawAgent, RawCamera, RawConfig, RawLegacy, RawSync, RawTransport, RawZenoh};
use super::{
    AgentConfig, CameraConfig, ConfigLoadError, DEFAULT_RESUME_WINDOW_S,
    DEFAULT_SPIN_BEFORE_BLOCK_US, DEFAULT_ZENOH_ENDPOINT, LegacyConfig, MAX_AGENT_ID,
    MAX_IMAGE_SIDE_PX, SyncConfig, TransportConfig, TransportKind, WaitForStop, ZenohConfig,
    ZenohTls, derived_height,
};
use crate::wire::{CAMERA_NAME_LEN, MAX_CAMERAS, MAX_TOKEN, PixelFormat};

/// The file being checked: its path (named in errors) and text (for line numbers).
pub(super) struct Ctx<'a> {
    pub(super) path: &'a Path,
    pub(super) text: &'a str,
}

impl Ctx<'_> {
    fn line_of(&self, span: Range<usize>) -> usize {
        let end = span.start.min(self.text.len());
        self.text.as_bytes()[..end]
            .iter()
            .filter(|&&b| b == b'\n')
            .count()
            + 1
    }

    pub(super) fn invalid(
        &self,
        span: Range<usize>,
        key: &str,
        reason: impl Into<String>,
    ) -> ConfigLoadError {
        ConfigLoadError::Invalid {
            path: self.path.to_path_buf(),
            line: self.line_of(span),
            key: key.to_string(),
            reason: reason.into(),
        }
    }

    fn zenoh(&self, mut rz: RawZenoh) -> Result<ZenohConfig, ConfigLoadError> {
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
                return Err(self.invalid(
                    span.clone(),
                    key,
                    format!("must list 1 to 16 endpoints, found {}", list.len()),
                ));
            }
            for e in &list {
                if let Err(reason) = check_zenoh_endpoint(e) {
                    return Err(self.invalid(span.clone(), key, reason));
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
        let lease = self.seconds(rz.lease, "transport.zenoh.lease", 2.0)?;
        if !(0.1..=3600.0).contains(&lease.as_secs_f64()) {
            return Err(ConfigLoadError::Invalid {
                path: self.path.to_path_buf(),
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
                    return Err(self.invalid(
                        t.span(),
                        "transport.zenoh.token",
                        format!("must be 1..={MAX_TOKEN} bytes, found {len}"),
                    ));
                }
                Some(t.into_inner())
            }
        };
        let tls = self.zenoh_tls(tls_raw, &listen, &connect)?;
        Ok(ZenohConfig {
            listen,
            connect,
            lease,
            scouting: rz.scouting.unwrap_or(false),
            token,
            tls,
        })
    }

    /// `tls_ca`, `tls_cert`, `tls_key` and `mtls`: each file exists; a `tls/` listen
    /// endpoint has a certificate and key (and the CA with `mtls`), a `tls/` connect
    /// endpoint the CA (and a certificate and key with `mtls`); TLS settings without any
    /// `tls/` endpoint are refused (the traffic would be in the clear).
    fn zenoh_tls(
        &self,
        rz: RawTls,
        listen: &[String],
        connect: &[String],
    ) -> Result<ZenohTls, ConfigLoadError> {
        let base = self.path.parent().unwrap_or(Path::new(""));
        let file = |v: &Option<Spanned<String>>, name: &str| -> Result<_, ConfigLoadError> {
            let Some(v) = v else { return Ok(None) };
            let key = format!("transport.zenoh.{name}");
            let given = v.get_ref();
            if given.is_empty() {
                return Err(self.invalid(v.span(), &key, "must name a PEM file, found \"\""));
            }
            let path = base.join(given);
            // Absolute: a config written back (`to_toml_string`) elsewhere names the same file.
            let path = std::path::absolute(&path).unwrap_or(path);
            if !path.is_file() {
                return Err(self.invalid(
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
            Err(self.invalid(
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
                return Err(self.invalid(
                    at,
                    &format!("transport.zenoh.{name}"),
                    "is set, but no listen or connect endpoint is tls/: the traffic would \
                     be in the clear; use endpoints like \"tls/192.168.1.10:7447\"",
                ));
            }
        }
        Ok(tls)
    }

    fn seconds(
        &self,
        value: Option<Spanned<f64>>,
        key: &str,
        default: f64,
    ) -> Result<Duration, ConfigLoadError> {
        let Some(v) = value else {
            return Ok(Duration::from_secs_f64(default));
        };
        let (span, secs) = (v.span(), *v.get_ref());
        if !secs.is_finite() || secs <= 0.0 {
            return Err(self.invalid(
                span,
                key,
                format!("must be a positive number of seconds, found {secs}"),
            ));
        }
        if secs > 86_400.0 {
            return Err(self.invalid(span, key, format!("{secs} s is more than a day")));
        }
        Ok(Duration::from_secs_f64(secs))
    }
}

impl Ctx<'_> {
    fn legacy(&self, l: RawLegacy) -> Result<LegacyConfig, ConfigLoadError> {
        let d = LegacyConfig::default();
        let local_port = match l.local_port {
            None => d.local_port,
            Some(v) => {
                let p = *v.get_ref();
                // The highest agent port must exist too: local_port + 1 + MAX_AGENT_ID.
                let max = i64::from(u16::MAX) - 1 - i64::from(MAX_AGENT_ID);
                if !(1..=max).contains(&p) {
                    return Err(self.invalid(
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
                self.invalid(
                    s.span(),
                    "transport.legacy.bind",
                    format!(
                        "{:?} is not an IP address like 127.0.0.1 ({e})",
                        s.get_ref()
                    ),
                )
            })?,
        };
        Ok(LegacyConfig {
            local_port,
            bind,
            dialect: l.dialect.unwrap_or(d.dialect),
            png_compression: l.png_compression.unwrap_or(d.png_compression),
            send_eye_position: l.send_eye_position.unwrap_or(d.send_eye_position),
            send_head_motion: l.send_head_motion.unwrap_or(d.send_head_motion),
        })
    }
}

impl Ctx<'_> {
    /// Parses the text into the raw structs; a syntax error, a wrong type or an unknown
    /// key names its line, column and key.
    pub(super) fn parse(&self) -> Result<RawConfig, ConfigLoadError> {
        let (text, path) = (self.text, self.path);
        toml::from_str(text).map_err(|e| {
            let (line, column) = match e.span() {
                Some(span) => {
                    let line = self.line_of(span.clone());
                    let line_start = text[..span.start.min(text.len())]
                        .rfind('\n')
                        .map_or(0, |i| i + 1);
                    (line, span.start.saturating_sub(line_start) + 1)
                }
                None => (1, 1),
            };
            ConfigLoadError::Parse {
                path: path.to_path_buf(),
                line,
                column,
                key: key_at_line(text, line),
                message: e.message().trim().to_string(),
            }
        })
    }

    /// `session`: 1 to 64 characters from `A-Z a-z 0-9 - _ .` (default `"default"`).
    pub(super) fn session(
        &self,
        session: Option<Spanned<String>>,
    ) -> Result<String, ConfigLoadError> {
        let Some(s) = session else {
            return Ok("default".to_string());
        };
        let span = s.span();
        let s = s.into_inner();
        if !valid_session(&s) {
            return Err(self.invalid(
                span,
                "session",
                format!("{s:?}: use 1 to 64 characters from A-Z a-z 0-9 - _ ."),
            ));
        }
        Ok(s)
    }

    /// The `[sync]` section, with its defaults.
    pub(super) fn sync(&self, rs: Option<RawSync>) -> Result<SyncConfig, ConfigLoadError> {
        let rs = rs.unwrap_or_default();
        Ok(SyncConfig {
            sync_mode: rs.sync_mode.unwrap_or(true),
            simulation_time_per_frame: self.seconds(
                rs.simulation_time_per_frame,
                "sync.simulation_time_per_frame",
                0.1,
            )?,
            stop_timeout: self.seconds(rs.stop_timeout, "sync.stop_timeout", 5.0)?,
            connect_timeout: self.seconds(rs.connect_timeout, "sync.connect_timeout", 30.0)?,
            wait: rs.wait.unwrap_or_default(),
            spin_before_block: match rs.spin_before_block_us {
                None => Duration::from_micros(DEFAULT_SPIN_BEFORE_BLOCK_US),
                Some(v) => {
                    let us = *v.get_ref();
                    if !(0..=10_000).contains(&us) {
                        return Err(self.invalid(
                            v.span(),
                            "sync.spin_before_block_us",
                            format!("must be 0..=10000 microseconds, found {us}"),
                        ));
                    }
                    Duration::from_micros(us as u64)
                }
            },
            on_agent_lost: rs.on_agent_lost.unwrap_or_default(),
            wait_for_stop: rs.wait_for_stop,
            resume_window: match rs.resume_window {
                // Zero turns resuming off: a lost link ends the agent's connection.
                Some(v) if *v.get_ref() == 0.0 => Duration::ZERO,
                v => self.seconds(v, "sync.resume_window", DEFAULT_RESUME_WINDOW_S)?,
            },
        })
    }

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
            Some(l) => self.legacy(l)?,
        };
        let zenoh = match rt.zenoh {
            None => ZenohConfig::default(),
            Some(rz) => self.zenoh(rz)?,
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

    /// The `[[agent]]` entries, sorted by id: at least one, ids unique; an agent's
    /// `transport` and `wait_for_stop` default from `[transport] kind` and `[sync]`.
    pub(super) fn agents(
        &self,
        raw: Vec<Spanned<RawAgent>>,
        sync: &SyncConfig,
        kind: TransportKind,
    ) -> Result<Vec<AgentConfig>, ConfigLoadError> {
        if raw.is_empty() {
            return Err(ConfigLoadError::Invalid {
                path: self.path.to_path_buf(),
                line: 1,
                key: "agent".into(),
                reason: "no [[agent]] entries: at least one agent is needed".into(),
            });
        }
        let mut seen = BTreeSet::new();
        let mut agents = Vec::with_capacity(raw.len());
        for a in raw {
            agents.push(self.agent(a, &mut seen, sync, kind)?);
        }
        agents.sort_by_key(|a| a.id);
        Ok(agents)
    }

    /// One `[[agent]]` entry; `seen` holds the ids of the entries before it.
    fn agent(
        &self,
        a: Spanned<RawAgent>,
        seen: &mut BTreeSet<u32>,
        sync: &SyncConfig,
        kind: TransportKind,
    ) -> Result<AgentConfig, ConfigLoadError> {
        let agent_span = a.span();
        let a = a.into_inner();
        let id = *a.id.get_ref();
        if !(0..=i64::from(MAX_AGENT_ID)).contains(&id) {
            return Err(self.invalid(
                a.id.span(),
                "agent.id",
                format!("must be 0..={MAX_AGENT_ID}, found {id}"),
            ));
        }
        let id = id as u32;
        if !seen.insert(id) {
            return Err(self.invalid(a.id.span(), "agent.id", format!("duplicate agent id {id}")));
        }
        if a.camera.len() > MAX_CAMERAS {
            return Err(self.invalid(
                agent_span,
                "agent.camera",
                format!(
                    "agent {id} has {} cameras, at most {MAX_CAMERAS}",
                    a.camera.len()
                ),
            ));
        }
        let mut names = BTreeSet::new();
        let mut cameras = Vec::with_capacity(a.camera.len());
        for c in a.camera {
            let cam = self.camera(c.into_inner(), id, &mut names)?;
            cameras.push(cam);
        }
        let transport = a.transport.unwrap_or(kind);
        let has_channels = !a.vector.is_empty() || !a.action.is_empty();
        let vectors = self.vectors(a.vector, id)?;
        let actions = self.actions(a.action, id)?;
        if has_channels && transport == TransportKind::Legacy {
            return Err(self.invalid(
                agent_span,
                "agent.transport",
                format!(
                    "agent {id} is served over the original protocol (legacy), which has no \
                     channels: remove its [[agent.vector]] / [[agent.action]] entries or \
                     give it another transport"
                ),
            ));
        }
        Ok(AgentConfig {
            id,
            transport,
            wait_for_stop: a
                .wait_for_stop
                .unwrap_or_else(|| WaitForStop::default_for(sync.wait_for_stop, transport)),
            cameras,
            vectors,
            actions,
        })
    }
}

impl Ctx<'_> {
    fn camera(
        &self,
        c: RawCamera,
        agent: u32,
        names: &mut BTreeSet<String>,
    ) -> Result<CameraConfig, ConfigLoadError> {
        let name = c.name.get_ref().clone();
        if name.is_empty() || name.len() > CAMERA_NAME_LEN {
            return Err(self.invalid(
                c.name.span(),
                "agent.camera.name",
                format!("{name:?}: must be 1 to {CAMERA_NAME_LEN} bytes"),
            ));
        }
        if !names.insert(name.clone()) {
            return Err(self.invalid(
                c.name.span(),
                "agent.camera.name",
                format!("agent {agent} has two cameras named {name:?}"),
            ));
        }
        let fov_h = *c.fov_horizontal_deg.get_ref();
        let fov_v = *c.fov_vertical_deg.get_ref();
        for (v, key) in [
            (&c.fov_horizontal_deg, "agent.camera.fov_horizontal_deg"),
            (&c.fov_vertical_deg, "agent.camera.fov_vertical_deg"),
        ] {
            let deg = *v.get_ref();
            if !(deg > 0.0 && deg < 180.0) {
                return Err(self.invalid(
                    v.span(),
                    key,
                    format!("must be in (0, 180) degrees, found {deg}"),
                ));
            }
        }
        let side = |v: &Spanned<i64>, key: &str| -> Result<u32, ConfigLoadError> {
            let n = *v.get_ref();
            if !(1..=i64::from(MAX_IMAGE_SIDE_PX)).contains(&n) {
                return Err(self.invalid(
                    v.span(),
                    key,
                    format!("must be 1..={MAX_IMAGE_SIDE_PX} pixels, found {n}"),
                ));
            }
            Ok(n as u32)
        };
        let width_px = side(&c.width, "agent.camera.width")?;
        let height_px = match &c.height {
            Some(h) => side(h, "agent.camera.height")?,
            // The original derived the height from the fields of view.
            None => derived_height(width_px, fov_h, fov_v),
        };
        let format = match &c.format {
            None => PixelFormat::Rgb8,
            Some(f) => match f.get_ref().as_str() {
                "rgb8" => PixelFormat::Rgb8,
                "rgba8" => PixelFormat::Rgba8,
                "gray8" => PixelFormat::Gray8,
                "depth32f" => PixelFormat::Depth32f,
                other => {
                    return Err(self.invalid(
                        f.span(),
                        "agent.camera.format",
                        format!("{other:?}: expected one of rgb8, rgba8, gray8, depth32f"),
                    ));
                }
            },
        };
        Ok(CameraConfig {
            name,
            width_px,
            height_px,
            format,
            fov_horizontal_deg: fov_h as f32,
            fov_vertical_deg: fov_v as f32,
        })
    }
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

/// Whether `s` is a valid session name: 1 to 64 characters from `A-Z a-z 0-9 - _ .`.
pub(super) fn valid_session(s: &str) -> bool {
    !s.is_empty()
        && s.len() <= 64
        && s.bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_' || b == b'.')
}

/// The dotted key written on 1-based `line` of `text`: the last table header above it plus
/// the key before `=` (e.g. `sync.stop_timeout`), or the table name on a header line.
fn key_at_line(text: &str, line: usize) -> String {
    let mut table = String::new();
    for (i, raw) in text.lines().enumerate() {
        let l = raw.trim();
        if l.starts_with('[') {
            table = l.trim_matches(|c| c == '[' || c == ']').trim().to_string();
        }
        if i + 1 == line {
            if l.starts_with('[') {
                return table;
            }
            let key = l.split('=').next().unwrap_or("").trim();
            return match (table.is_empty(), key.is_empty()) {
                (_, true) => "?".to_string(),
                (true, false) => key.to_string(),
                (false, false) => format!("{table}.{key}"),
            };
        }
    }
    "?".to_string()
}
