//! The agent → host side: motor batches (header and commands) and their decoding.

use super::*;

/// Motor header flag: this batch ends the agent's cycle (the *stop*).
pub const MOTOR_FLAG_STOP: u32 = 1;
/// Motor header flag: [`MotorHeader::ack_cycle`] is valid.
pub const MOTOR_FLAG_ACK: u32 = 2;
/// Motor header flag: the agent leaves the session now (a graceful leave: `Agent::close`
/// or drop). The batch carries no commands; its `cycle` is the newest the agent saw. The
/// host stops waiting for it at once and frees its id for a new connection. (Hosts that
/// predate the flag ignore it and notice the closed connection instead: no protocol
/// version change.)
pub const MOTOR_FLAG_LEAVE: u32 = 4;

/// Header of a motor batch: the iceoryx2 user header of an `agent/<id>/motor` sample whose
/// payload is `[MotorCommand]`.
#[repr(C)]
#[derive(
    Debug,
    Clone,
    Copy,
    Default,
    PartialEq,
    ZeroCopySend,
    IntoBytes,
    FromBytes,
    Immutable,
    KnownLayout,
)]
#[type_name("vrsync::MotorHeader/v2")]
pub struct MotorHeader {
    /// [`PROTOCOL_VERSION`] of the writer.
    pub protocol_version: u32,
    /// The sending agent.
    pub agent_id: u32,
    /// The cycle these commands answer (the `cycle` of the sensor frame they were computed from).
    pub cycle: u64,
    /// `MOTOR_FLAG_*` bits.
    pub flags: u32,
    /// Number of commands in the payload.
    pub command_count: u32,
    /// With [`MOTOR_FLAG_ACK`]: the newest cycle whose sensor frame the agent has read. The
    /// host stops repeating the events that frame (or an earlier one) carried, and counts
    /// the frame as read. Valid in any batch, also a late one. A transport that reads every
    /// frame for its agent (one that does not skip) may set it for the agent.
    pub ack_cycle: u64,
}

impl MotorHeader {
    /// Whether this batch carries the stop.
    pub fn is_stop(&self) -> bool {
        self.flags & MOTOR_FLAG_STOP != 0
    }

    /// Whether the agent leaves with this batch ([`MOTOR_FLAG_LEAVE`]).
    pub fn is_leave(&self) -> bool {
        self.flags & MOTOR_FLAG_LEAVE != 0
    }

    /// The acknowledged cycle, if the batch carries one.
    pub fn acknowledged(&self) -> Option<u64> {
        (self.flags & MOTOR_FLAG_ACK != 0).then_some(self.ack_cycle)
    }
}

/// One motor command on the wire: a tag, the agent's action id and the arguments.
///
/// Use [`Command`] to build and read it: [`Command::encode`] / [`MotorCommand::decode`].
#[repr(C)]
#[derive(
    Debug,
    Clone,
    Copy,
    Default,
    PartialEq,
    ZeroCopySend,
    IntoBytes,
    FromBytes,
    Immutable,
    KnownLayout,
)]
#[type_name("vrsync::MotorCommand/v1")]
pub struct MotorCommand {
    /// One of the [`kind`] tags.
    pub kind: u32,
    /// Action id chosen by the agent; echoed in statuses and collisions.
    pub action_id: u32,
    /// Object id or reset type, for the kinds that take one.
    pub object_id: u32,
    /// Reserved, zero.
    pub reserved: u32,
    /// Float arguments, meaning per kind.
    pub args: [f32; 4],
}

/// A [`MotorCommand`] that does not decode to a [`Command`].
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum CommandDecodeError {
    /// The tag is not one of [`kind`].
    #[error("unknown command kind {kind} (action id {action_id})")]
    UnknownKind {
        /// The tag found.
        kind: u32,
        /// The action id of the command.
        action_id: u32,
    },
    /// An argument is NaN or infinite.
    #[error("command kind {kind} (action id {action_id}) has a non-finite argument {index}")]
    NonFinite {
        /// The tag.
        kind: u32,
        /// The action id of the command.
        action_id: u32,
        /// Index of the bad argument.
        index: usize,
    },
}
