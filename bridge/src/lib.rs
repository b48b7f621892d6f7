//! # vrsync-bridge
//!
//! The core of vrsync: a simulator (the **host**) and many **agent** processes on one
//! machine run in lock-step through zero-copy shared memory (iceoryx2).
//!
//! - A **cycle** is a frame pair. In *frame 1* the host writes every agent's sensor frame
//!   (a fixed [`SensorHeader`] plus raw images) straight into shared memory, publishes it
//!   and signals *start* once for everyone. In *frame 2* the host blocks until every agent
//!   sent its motor batch with the *stop* flag for that cycle, or `stop_timeout` passes,
//!   then advances the world by exactly `simulation_time_per_frame`.
//! - The **barrier** (inside [`Host`]) counts a stop only for the cycle it names: a late
//!   stop never completes the next cycle ([`AgentOutcome`] says how each agent ended one).
//! - A **transport** moves frames, batches and signals; the contract every transport keeps
//!   is [`HostTransport`] (host side) and [`AgentTransport`] (agent side): shared memory
//!   ([`shm`]) for agents on this machine, TCP ([`tcp`]) as the measured baseline, and the
//!   original system's protocol ([`legacy`]) for agents written for it. A host serves each
//!   agent over its own transport ([`Transports`]).
//! - The **host API** ([`Host`]) is what a simulator calls; agents use the `vrsync-agent`
//!   crate.
//!
//! The modules are private; everything public is re-exported here. The wire types (the
//! `#[repr(C)]` types, the image layout, the command catalogue) and the record codec come
//! from the `vrsync-protocol` crate, below this one, and keep their paths here
//! ([`record`], the wire items at the root). Inside the crate, modules import one way:
//! `config` ← `transport` (with `signal`) ← `barrier` ← `host`; no module imports one that
//! imports it back.
//!
//! ```no_run
//! use std::time::Duration;
//! use vrsync_bridge::{Config, Host};
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let config = Config::load("config/default.toml")?;
//! let mut host = Host::builder(&config).create()?;
//! host.wait_for_agents(config.sync.connect_timeout)?;
//! for _ in 0..100 {
//!     let ids: Vec<u32> = host.agent_ids().collect();
//!     for id in ids {
//!         let mut frame = host.loan_frame(id)?;
//!         for image in frame.images_mut() {
//!             image.data.fill(128); // render here, straight into shared memory
//!         }
//!         host.publish(frame)?;
//!     }
//!     host.start()?;
//!     let report = host.collect()?;
//!     for agent in report.agents() {
//!         for command in agent.commands() {
//!             let _ = command.decode(); // apply to the world
//!         }
//!     }
//! }
//! # Ok(())
//! # }
//! ```

mod barrier;
mod colour;
mod config;
mod events;
mod host;
mod logging;
mod rounded;
mod signal;
mod transport;
// The wire types live in the protocol crate; `crate::wire` keeps their old path.
use vrsync_protocol::wire;

pub use vrsync_protocol::channel_layout::{Channel, ChannelDifference, ChannelLayout};

pub use barrier::AgentOutcome;
pub use colour::ansi_on_stderr;
pub use config::{
    ActionConfig, ActionSpace, AgentConfig, AgentLostPolicy, CameraConfig, Config, ConfigLoadError,
    DEFAULT_CONFIG_TOML, DEFAULT_RESUME_WINDOW_S, DEFAULT_SPIN_BEFORE_BLOCK_US,
    DEFAULT_ZENOH_ENDPOINT, LegacyConfig, LegacyDialect, MAX_AGENT_ID, MAX_CONFIG_BYTES,
    MAX_IMAGE_SIDE_PX, PngCompression, SyncConfig, TransportConfig, TransportKind, VectorConfig,
    WaitForStop, WaitMode, ZenohConfig, ZenohTls, derived_height,
};
pub use host::{
    ActionValue, AgentReport, CycleReport, Host, HostBuilder, HostCreateError, HostCycleError,
    HostStats, HostWaitError, INTERRUPT_PERIOD, ImageMut, ImagesMut, REAP_PERIOD, SensorFrameMut,
};
pub use logging::{QUIET_ZENOH, default_log_filter};
pub use rounded::Rounded;
pub use shm::{ShmBudgetError, check_shm_budget};
pub use signal::SignalHandling;
pub use transport::any_agent::{AnyAgent, AnyFrame};
pub use transport::mixed::{AnyLoan, Transports, TransportsCreateError};
pub use transport::{
    AGENT_MAX_HELD_FRAMES, AgentConnectError, AgentFrame, AgentReceiveError, AgentSendError,
    AgentTransport, AgentWaitError, Attempt, BatchSink, FrameLoanMut, HOST_LIVENESS_PERIOD,
    HostLiveness, HostTransport, HostTransportError, MAX_KEPT_REFUSALS, PeerRefusal, RefusalKind,
    Refusals, retry_until, wait_for_newer_frame,
};
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

/// The shared-memory transport (iceoryx2): agents on this machine, zero copy.
pub mod shm {
    pub use crate::transport::shm::*;
}

/// The record codec both network transports speak (hello, welcome, reject, motor batch,
/// TCP's record framing): what the fuzz target and the hostile-peer tests drive.
pub mod record {
    pub use crate::transport::record::*;
}

/// The TCP transport (the measured baseline). Re-exports the [`record`] codec it frames.
pub mod tcp {
    pub use crate::transport::tcp::*;
}

/// The original system's protobuf/TCP protocol, served to agents written for it, with its
/// codec (what the fuzz target and the legacy bench client use).
///
/// Only with the `legacy` cargo feature; without it, this module holds uninhabited
/// stand-ins whose `LegacyHost::create` fails with an error naming the feature.
pub mod legacy {
    pub use crate::transport::legacy::*;
}

/// The zenoh transport: agents on other machines (keys, hello, liveliness, validation).
///
/// Only with the `zenoh` cargo feature; without it, this module holds uninhabited stand-ins
/// whose `ZenohHost::create` and agent `connect` fail with an error that names the feature.
pub mod zenoh {
    pub use crate::transport::zenoh::*;
}
