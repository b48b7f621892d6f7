//! Checks: the raw values of a config file into a typed [`Config`](super::Config), one
//! step per section; every error names the file, the line and the dotted key.

use std::collections::BTreeSet;
use std::time::Duration;

use toml::Spanned;

use super::ctx::Ctx;
use super::raw::{RawAgent, RawCamera, RawConfig, RawSync};
use super::{
    AgentConfig, CameraConfig, ConfigLoadError, DEFAULT_RESUME_WINDOW_S,
    DEFAULT_SPIN_BEFORE_BLOCK_US, MAX_AGENT_ID, MAX_IMAGE_SIDE_PX, SyncConfig, TransportKind,
    WaitForStop, derived_height,
};
use crate::wire::{CAMERA_NAME_LEN, MAX_CAMERAS, PixelFormat};

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

    /// `[transport.shm] stacked_images` (at `span`): every shared-memory agent's payload
    /// has the same layout (cameras and vectors), so that their payloads stack.
    pub(super) fn stacked(
        &self,
        span: core::ops::Range<usize>,
        agents: &[AgentConfig],
    ) -> Result<(), ConfigLoadError> {
        let mut shm = agents.iter().filter(|a| a.transport == TransportKind::Shm);
        let Some(first) = shm.next() else {
            return Ok(());
        };
        let layout = |a: &AgentConfig| (a.image_layout(), a.vector_layout());
        let want = layout(first);
        match shm.find(|a| layout(a) != want) {
            None => Ok(()),
            Some(other) => Err(self.invalid(
                span,
                "transport.shm.stacked_images",
                format!(
                    "the shared-memory agents' images and vectors are stacked, so every such \
                     agent needs the same cameras (names, sizes, formats) and vectors, but \
                     agent {} has other ones than agent {}",
                    other.id, first.id
                ),
            )),
        }
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
        if has_channels && !transport.carries_channels() {
            return Err(self.invalid(
                agent_span,
                "agent.transport",
                format!(
                    "agent {id} is served over the {} transport, which carries no channels: \
                     remove its [[agent.vector]] / [[agent.action]] entries or give it \
                     another transport",
                    transport.as_str()
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
