//! # vrsync-agent
//!
//! What an agent links to take part in a vrsync session: connect to the host, wait for
//! *start*, read the sensor frame (images are `&[u8]` straight into shared memory), send
//! motor commands, *stop*. The loop mirrors the original system's agents:
//!
//! ```no_run
//! use vrsync_agent::{Agent, Command, Config};
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let config = Config::load("config/default.toml")?;
//! let mut agent = Agent::connect(&config, 0)?;
//! loop {
//!     let frame = match agent.wait_start(None) {
//!         Ok(frame) => frame,
//!         Err(vrsync_agent::WaitStartError::HostClosed) => break,
//!         Err(e) => return Err(e.into()),
//!     };
//!     let left = frame.image_by_name("left").ok_or("no left camera")?;
//!     let brightness = left.data().iter().map(|&b| u64::from(b)).sum::<u64>();
//!     drop(frame); // release the shared memory before the next cycle
//!     if brightness > 0 {
//!         agent.send(Command::Turn { angle_deg: 10.0 })?;
//!     }
//!     agent.stop()?;
//! }
//! # Ok(())
//! # }
//! ```
//!
//! # Transports and the `zenoh` feature
//!
//! The config file says which transport the agent uses (`[[agent]] transport`): shared
//! memory and TCP are always built; the zenoh transport, for agents on other machines,
//! comes with this crate's `zenoh` feature (off by default: zenoh and its async runtime are
//! the largest part of a build). Without it, [`Agent::connect`] with a config that puts
//! the agent on zenoh fails with an error naming the feature. The C ABI over this SDK, for
//! C and C++ agents, is the `vrsync-agent-ffi` package (`libvrsync_agent`).

mod agent;
pub mod log;

pub use agent::{
    ACTION_STATES_CAPACITY, ActError, Agent, AgentBuilder, AgentConnectError, Frame,
    HOST_LIVENESS_PERIOD, Image, REJOIN_GRACE, SendError, SharedStack, ShmStack, SignalHandling,
    StackSample, StopError, WaitStartError, close_all,
};
/// The [glam](https://docs.rs/glam) this SDK uses for poses and targets ([`Pose::position`],
/// [`Command::MoveTo`]): use `vrsync_agent::glam` instead of pinning the same version.
pub use glam;
pub use vrsync_transport::{
    ActionConfig, ActionSpace, ActionState, ActionStatus, Collision, Command, PixelFormat, Pose,
    SensorHeader, VectorConfig, VectorDesc,
};
pub use vrsync_transport::{Config, WaitForStop};
