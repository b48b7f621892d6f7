//! Configuration: TOML → typed, validated [`Config`].
//!
//! Every key is documented in `config/default.toml`. Unknown keys, wrong types and
//! invalid values are rejected with a [`ConfigLoadError`] that names the file, the line
//! and the key. The original system's names `SyncMode` and `SimulationTimePerFrame` are
//! accepted as aliases.
//!
//! The file is read into `raw` (serde structs, every key optional), checked section by
//! section in `checks` (defaults, ranges, file:line:key errors, with the context of
//! `ctx`), and written back by `emit` ([`Config::to_toml_string`]). The `[transport]`
//! section (`transport`) is composed of the sections the transports define themselves
//! (`[transport.legacy]`, `[transport.zenoh]`: their `section.rs`), each with its raw form,
//! its checks and its text.

use std::path::{Path, PathBuf};
use std::time::Duration;

use serde::Deserialize;

use vrsync_protocol::channel_layout::ChannelLayout;

use crate::wire::{
    ActionDesc, ImageDesc, MAX_ACTIONS, MAX_CAMERAS, MAX_VECTORS, PixelFormat, VectorDesc,
};

#[cfg(test)]
mod channel_tests;
mod channels;
mod checks;
pub(crate) mod ctx;
mod emit;
pub(crate) mod error;
mod raw;
#[cfg(test)]
mod tests;
mod transport;

pub use channels::{ActionConfig, ActionSpace, VectorConfig};
use checks::valid_session;
use ctx::Ctx;
pub use ctx::MAX_AGENT_ID;
pub use error::ConfigLoadError;
pub use transport::TransportConfig;

/// Default of `[sync] spin_before_block_us`.
pub const DEFAULT_SPIN_BEFORE_BLOCK_US: u64 = 50;

/// Default `[sync] resume_window`, seconds: how long a network agent whose link was lost
/// is held for its return (and tries to come back) before it is evicted (gives up).
pub const DEFAULT_RESUME_WINDOW_S: f64 = 30.0;

/// Largest accepted image side in pixels.
pub const MAX_IMAGE_SIDE_PX: u32 = 8192;
/// Largest config file [`Config::load`] reads, bytes.
pub const MAX_CONFIG_BYTES: u64 = 4 << 20;

