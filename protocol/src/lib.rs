//! # vrsync-protocol
//!
//! What a vrsync host and its agents say to each other, with no I/O and no transport: the
//! words every other crate of vrsync shares.
//!
//! - [`wire`]: the `#[repr(C)]` types that cross process boundaries (the sensor frame's
//!   header with its image, vector and action tables, the motor batch), their layout hash
//!   and [`wire::PROTOCOL_VERSION`], and the **command catalogue**: the commands an agent
//!   sends ([`wire::Command`]), defined once with their tags, names and fields
//!   ([`wire::CommandKind::ALL`]), the list every binding's copy is checked against.
//! - [`record`]: the record codec both network transports speak (hello, welcome, reject,
//!   motor batch, TCP's `[len][kind][body]` framing with its bounded reader), and
//!   [`record::admit`], the one decision a network host makes on a hello, its refusal a
//!   typed [`record::Reject`].
//! - [`channel_layout`]: an agent's channels as host and agent compare them at connect
//!   (a canonical text, its hash, the first channel that differs).
//!
//! The transports, the host and the agent SDK live in `vrsync-bridge` and `vrsync-agent`,
//! which re-export these modules at their old paths.
//!
//! ```
//! use vrsync_protocol::wire::{Command, CommandKind};
//!
//! let wire = Command::Turn { angle_deg: 30.0 }.encode(7);
//! assert_eq!(wire.decode(), Ok(Command::Turn { angle_deg: 30.0 }));
//! let turn = CommandKind::of(wire.kind).map(|k| (k.name, k.params.len()));
//! assert_eq!(turn, Some(("turn", 1)));
//! ```

mod admission;
pub mod channel_layout;
pub mod record;
pub mod wire;
