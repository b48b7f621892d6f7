//! Configuration: TOML → typed, validated [`Config`].
//!
//! Every key is documented in `config/default.toml`. Unknown keys, wrong types and
//! invalid values are rejected with a [`ConfigLoadError`] that names the file, the line
//! and the key. The original system's names `SyncMode` and `SimulationTimePerFrame` are
//! accepted as aliases.

use std::collections::BTreeSet;
use std::net::SocketAddr;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::time::Duration;

use serde::Deserialize;
use toml::Spanned;

use crate::wire::{CAMERA_NAME_LEN, ImageDesc, MAX_CAMERAS, MAX_TOKEN, PixelFormat};

/// Default of `[sync] spin_before_block_us`.
pub const DEFAULT_SPIN_BEFORE_BLOCK_US: u64 = 50;

/// Highest agent id accepted (ids are also iceoryx2 event ids).
pub const MAX_AGENT_ID: u32 = 250;
/// Largest accepted image side in pixels.
pub const MAX_IMAGE_SIDE_PX: u32 = 8192;
/// Largest config file [`Config::load`] reads, bytes.
pub const MAX_CONFIG_BYTES: u64 = 4 << 20;

/// Transport selected by `[transport] kind`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum TransportKind {
    /// iceoryx2 shared memory (default).
    #[default]
    Shm,
    /// TCP, the measured baseline.
    Tcp,
    /// The original system's protobuf/TCP protocol, for agents written for it
    /// (`[transport.legacy]`; see [`crate::legacy`]).
    Legacy,
    /// zenoh, for agents on other machines (`[transport.zenoh]`).
    Zenoh,
}

impl TransportKind {
    /// Every transport, in the order above (the test matrix and the docs take it from
    /// here; a unit test with an exhaustive match keeps it complete).
    pub const ALL: [TransportKind; 4] = [Self::Shm, Self::Tcp, Self::Legacy, Self::Zenoh];

    /// The config spelling.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Shm => "shm",
            Self::Tcp => "tcp",
            Self::Legacy => "legacy",
            Self::Zenoh => "zenoh",
        }
    }
}

/// How waiting parties wait (`[sync] wait`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum WaitMode {
    /// Sleep on the event until woken (default): no CPU while waiting.
    #[default]
    Block,
    /// Busy-poll: lowest latency, one core per waiting process. Only sensible when there
    /// are at least as many free cores as waiting processes.
    Spin,
}

/// What the host does when an agent's process dies or disconnects (`[sync] on_agent_lost`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum AgentLostPolicy {
    /// Stop waiting for it at once and go on with the others; it may rejoin (default).
    #[default]
    Evict,
    /// Pause the simulation until it reconnects (up to `connect_timeout`).
    Wait,
    /// End the run with an error naming the agent.
    Abort,
}

/// How long the host waits for an agent's stop in sync mode (`[sync] wait_for_stop`,
/// per agent `[[agent]] wait_for_stop`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum WaitForStop {
    /// Wait as long as the agent is alive (its transport still has it connected): a busy
    /// agent (a learner updating, a debugger) never costs a stop timeout. Past
    /// `stop_timeout` it is reported as slow (a warning with back-off, counted in
    /// `HostStats::slow_stops`); a dead one is evicted by liveness (default).
    #[default]
    Alive,
    /// End the cycle without the agent after `stop_timeout` (the original system's
    /// behaviour): counted as a stop timeout, its late stop is dropped.
    Timeout,
}

impl WaitForStop {
    /// The policy of an agent on `transport` that does not choose its own, given
    /// `[sync] wait_for_stop` (`None`: not set): `[sync]`'s, else `Alive`, except on the
    /// legacy transport, whose clients (written for the original system) may block on an
    /// action's end before they stop and so rely on the stop timeout: `Timeout` there.
    pub fn default_for(sync: Option<WaitForStop>, transport: TransportKind) -> Self {
        match (sync, transport) {
            (Some(w), _) => w,
            (None, TransportKind::Legacy) => Self::Timeout,
            (None, _) => Self::Alive,
        }
    }

    /// The config spelling.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Alive => "alive",
            Self::Timeout => "timeout",
        }
    }
}

/// One camera of an agent.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraConfig {
    /// Name (≤ 16 bytes), e.g. `left`, `right`, `main`.
    pub name: String,
    /// Width in pixels.
    pub width_px: u32,
    /// Height in pixels (given, or derived from the fields of view).
    pub height_px: u32,
    /// Pixel format.
    pub format: PixelFormat,
    /// Horizontal field of view in degrees.
    pub fov_horizontal_deg: f32,
    /// Vertical field of view in degrees.
    pub fov_vertical_deg: f32,
}

