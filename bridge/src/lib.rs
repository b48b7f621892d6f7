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
//! The crate is the host: the barrier, the routing of one host over several transports,
//! the host API. What it builds on comes from the crates below it and keeps its paths here
//! (everything public is re-exported at the root): the wire types (the `#[repr(C)]` types,
//! the image layout, the command catalogue) and the record codec from `vrsync-protocol`;
//! the config, the transport contract and the transports from `vrsync-transport`; the
//! original protocol's host from `vrsync-legacy` (with the `legacy` feature). Inside the
//! crate, modules import one way: `transport` (the routing) ← `barrier` ← `host`.
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
mod events;
mod host;
mod transport;
// The wire types live in the protocol crate; `crate::wire` keeps their old path.
use vrsync_protocol::wire;

pub use vrsync_protocol::channel_layout::{Channel, ChannelDifference, ChannelLayout};

pub use barrier::AgentOutcome;
pub use host::{
    ActionValue, AgentReport, CycleReport, Host, HostBuilder, HostCreateError, HostCycleError,
    HostStats, HostWaitError, INTERRUPT_PERIOD, ImageMut, ImagesMut, REAP_PERIOD, SensorFrameMut,
};
pub use transport::mixed::{AnyLoan, Transports, TransportsCreateError};
// The config, the transport contract, the transports and the wire types, at their old
// paths (the `legacy` module below is the host's: the `vrsync-legacy` crate).
pub use vrsync_transport::*;

/// The original system's protobuf/TCP protocol, served to agents written for it, with its
/// codec (what the fuzz target and the legacy bench client use): the `vrsync-legacy`
/// crate.
///
/// Only with the `legacy` cargo feature; without it, this module holds uninhabited
/// stand-ins whose `LegacyHost::create` fails with an error naming the feature.
pub mod legacy {
    pub use crate::transport::legacy::*;
    pub use vrsync_transport::legacy::{LegacyAgent, LegacyFrame};
}