/// Generates [`TransportKind`] from the transport registry
/// (`registry.rs`).
macro_rules! transport_kind {
    ($(
        $(#[$attr:meta])*
        $kind:ident $name:literal $module:ident:
            $host:ident, $loan:ident, $create_error:ident, $agent:ident, $frame:ident
            [channels: $channels:literal, wait_for_stop: $wait:ident $(, $($section:tt)*)?];
    )*) => {
        /// Transport selected by `[transport] kind` (and `[[agent]] transport`), spelled
        /// as [`TransportKind::as_str`] says.
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
        pub enum TransportKind {
            $(
                $(#[$attr])*
                #[serde(rename = $name)]
                $kind,
            )*
        }

        impl TransportKind {
            /// Every transport, in the registry's order (the test matrix and the docs take
            /// it from here).
            pub const ALL: [TransportKind; [$($name),*].len()] = [$(Self::$kind),*];

            /// The config spelling.
            pub fn as_str(self) -> &'static str {
                match self {
                    $(Self::$kind => $name,)*
                }
            }

            /// Whether agents on this transport can have channels (`[[agent.vector]]`,
            /// `[[agent.action]]`).
            pub fn carries_channels(self) -> bool {
                match self {
                    $(Self::$kind => $channels,)*
                }
            }

            /// The `wait_for_stop` of an agent on this transport when neither its
            /// `[[agent]]` entry nor `[sync]` sets one.
            pub fn default_wait_for_stop(self) -> WaitForStop {
                match self {
                    $(Self::$kind => WaitForStop::$wait,)*
                }
            }
        }
    };
}

crate::transports!(transport_kind);

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
    /// `[sync] wait_for_stop` (`None`: not set): `[sync]`'s, else the transport's
    /// ([`TransportKind::default_wait_for_stop`]: `Alive`, except on the legacy transport,
    /// whose clients, written for the original system, may block on an action's end
    /// before they stop and so rely on the stop timeout: `Timeout` there).
    pub fn default_for(sync: Option<WaitForStop>, transport: TransportKind) -> Self {
        sync.unwrap_or_else(|| transport.default_wait_for_stop())
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
    /// Float vectors the host writes beside the images (`[[agent.vector]]`), in payload
    /// order.
    pub vectors: Vec<VectorConfig>,
    /// What the agent sends back each cycle (`[[agent.action]]`), in config order (an
    /// action's index here is its wire index).
    pub actions: Vec<ActionConfig>,
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

    /// The vector table of this agent's sensor frames (vectors after the images) and the
    /// whole payload size in bytes (see [`crate::wire::vector_layout`]).
    pub fn vector_layout(&self) -> ([VectorDesc; MAX_VECTORS], usize) {
        crate::wire::vector_layout(
            self.image_layout().1,
            self.vectors.iter().map(|v| (v.name.as_str(), v.len)),
        )
    }

    /// The action table of this agent's sensor frames (what the host expects back).
    pub fn action_table(&self) -> [ActionDesc; MAX_ACTIONS] {
        let mut table = [ActionDesc::default(); MAX_ACTIONS];
        for (d, a) in table.iter_mut().zip(&self.actions) {
            *d = a.desc();
        }
        table
    }

    /// This agent's channels as host and agent compare them at connect.
    pub fn channel_layout(&self) -> ChannelLayout {
        let (vectors, _) = self.vector_layout();
        let actions = self.action_table();
        ChannelLayout::from_descs(
            &vectors[..self.vectors.len().min(MAX_VECTORS)],
            &actions[..self.actions.len().min(MAX_ACTIONS)],
        )
    }

    /// The index of the action called `name`.
    pub fn action_index(&self, name: &str) -> Option<usize> {
        self.actions.iter().position(|a| a.name == name)
    }

    /// Bytes of the payload of one sensor frame of this agent: every image, then every
    /// vector.
    pub fn frame_bytes(&self) -> usize {
        self.vector_layout().1
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
    /// How long a network agent whose link was lost is held for its return, and how long
    /// it tries to reconnect before it gives up (`resume_window`; zero: not at all).
    pub resume_window: Duration,
}

impl SyncConfig {
    /// The poll-before-sleep time to use with `agents` agents, each in a process of its
    /// own: see [`Self::spin_for_processes`].
    pub fn effective_spin_before_block(&self, agents: usize) -> Duration {
        Self::spin_for_processes(self.spin_before_block, agents)
    }

    /// The poll-before-sleep time to use when the agents run in `processes` processes:
    /// `spin_before_block`, or zero when those and the host together outnumber the cores
    /// (polling would then steal the CPU from the process that has work to do).
    pub fn spin_for_processes(spin_before_block: Duration, processes: usize) -> Duration {
        let cores = std::thread::available_parallelism().map_or(1, usize::from);
        if processes + 1 > cores {
            Duration::ZERO
        } else {
            spin_before_block
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

/// The built-in default configuration (`config/default.toml`).
pub const DEFAULT_CONFIG_TOML: &str = include_str!("../../../config/default.toml");

impl Config {
    /// The channels the config declares for agent `id` (none if it has no such agent).
    pub fn channel_layout_of(&self, id: u32) -> ChannelLayout {
        self.agents
            .iter()
            .find(|a| a.id == id)
            .map(AgentConfig::channel_layout)
            .unwrap_or_default()
    }

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
        let raw = ctx.parse()?;
        let session = ctx.session(raw.session)?;
        let sync = ctx.sync(raw.sync)?;
        let stacked_span = raw
            .transport
            .as_ref()
            .and_then(|t| t.shm.as_ref())
            .and_then(|s| s.stacked_images.as_ref())
            .map(toml::Spanned::span);
        let transport = ctx.transport(raw.transport)?;
        let agents = ctx.agents(raw.agent, &sync, transport.kind)?;
        if transport.shm.stacked_images {
            ctx.stacked(stacked_span.unwrap_or(0..0), &agents)?;
        }
        Ok(Self {
            source: path.to_path_buf(),
            session,
            seed: raw.seed,
            sync,
            transport,
            agents,
            world: raw.world,
        })
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
    /// their cameras and channels, new ones copy the cameras and channels (vectors,
    /// actions) of the last configured agent. Used by `--agents` / `--spawn-agents`.
    ///
    /// # Errors
    /// [`ConfigLoadError::Invalid`] if `count` is 0 or larger than the id space, or if a
    /// new agent would be served over the original protocol (`[transport] kind =
    /// "legacy"`) with the channels it copies, which that protocol cannot carry.
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
            .map(|a| (a.cameras.clone(), a.vectors.clone(), a.actions.clone()));
        let mut agents = Vec::with_capacity(count as usize);
        for id in 0..count {
            let agent = match self.agent(id) {
                Some(a) => a.clone(),
                None => {
                    let (cameras, vectors, actions) = template.clone().unwrap_or_default();
                    AgentConfig {
                        id,
                        transport: self.transport.kind,
                        wait_for_stop: WaitForStop::default_for(
                            self.sync.wait_for_stop,
                            self.transport.kind,
                        ),
                        cameras,
                        vectors,
                        actions,
                    }
                }
            };
            let has_channels = !(agent.vectors.is_empty() && agent.actions.is_empty());
            if has_channels && !agent.transport.carries_channels() {
                return Err(ConfigLoadError::Invalid {
                    path: self.source.clone(),
                    line: 1,
                    key: "agent".into(),
                    reason: format!(
                        "added agent {id} would copy the channels of the last agent but is \
                         served over the {} transport, which carries no channels",
                        agent.transport.as_str()
                    ),
                });
            }
            agents.push(agent);
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
}

/// Image height from width and fields of view, as the original system computed it:
/// `H = round(W · tan(fov_v/2) / tan(fov_h/2))` (256 px at 120°×90° → 148 px).
pub fn derived_height(width_px: u32, fov_h_deg: f64, fov_v_deg: f64) -> u32 {
    let h = f64::from(width_px) * (fov_v_deg.to_radians() / 2.0).tan()
        / (fov_h_deg.to_radians() / 2.0).tan();
    (h.round() as u32).clamp(1, MAX_IMAGE_SIDE_PX)
}