impl CameraConfig {
    /// Bytes per row.
    pub fn stride_bytes(&self) -> usize {
        self.width_px as usize * self.format.bytes_per_pixel()
    }

    /// Bytes of one image.
    pub fn image_bytes(&self) -> usize {
        self.stride_bytes() * self.height_px as usize
    }
}

/// One agent: its id and cameras.
#[derive(Debug, Clone, PartialEq)]
pub struct AgentConfig {
    /// Agent id (`0..=250`).
    pub id: u32,
    /// The transport this agent uses (`[[agent]] transport`, default `[transport] kind`).
    pub transport: TransportKind,
    /// How long the host waits for this agent's stop (`[[agent]] wait_for_stop`, default
    /// `[sync] wait_for_stop`): resolved, so this is the agent's effective policy.
    pub wait_for_stop: WaitForStop,
    /// Cameras, in image order.
    pub cameras: Vec<CameraConfig>,
}

impl AgentConfig {
    /// The image table of this agent's sensor frames and their payload size in bytes
    /// (see [`crate::wire::image_layout`]).
    pub fn image_layout(&self) -> ([ImageDesc; MAX_CAMERAS], usize) {
        crate::wire::image_layout(
            self.cameras
                .iter()
                .map(|c| (c.name.as_str(), c.width_px, c.height_px, c.format)),
        )
    }

    /// Bytes of all images of one sensor frame of this agent.
    pub fn frame_bytes(&self) -> usize {
        self.image_layout().1
    }
}

/// `[sync]` section.
#[derive(Debug, Clone, PartialEq)]
pub struct SyncConfig {
    /// Lock-step mode (`sync_mode`, alias `SyncMode`).
    pub sync_mode: bool,
    /// Simulated time per cycle (`simulation_time_per_frame`, alias `SimulationTimePerFrame`).
    pub simulation_time_per_frame: Duration,
    /// How long the host waits for all stops of a cycle (`stop_timeout`).
    pub stop_timeout: Duration,
    /// How long the host waits for agents to connect, and agents for the host (`connect_timeout`).
    pub connect_timeout: Duration,
    /// Block on events or busy-poll (`wait`).
    pub wait: WaitMode,
    /// In block mode, how long to poll before going to sleep (`spin_before_block_us`).
    pub spin_before_block: Duration,
    /// What to do when an agent is lost (`on_agent_lost`).
    pub on_agent_lost: AgentLostPolicy,
    /// How long to wait for a stop, for agents that do not choose (`wait_for_stop`;
    /// `None`: not set, see [`WaitForStop::default_for`]).
    pub wait_for_stop: Option<WaitForStop>,
}

impl SyncConfig {
    /// The poll-before-sleep time to use with `agents` agents: `spin_before_block`, or zero
    /// when the host and the agents together outnumber the cores (polling would then steal
    /// the CPU from the process that has work to do).
    pub fn effective_spin_before_block(&self, agents: usize) -> Duration {
        let cores = std::thread::available_parallelism().map_or(1, usize::from);
        if agents + 1 > cores {
            Duration::ZERO
        } else {
            self.spin_before_block
        }
    }
}

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
}

impl Default for ZenohConfig {
    fn default() -> Self {
        Self {
            listen: vec![DEFAULT_ZENOH_ENDPOINT.into()],
            connect: vec![DEFAULT_ZENOH_ENDPOINT.into()],
            lease: Duration::from_secs(2),
            scouting: false,
            token: None,
        }
    }
}

/// The validated configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct Config {
    /// Where it was loaded from (`<embedded>` for built-in configs).
    pub source: PathBuf,
    /// Session name: prefixes every service (`vrsync/<session>/…`).
    pub session: String,
    /// Seed of every random choice in the simulator.
    pub seed: u64,
    /// `[sync]`.
    pub sync: SyncConfig,
    /// `[transport]`.
    pub transport: TransportConfig,
    /// `[[agent]]` entries, sorted by id.
    pub agents: Vec<AgentConfig>,
    /// The `[world]` table, left to the simulator to interpret.
    pub world: Option<toml::Table>,
}

