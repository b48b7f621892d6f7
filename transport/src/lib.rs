//! # vrsync-transport
//!
//! How vrsync's sensor frames, motor batches, *start* and *stop* move between a host and
//! its agents, and the session configuration both sides read.
//!
//! - The **contract** every transport keeps: on the host side [`HostTransport`] (the data
//!   path) with [`HostReadiness`] (how the host waits for it) and [`HostConnections`] (who
//!   is attached), on the agent side [`AgentTransport`]; with what is written once over it
//!   ([`wait_for_newer_frame`], [`retry_until`]).
//! - The transports, each in its own module with its host and agent halves: shared memory
//!   ([`shm`], iceoryx2) for agents on this machine, TCP ([`tcp`]) as the measured
//!   baseline, zenoh ([`zenoh`], behind the `zenoh` cargo feature) for agents on other
//!   machines. The original system's protocol has a host side only, in the
//!   `vrsync-legacy` crate; here it has its registry entry and the agent stand-in
//!   ([`legacy`]) that tells a vrsync agent why it cannot connect over it.
//! - The **config** ([`Config`]): TOML → typed, validated, with every transport's section.
//! - [`AnyAgent`]: the agent side over whichever transport the config names for an agent.
//!
//! The host side (the barrier, the routing of a host over several transports at once, the
//! host API) is the `vrsync-bridge` crate, above this one; the agent SDK (`vrsync-agent`)
//! needs only this crate. Inside the crate, files import one way: the wire types (from
//! `vrsync-protocol`) ← the transports' config sections (`zenoh/section.rs`,
//! `legacy/section.rs`) ← `config` ← the contract (`contract`, with `signal`, `wait`) ← the
//! transports' host and agent halves.

mod absent;
mod any_agent;
mod colour;
mod config;
mod contract;
pub mod legacy;
mod logging;
/// The record codec and admission, from the protocol crate.
pub use vrsync_protocol::record;
mod refusal;
mod registry;
mod rounded;
pub mod shm;
mod signal;
pub mod tcp;
mod wait;
#[cfg(feature = "zenoh")]
pub mod zenoh;
/// Without the `zenoh` feature, the zenoh entry of the registry: stand-ins whose host and
/// agent constructors fail with an error naming the feature.
#[cfg(not(feature = "zenoh"))]
#[path = "zenoh/off.rs"]
pub mod zenoh;

// The wire types live in the protocol crate; `crate::wire` is their path here, and they
// are re-exported at the root (as `vrsync-bridge` does) for the agent side's users.
use vrsync_protocol::wire;

pub use vrsync_protocol::channel_layout::{Channel, ChannelDifference, ChannelLayout};

pub use any_agent::{AnyAgent, AnyFrame};
pub use colour::ansi_on_stderr;
pub use config::{
    ActionConfig, ActionSpace, AgentConfig, AgentLostPolicy, CameraConfig, Config, ConfigLoadError,
    DEFAULT_CONFIG_TOML, DEFAULT_RESUME_WINDOW_S, DEFAULT_SPIN_BEFORE_BLOCK_US, MAX_AGENT_ID,
    MAX_CONFIG_BYTES, MAX_IMAGE_SIDE_PX, SyncConfig, TransportConfig, TransportKind, VectorConfig,
    WaitForStop, WaitMode, derived_height,
};
pub use contract::*;
pub use legacy::{LegacyConfig, LegacyDialect, PngCompression};
pub use logging::{QUIET_ZENOH, default_log_filter};
pub use refusal::{MAX_KEPT_REFUSALS, PeerRefusal, RefusalKind, Refusals};
pub use rounded::Rounded;
pub use shm::ShmConfig;
pub use shm::{ShmBudgetError, check_shm_budget};
pub use signal::SignalHandling;
pub use wire::{
    ACTION_CHUNK, ACTION_KIND, ActionDesc, ActionState, ActionStatus, CAMERA_NAME_LEN,
    CHANNEL_NAME_LEN, Collision, Command, CommandDecodeError, CommandKind, CommandParam,
    EyePosition, GridPosition, HeadMotion, IMAGE_ALIGN, ImageDesc, LAYOUT_HASH, MAX_ACTION_LEN,
    MAX_ACTIONS, MAX_CAMERAS, MAX_COLLISIONS, MAX_STATUSES, MAX_TOKEN, MAX_VECTOR_LEN, MAX_VECTORS,
    MOTOR_FLAG_ACK, MOTOR_FLAG_LEAVE, MOTOR_FLAG_STOP, MotorCommand, MotorHeader, PROTOCOL_VERSION,
    ParamType, PixelFormat, Pose, SENSOR_FLAG_SYNC_MODE, SensorHeader, VectorDesc, WireOutcome,
    action_chunks, bounds_hash, discrete_action_chunk, image_layout, kind as command_kind,
    kind_name, vector_layout,
};
/// The `tracing` layer a host's subscriber needs for the refusals its transports see only
/// as log events (zenoh's TLS handshake failures, counted as refused peers whatever the
/// filter): [`zenoh::tls_refusal_layer`].
#[cfg(feature = "zenoh")]
pub use zenoh::tls_refusal_layer as refusal_layer;
pub use zenoh::{DEFAULT_ZENOH_ENDPOINT, ZenohConfig, ZenohTls};

/// For the routing of a host over several transports (`vrsync-bridge`) and for the
/// original protocol's host (`vrsync-legacy`): the pieces of this crate they build on,
/// which are not part of the public API.
#[doc(hidden)]
pub mod internal {
    pub use crate::wait::{EpollSet, write_all_until};
    pub use vrsync_protocol::wire;
}
