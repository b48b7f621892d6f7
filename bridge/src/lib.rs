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
//! - The **barrier** ([`barrier::CycleBarrier`]) counts a stop only for the cycle it names:
//!   a late stop never completes the next cycle.
//! - A **transport** ([`transport::HostTransport`]) moves frames, batches and signals:
//!   shared memory ([`transport::shm`]) for agents on this machine.
//! - The **host API** ([`Host`]) is what a simulator calls; agents use the `vrsync-agent`
//!   crate.
//!
//! Inside the crate, modules import one way: `wire` (the `#[repr(C)]` types, the image
//! layout) ← `config` ← `transport` (with `signal`) ← `barrier` ← `host`; no module
//! imports one that imports it back.
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

pub mod barrier;
pub mod config;
pub mod host;
mod signal;
pub mod transport;
pub mod wire;

pub use barrier::AgentOutcome;
pub use config::{Config, ConfigLoadError, TransportKind};
pub use host::{
    AgentReport, CycleReport, Host, HostBuilder, HostCreateError, HostCycleError, HostStats,
    HostWaitError, ImageMut, SensorFrameMut,
};
pub use signal::SignalHandling;
pub use transport::AgentConnectError;
pub use transport::shm::{ShmBudgetError, check_shm_budget};
pub use wire::{
    ActionState, Command, CommandDecodeError, ImageDesc, LAYOUT_HASH, MotorCommand, MotorHeader,
    PROTOCOL_VERSION, PixelFormat, Pose, SensorHeader,
};