/// Why a configuration could not be loaded.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ConfigLoadError {
    /// The file could not be read.
    #[error("cannot read config file {path}: {error}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error (in the message, so not also a `source()`: printed once).
        error: std::io::Error,
    },
    /// TOML syntax error, unknown key or wrong type.
    #[error("{path}:{line}:{column}: {message} (at key `{key}`)")]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
        /// Dotted key at that line (table header + key), `?` if none.
        key: String,
        /// What the TOML parser said (names the key).
        message: String,
    },
    /// A value is out of range or inconsistent.
    #[error("{path}:{line}: invalid `{key}`: {reason}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// 1-based line of the value.
        line: usize,
        /// Dotted key, e.g. `sync.stop_timeout`.
        key: String,
        /// Why it is invalid.
        reason: String,
    },
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawConfig {
    session: Option<Spanned<String>>,
    #[serde(default)]
    seed: u64,
    #[serde(default)]
    sync: Option<RawSync>,
    #[serde(default)]
    transport: Option<RawTransport>,
    #[serde(default)]
    agent: Vec<Spanned<RawAgent>>,
    #[serde(default)]
    world: Option<toml::Table>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSync {
    #[serde(alias = "SyncMode")]
    sync_mode: Option<bool>,
    #[serde(alias = "SimulationTimePerFrame")]
    simulation_time_per_frame: Option<Spanned<f64>>,
    #[serde(alias = "SyncModeFrameTimeOut")]
    stop_timeout: Option<Spanned<f64>>,
    connect_timeout: Option<Spanned<f64>>,
    wait: Option<WaitMode>,
    spin_before_block_us: Option<Spanned<i64>>,
    on_agent_lost: Option<AgentLostPolicy>,
    wait_for_stop: Option<WaitForStop>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTransport {
    kind: Option<TransportKind>,
    tcp_listen: Option<Spanned<String>>,
    max_commands_per_cycle: Option<Spanned<i64>>,
    tcp_token: Option<Spanned<String>>,
    legacy: Option<RawLegacy>,
    zenoh: Option<RawZenoh>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLegacy {
    #[serde(alias = "LocalPort")]
    local_port: Option<Spanned<i64>>,
    bind: Option<Spanned<String>>,
    dialect: Option<LegacyDialect>,
    png_compression: Option<PngCompression>,
    send_eye_position: Option<bool>,
    send_head_motion: Option<bool>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawZenoh {
    listen: Option<Spanned<Vec<String>>>,
    connect: Option<Spanned<Vec<String>>>,
    lease: Option<Spanned<f64>>,
    scouting: Option<bool>,
    token: Option<Spanned<String>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawAgent {
    id: Spanned<i64>,
    transport: Option<TransportKind>,
    wait_for_stop: Option<WaitForStop>,
    #[serde(default)]
    camera: Vec<Spanned<RawCamera>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCamera {
    name: Spanned<String>,
    width: Spanned<i64>,
    height: Option<Spanned<i64>>,
    #[serde(default)]
    format: Option<Spanned<String>>,
    #[serde(default = "default_fov_h")]
    fov_horizontal_deg: Spanned<f64>,
    #[serde(default = "default_fov_v")]
    fov_vertical_deg: Spanned<f64>,
}

fn default_fov_h() -> Spanned<f64> {
    Spanned::new(0..0, 120.0)
}
fn default_fov_v() -> Spanned<f64> {
    Spanned::new(0..0, 90.0)
}

/// Checks a zenoh endpoint of this build: `tcp/<host>:<port>` (only TCP links are
/// compiled in), port 1..=65535.
fn check_zenoh_endpoint(e: &str) -> Result<(), String> {
    let hint = "use an endpoint like \"tcp/192.168.1.10:7447\" (only tcp/ links are built in)";
    let Some(addr) = e.strip_prefix("tcp/") else {
        return Err(format!("{e:?} is not a tcp/ endpoint: {hint}"));
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

/// The built-in default configuration (`config/default.toml`).
pub const DEFAULT_CONFIG_TOML: &str = include_str!("../../config/default.toml");

struct Ctx<'a> {
    path: &'a Path,
    text: &'a str,
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

    fn invalid(&self, span: Range<usize>, key: &str, reason: impl Into<String>) -> ConfigLoadError {
        ConfigLoadError::Invalid {
            path: self.path.to_path_buf(),
            line: self.line_of(span),
            key: key.to_string(),
            reason: reason.into(),
        }
    }

    fn zenoh(&self, rz: RawZenoh) -> Result<ZenohConfig, ConfigLoadError> {
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
        Ok(ZenohConfig {
            listen,
            connect,
            lease,
            scouting: rz.scouting.unwrap_or(false),
            token,
        })
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

impl Config {
    /// Loads and validates a config file.
    ///
    /// # Errors
    /// [`ConfigLoadError`] naming the file, line and key.
    pub fn load(path: impl AsRef<Path>) -> Result<Self, ConfigLoadError> {
        use std::io::Read;
        let path = path.as_ref();
        let read = |error| ConfigLoadError::Read {
            path: path.to_path_buf(),
            error,
        };
        // Bounded: a wrong path (a device, a huge file) fails at once instead of filling
        // memory.
        let mut text = String::new();
        std::fs::File::open(path)
            .and_then(|f| f.take(MAX_CONFIG_BYTES + 1).read_to_string(&mut text))
            .map_err(read)?;
        if text.len() as u64 > MAX_CONFIG_BYTES {
            return Err(read(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                format!(
                    "larger than {} MiB: not a vrsync config",
                    MAX_CONFIG_BYTES >> 20
                ),
            )));
        }
        Self::from_toml_str(&text, path)
    }

    /// The embedded default configuration.
    ///
    /// # Errors
    /// Only if the embedded file is broken, which a unit test rules out.
    pub fn embedded_default() -> Result<Self, ConfigLoadError> {
        Self::from_toml_str(DEFAULT_CONFIG_TOML, Path::new("<embedded default.toml>"))
    }

    /// Parses and validates TOML text; `path` is used in error messages.
    ///
    /// # Errors
    /// [`ConfigLoadError`] naming the file, line and key.
    pub fn from_toml_str(text: &str, path: &Path) -> Result<Self, ConfigLoadError> {
        let ctx = Ctx { path, text };
        let raw: RawConfig = toml::from_str(text).map_err(|e| {
            let (line, column) = match e.span() {
                Some(span) => {
                    let line = ctx.line_of(span.clone());
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
        })?;

        let session = match raw.session {
            None => "default".to_string(),
            Some(s) => {
                let span = s.span();
                let s = s.into_inner();
                if !valid_session(&s) {
                    return Err(ctx.invalid(
                        span,
                        "session",
                        format!("{s:?}: use 1 to 64 characters from A-Z a-z 0-9 - _ ."),
                    ));
                }
                s
            }
        };

        let rs = raw.sync.unwrap_or(RawSync {
            sync_mode: None,
            simulation_time_per_frame: None,
            stop_timeout: None,
            connect_timeout: None,
            wait: None,
            spin_before_block_us: None,
            on_agent_lost: None,
            wait_for_stop: None,
        });
        let sync = SyncConfig {
            sync_mode: rs.sync_mode.unwrap_or(true),
            simulation_time_per_frame: ctx.seconds(
                rs.simulation_time_per_frame,
                "sync.simulation_time_per_frame",
                0.1,
            )?,
            stop_timeout: ctx.seconds(rs.stop_timeout, "sync.stop_timeout", 5.0)?,
            connect_timeout: ctx.seconds(rs.connect_timeout, "sync.connect_timeout", 30.0)?,
            wait: rs.wait.unwrap_or_default(),
            spin_before_block: match rs.spin_before_block_us {
                None => Duration::from_micros(DEFAULT_SPIN_BEFORE_BLOCK_US),
                Some(v) => {
                    let us = *v.get_ref();
                    if !(0..=10_000).contains(&us) {
                        return Err(ctx.invalid(
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
        };

        let rt = raw.transport.unwrap_or(RawTransport {
            kind: None,
            tcp_listen: None,
            max_commands_per_cycle: None,
            tcp_token: None,
            legacy: None,
            zenoh: None,
        });
        let tcp_listen = match rt.tcp_listen {
            None => SocketAddr::from(([127, 0, 0, 1], 7400)),
            Some(s) => s.get_ref().parse().map_err(|e| {
                ctx.invalid(
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
                    return Err(ctx.invalid(
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
                    return Err(ctx.invalid(
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
            Some(l) => ctx.legacy(l)?,
        };
        let zenoh = match rt.zenoh {
            None => ZenohConfig::default(),
            Some(rz) => ctx.zenoh(rz)?,
        };
        let transport = TransportConfig {
            kind: rt.kind.unwrap_or_default(),
            tcp_listen,
            max_commands_per_cycle,
            tcp_token,
            legacy,
            zenoh,
        };

        if raw.agent.is_empty() {
            return Err(ConfigLoadError::Invalid {
                path: path.to_path_buf(),
                line: 1,
                key: "agent".into(),
                reason: "no [[agent]] entries: at least one agent is needed".into(),
            });
        }
        let mut seen = BTreeSet::new();
        let mut agents = Vec::with_capacity(raw.agent.len());
        for a in raw.agent {
            let agent_span = a.span();
            let a = a.into_inner();
            let id = *a.id.get_ref();
            if !(0..=i64::from(MAX_AGENT_ID)).contains(&id) {
                return Err(ctx.invalid(
                    a.id.span(),
                    "agent.id",
                    format!("must be 0..={MAX_AGENT_ID}, found {id}"),
                ));
            }
            let id = id as u32;
            if !seen.insert(id) {
                return Err(ctx.invalid(
                    a.id.span(),
                    "agent.id",
                    format!("duplicate agent id {id}"),
                ));
            }
            if a.camera.len() > MAX_CAMERAS {
                return Err(ctx.invalid(
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
                let cam = ctx.camera(c.into_inner(), id, &mut names)?;
                cameras.push(cam);
            }
            agents.push(AgentConfig {
                id,
                transport: a.transport.unwrap_or(transport.kind),
                wait_for_stop: a.wait_for_stop.unwrap_or_else(|| {
                    WaitForStop::default_for(
                        sync.wait_for_stop,
                        a.transport.unwrap_or(transport.kind),
                    )
                }),
                cameras,
            });
        }
        agents.sort_by_key(|a| a.id);

        let config = Self {
            source: path.to_path_buf(),
            session,
            seed: raw.seed,
            sync,
            transport,
            agents,
            world: raw.world,
        };
        Ok(config)
    }

    /// The agent with this id.
    pub fn agent(&self, id: u32) -> Option<&AgentConfig> {
        self.agents.iter().find(|a| a.id == id)
    }

    /// The effective `wait_for_stop` of agent `id`: its `[[agent]] wait_for_stop`, else
    /// `[sync] wait_for_stop`, else `"alive"` (`"timeout"` for legacy agents; see
    /// [`WaitForStop::default_for`]); for an id not in the config, what an agent on
    /// `[transport] kind` would get.
    pub fn wait_for_stop(&self, id: u32) -> WaitForStop {
        self.agent(id).map_or_else(
            || WaitForStop::default_for(self.sync.wait_for_stop, self.transport.kind),
            |a| a.wait_for_stop,
        )
    }

    /// Whether the host may wait for a stop without limit in this session (sync mode and
    /// some agent's `wait_for_stop = "alive"`): then an agent waiting for its next frame
    /// must not give up after a time derived from `stop_timeout`, since another agent may
    /// be busy for longer (host death is detected by liveness instead).
    pub fn waits_for_live_agents(&self) -> bool {
        self.sync.sync_mode
            && self
                .agents
                .iter()
                .any(|a| a.wait_for_stop == WaitForStop::Alive)
    }

    /// Resizes the agent list to `count` agents with ids `0..count`: existing entries keep
    /// their cameras, new ones copy the cameras of the last configured agent. Used by
    /// `--agents` / `--spawn-agents`.
    ///
    /// # Errors
    /// [`ConfigLoadError::Invalid`] if `count` is 0 or larger than the id space.
    pub fn with_agent_count(mut self, count: u32) -> Result<Self, ConfigLoadError> {
        if count == 0 || count > MAX_AGENT_ID + 1 {
            return Err(ConfigLoadError::Invalid {
                path: self.source.clone(),
                line: 1,
                key: "agent".into(),
                reason: format!(
                    "agent count must be 1..={}, found {count}",
                    MAX_AGENT_ID + 1
                ),
            });
        }
        let template = self
            .agents
            .last()
            .map(|a| a.cameras.clone())
            .unwrap_or_default();
        let mut agents = Vec::with_capacity(count as usize);
        for id in 0..count {
            let (cameras, transport, wait_for_stop) = self.agent(id).map_or_else(
                || {
                    (
                        template.clone(),
                        self.transport.kind,
                        WaitForStop::default_for(self.sync.wait_for_stop, self.transport.kind),
                    )
                },
                |a| (a.cameras.clone(), a.transport, a.wait_for_stop),
            );
            agents.push(AgentConfig {
                id,
                transport,
                wait_for_stop,
                cameras,
            });
        }
        self.agents = agents;
        Ok(self)
    }

    /// Replaces the session name.
    ///
    /// # Errors
    /// [`ConfigLoadError::Invalid`] if the name is not 1 to 64 characters from
    /// `A-Z a-z 0-9 - _ .`.
    pub fn with_session(mut self, session: &str) -> Result<Self, ConfigLoadError> {
        if !valid_session(session) {
            return Err(ConfigLoadError::Invalid {
                path: self.source.clone(),
                line: 1,
                key: "session".into(),
                reason: format!("{session:?}: use 1 to 64 characters from A-Z a-z 0-9 - _ ."),
            });
        }
        self.session = session.to_string();
        Ok(self)
    }

    /// The config as TOML again (for handing the effective config to spawned agents).
    pub fn to_toml_string(&self) -> String {
        use std::fmt::Write;
        let mut s = String::new();
        let _ = writeln!(
            s,
            "# effective vrsync config (generated from {})",
            self.source.display().to_string().escape_debug()
        );
        let _ = writeln!(s, "session = {:?}\nseed = {}", self.session, self.seed);
        let _ = writeln!(
            s,
            "\n[sync]\nsync_mode = {}\nsimulation_time_per_frame = {:?}\nstop_timeout = {:?}\nconnect_timeout = {:?}\nwait = {:?}\nspin_before_block_us = {}\non_agent_lost = {:?}",
            self.sync.sync_mode,
            self.sync.simulation_time_per_frame.as_secs_f64(),
            self.sync.stop_timeout.as_secs_f64(),
            self.sync.connect_timeout.as_secs_f64(),
            match self.sync.wait {
                WaitMode::Block => "block",
                WaitMode::Spin => "spin",
            },
            self.sync.spin_before_block.as_micros(),
            match self.sync.on_agent_lost {
                AgentLostPolicy::Evict => "evict",
                AgentLostPolicy::Wait => "wait",
                AgentLostPolicy::Abort => "abort",
            }
        );
        if let Some(w) = self.sync.wait_for_stop {
            let _ = writeln!(s, "wait_for_stop = {:?}", w.as_str());
        }
        let _ = writeln!(
            s,
            "\n[transport]\nkind = {:?}\ntcp_listen = \"{}\"\nmax_commands_per_cycle = {}",
            self.transport.kind.as_str(),
            self.transport.tcp_listen,
            self.transport.max_commands_per_cycle
        );
        if let Some(token) = &self.transport.tcp_token {
            let _ = writeln!(s, "tcp_token = {}", toml_string(token));
        }
        let l = &self.transport.legacy;
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
        let z = &self.transport.zenoh;
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
        for a in &self.agents {
            let _ = writeln!(
                s,
                "\n[[agent]]\nid = {}\ntransport = {:?}\nwait_for_stop = {:?}",
                a.id,
                a.transport.as_str(),
                a.wait_for_stop.as_str()
            );
            for c in &a.cameras {
                let _ = writeln!(
                    s,
                    "[[agent.camera]]\nname = {}\nwidth = {}\nheight = {}\nformat = {:?}\nfov_horizontal_deg = {:?}\nfov_vertical_deg = {:?}",
                    toml_string(&c.name),
                    c.width_px,
                    c.height_px,
                    c.format.as_str(),
                    f64::from(c.fov_horizontal_deg),
                    f64::from(c.fov_vertical_deg)
                );
            }
        }
        if let Some(world) = &self.world {
            let mut doc = toml::Table::new();
            doc.insert("world".into(), toml::Value::Table(world.clone()));
            if let Ok(text) = toml::to_string(&doc) {
                let _ = writeln!(s, "\n{text}");
            }
        }
        s
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

/// `s` as a TOML string value. (Rust's `{:?}` is not TOML: it writes `\u{7f}`.)
fn toml_string(s: &str) -> String {
    toml::Value::String(s.to_string()).to_string()
}

fn valid_session(s: &str) -> bool {
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

/// Image height from width and fields of view, as the original system computed it:
/// `H = round(W · tan(fov_v/2) / tan(fov_h/2))` (256 px at 120°×90° → 148 px).
pub fn derived_height(width_px: u32, fov_h_deg: f64, fov_v_deg: f64) -> u32 {
    let h = f64::from(width_px) * (fov_v_deg.to_radians() / 2.0).tan()
        / (fov_h_deg.to_radians() / 2.0).tan();
    (h.round() as u32).clamp(1, MAX_IMAGE_SIDE_PX)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Config, ConfigLoadError> {
        Config::from_toml_str(text, Path::new("test.toml"))
    }

    const MINIMAL: &str = "session = \"t\"\n[[agent]]\nid = 0\n";

    #[test]
    fn transport_kind_all_lists_every_transport_once() {
        // Exhaustive: a new variant does not compile here until it is counted.
        let index = |k: TransportKind| match k {
            TransportKind::Shm => 0,
            TransportKind::Tcp => 1,
            TransportKind::Legacy => 2,
            TransportKind::Zenoh => 3,
        };
        let found: Vec<usize> = TransportKind::ALL.into_iter().map(index).collect();
        assert_eq!(found, (0..TransportKind::ALL.len()).collect::<Vec<_>>());
    }

    #[test]
    fn embedded_default_matches_the_documented_defaults() {
        let c = Config::embedded_default().unwrap();
        assert_eq!(c.agents.len(), 2);
        assert!(c.sync.sync_mode);
        assert_eq!(c.sync.simulation_time_per_frame, Duration::from_millis(100));
        assert_eq!(c.sync.stop_timeout, Duration::from_secs(5));
        assert_eq!(c.transport.kind, TransportKind::Shm);
        for a in &c.agents {
            assert_eq!(a.cameras.len(), 2);
            for cam in &a.cameras {
                assert_eq!((cam.width_px, cam.height_px), (256, 148));
                assert_eq!(cam.format, PixelFormat::Rgb8);
            }
        }
    }

    #[test]
    fn the_legacy_section_takes_the_original_key_and_round_trips() {
        let c = parse(MINIMAL).unwrap();
        assert_eq!(c.transport.legacy, LegacyConfig::default());
        assert_eq!(c.transport.legacy.local_port, 1337);
        assert!(c.transport.legacy.bind.is_loopback());
        let c = parse(
            "[transport.legacy]\nLocalPort = 2000\ndialect = \"burkhardt\"\npng_compression = \"fast\"\nbind = \"0.0.0.0\"\n[[agent]]\nid = 3\ntransport = \"legacy\"\n",
        )
        .unwrap();
        let l = &c.transport.legacy;
        assert_eq!(l.local_port, 2000);
        assert_eq!(l.dialect, LegacyDialect::Burkhardt);
        assert_eq!(l.png_compression, PngCompression::Fast);
        assert_eq!(c.agents[0].transport, TransportKind::Legacy);
        let back = parse(&c.to_toml_string()).unwrap();
        assert_eq!(back.transport, c.transport);
        assert_eq!(back.agents, c.agents);
        // The agent ports must fit: local_port + 1 + 250 <= 65535.
        let err = parse("[transport.legacy]\nlocal_port = 65300\n[[agent]]\nid = 0\n").unwrap_err();
        assert!(
            err.to_string().contains("transport.legacy.local_port"),
            "{err}"
        );
        let err =
            parse("[transport.legacy]\nbind = \"localhost:1\"\n[[agent]]\nid = 0\n").unwrap_err();
        assert!(err.to_string().contains("transport.legacy.bind"), "{err}");
        assert!(parse("[transport.legacy]\nport = 1\n[[agent]]\nid = 0\n").is_err());
    }

    #[test]
    fn each_agent_has_a_transport_defaulting_to_the_kind() {
        let text = "session = \"t\"\n[transport]\nkind = \"tcp\"\n\
                    [[agent]]\nid = 0\ntransport = \"shm\"\n[[agent]]\nid = 1\n";
        let c = parse(text).unwrap();
        assert_eq!(c.agents[0].transport, TransportKind::Shm);
        assert_eq!(c.agents[1].transport, TransportKind::Tcp);
        // The effective config keeps each agent's choice, and resizing keeps it too.
        let again = parse(&c.to_toml_string()).unwrap();
        assert_eq!(again.agents, c.agents);
        let more = c.with_agent_count(3).unwrap();
        let kinds: Vec<_> = more.agents.iter().map(|a| a.transport).collect();
        assert_eq!(
            kinds,
            [TransportKind::Shm, TransportKind::Tcp, TransportKind::Tcp]
        );
        let err = parse("[[agent]]\nid = 0\ntransport = \"carrier-pigeon\"\n").unwrap_err();
        assert!(err.to_string().contains("transport"), "{err}");
    }

    #[test]
    fn wait_for_stop_defaults_to_alive_and_each_agent_may_override_it() {
        let c = parse(MINIMAL).unwrap();
        assert_eq!(c.sync.wait_for_stop, None);
        assert_eq!(c.wait_for_stop(0), WaitForStop::Alive);
        assert!(c.waits_for_live_agents());
        let text = "session = \"t\"\n[sync]\nwait_for_stop = \"timeout\"\n[[agent]]\nid = 0\n\
                    [[agent]]\nid = 1\nwait_for_stop = \"alive\"\n";
        let c = parse(text).unwrap();
        assert_eq!(c.sync.wait_for_stop, Some(WaitForStop::Timeout));
        assert_eq!(c.wait_for_stop(0), WaitForStop::Timeout);
        assert_eq!(c.wait_for_stop(1), WaitForStop::Alive);
        assert_eq!(
            c.wait_for_stop(9),
            WaitForStop::Timeout,
            "not an agent: the default"
        );
        assert!(c.waits_for_live_agents());
        // Round trip, and agents added by a count take the [sync] default.
        let again = parse(&c.to_toml_string()).unwrap();
        assert_eq!(again.wait_for_stop(1), WaitForStop::Alive);
        let grown = c.with_agent_count(3).unwrap();
        assert_eq!(grown.wait_for_stop(2), WaitForStop::Timeout);
        let all_timeout = parse(&text.replace("\"alive\"", "\"timeout\"")).unwrap();
        assert!(!all_timeout.waits_for_live_agents());
        // Legacy agents (original clients may block on an action's end before stopping)
        // default to "timeout", unless [sync] or the agent says otherwise.
        let legacy =
            "session = \"t\"\n[[agent]]\nid = 0\ntransport = \"legacy\"\n[[agent]]\nid = 1\n";
        let c = parse(legacy).unwrap();
        assert_eq!(c.wait_for_stop(0), WaitForStop::Timeout);
        assert_eq!(c.wait_for_stop(1), WaitForStop::Alive);
        let c = parse(&legacy.replace(
            "session = \"t\"\n",
            "session = \"t\"\n[sync]\nwait_for_stop = \"alive\"\n",
        ))
        .unwrap();
        assert_eq!(c.wait_for_stop(0), WaitForStop::Alive);
        expect_err(
            "[sync]\nwait_for_stop = \"forever\"\n[[agent]]\nid = 0\n",
            2,
            "sync.wait_for_stop",
        );
    }

    #[test]
    fn original_names_are_aliases() {
        let c =
            parse("[sync]\nSyncMode = false\nSimulationTimePerFrame = 0.05\n[[agent]]\nid = 0\n")
                .unwrap();
        assert!(!c.sync.sync_mode);
        assert_eq!(c.sync.simulation_time_per_frame, Duration::from_millis(50));
    }

    #[test]
    fn derived_height_matches_the_original() {
        assert_eq!(derived_height(256, 120.0, 90.0), 148);
        assert_eq!(derived_height(512, 120.0, 90.0), 296);
        assert_eq!(derived_height(1024, 120.0, 90.0), 591);
    }

    fn expect_err(text: &str, line: usize, needle: &str) {
        let e = parse(text).unwrap_err();
        let msg = e.to_string();
        assert!(msg.contains("test.toml"), "{msg}");
        assert!(msg.contains(needle), "expected {needle:?} in {msg}");
        match e {
            ConfigLoadError::Parse { line: l, .. } | ConfigLoadError::Invalid { line: l, .. } => {
                assert_eq!(l, line, "{msg}")
            }
            other => panic!("unexpected {other:?}"),
        }
    }

    #[test]
    fn bad_configs_name_file_line_and_key() {
        expect_err(
            "session = \"t\"\nbogus = 1\n[[agent]]\nid = 0\n",
            2,
            "bogus",
        );
        expect_err(
            "[sync]\nsync_mode = \"yes\"\n[[agent]]\nid = 0\n",
            2,
            "sync_mode",
        );
        expect_err(
            "[sync]\nstop_timeout = -1.0\n[[agent]]\nid = 0\n",
            2,
            "sync.stop_timeout",
        );
        expect_err(
            "[sync]\nsimulation_time_per_frame = 0\n[[agent]]\nid = 0\n",
            2,
            "sync.simulation_time_per_frame",
        );
        expect_err(
            "[[agent]]\nid = 0\n[[agent]]\nid = 0\n",
            4,
            "duplicate agent id 0",
        );
        expect_err("session = \"t\"\n", 1, "agent");
        expect_err(
            "[[agent]]\nid = 0\n[[agent.camera]]\nname = \"l\"\nwidth = 0\n",
            5,
            "agent.camera.width",
        );
        expect_err(
            "[[agent]]\nid = 0\n[[agent.camera]]\nname = \"l\"\nwidth = 64\nformat = \"bgr\"\n",
            6,
            "agent.camera.format",
        );
        expect_err("[transport]\nkind = \"udp\"\n[[agent]]\nid = 0\n", 2, "udp");
        expect_err("[[agent]]\nid = 999\n", 2, "agent.id");
        expect_err("session = \"a/b\"\n[[agent]]\nid = 0\n", 1, "session");
    }

    #[test]
    fn agent_count_override_copies_the_last_agents_cameras() {
        let c = Config::embedded_default()
            .unwrap()
            .with_agent_count(3)
            .unwrap();
        assert_eq!(c.agents.iter().map(|a| a.id).collect::<Vec<_>>(), [0, 1, 2]);
        assert_eq!(c.agents[2].cameras, c.agents[1].cameras);
        assert!(parse(MINIMAL).unwrap().with_agent_count(0).is_err());
    }

    #[test]
    fn effective_config_round_trips() {
        let c = Config::embedded_default()
            .unwrap()
            .with_agent_count(3)
            .unwrap();
        let text = c.to_toml_string();
        let back = Config::from_toml_str(&text, Path::new("eff.toml")).unwrap();
        assert_eq!(back.agents, c.agents);
        assert_eq!(back.sync, c.sync);
        assert_eq!(back.transport, c.transport);
        assert_eq!(back.session, c.session);
        assert_eq!(back.world, c.world);
    }
}
