//! The original system's protocol (`[[agent]] transport = "legacy"`): agents written for
//! the original system (its Python `Annar4Interface` clients, its C++ client) run against
//! a vrsync host unchanged, in lock step with agents on the other transports.
//!
//! The specification is `shared/reference/legacy-protocol.md`; in short:
//! - **Sockets.** An environment socket on `[transport.legacy] local_port` (alias
//!   `LocalPort`, default 1337), read only for EnvironmentReset and TrialReset, and one
//!   socket per agent on `local_port + 1 + id`, bound to loopback unless `bind` says
//!   otherwise. A new connection on an agent port replaces the old one once it has passed
//!   its version check (a stranger that connects and says nothing cannot push a working
//!   agent out; it is dropped after [`HELLO_TIMEOUT`]).
//! - **Resets.** The environment socket carries no agent id: an agent connection that
//!   passes its version check is paired with its client's environment connection (the
//!   newest unpaired one from the same IP accepted before it; of the same process where
//!   `/proc` shows the owner), and that connection's resets go to this agent. Unpaired
//!   environment connections close after [`HELLO_TIMEOUT`]; a full set of 16 closes its
//!   oldest for a newcomer; a stalled or oversize frame closes the connection.
//! - **Framing.** A signed little-endian `i32` length, then one protobuf `MsgObject`
//!   ([`codec`]); frames longer than [`codec::MAX_INCOMING_FRAME`] are skipped unread, a
//!   negative length drops the connection (there is no boundary to resume at).
//! - **Dialects.** `vrnew` (the older clients) and `burkhardt` (the later one) differ in the
//!   fields from 25 up; `dialect = "auto"` tells them apart by each connection's version
//!   check, which is answered at once in the client's dialect.
//! - **One cycle**, written when the host publishes the agent's frame: the statuses and
//!   collisions of the last cycle's commands, the images as PNG (left, right, and for
//!   burkhardt a main image), GridPosition, optionally EyePosition and HeadMotion,
//!   StartSync, and a Debug trailer naming the cycle. A Debug keep-alive goes out after a
//!   second without writes.
//! - **Stop.** A zero-length frame (what the unmodified clients send) or a StopSync ends
//!   the agent's open cycle. The wire carries no cycle number: a stop that arrives while
//!   no cycle is open (the agent's last one already ended by the stop timeout) ends the
//!   next one, as the original did; such stops are counted ([`LegacyStats`]).
//! - **Commands** are handed to the host as they arrive (so a cycle that ends by timeout
//!   still applies them), each acknowledged at once (Rotating for a turn, Walking for a
//!   movement, InExecution otherwise). The simulator reports the rest (Walking,
//!   Finished, Aborted); a command the simulator rejected, and one refused here (a
//!   non-finite argument, more than `max_commands_per_cycle` in a cycle) ends Aborted, so
//!   a client that blocks on a final status never hangs.
//!
//! Everything is read without blocking, from one `epoll` set whose descriptor is the
//! transport's [`vrsync_transport::HostReadiness::activity_fd`]: a host serving agents over several
//! transports waits for all of them at once.

//!
//! This crate is the host side and the codec; `vrsync-bridge` serves agents over it with
//! its `legacy` cargo feature (without it, creating a host whose config puts an agent on
//! `"legacy"` fails with an error naming that feature). The agent side is a stand-in of
//! `vrsync-transport` ([`vrsync_transport::legacy`]): vrsync agents do not speak this
//! protocol.

pub mod codec;
mod host;

pub use host::*;
