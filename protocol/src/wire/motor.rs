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

/// Wire tags of [`MotorCommand::kind`].
pub mod kind {
    /// Walk `args[0]` degrees heading (world frame, 0..360) for `args[1]` metres.
    pub const MOVE: u32 = 1;
    /// Turn by `args[0]` degrees (clockwise, relative).
    pub const TURN: u32 = 2;
    /// Walk straight to `args[0..3]` (world position).
    pub const MOVE_TO: u32 = 3;
    /// Cancel the running movement.
    pub const CANCEL_MOVE: u32 = 4;
    /// Eye movement: pan left `args[0]`, pan right `args[1]`, tilt `args[2]` degrees.
    pub const EYE_MOVEMENT: u32 = 5;
    /// Fixate both eyes on the world point `args[0..3]`.
    pub const EYE_FIXATION: u32 = 6;
    /// Grasp the object `object_id`.
    pub const GRASP_ID: u32 = 7;
    /// Grasp what is seen at left-eye pixel (`args[0]`, `args[1]`).
    pub const GRASP_POS: u32 = 8;
    /// Point at the object `object_id`.
    pub const POINT_ID: u32 = 9;
    /// Point at left-eye pixel (`args[0]`, `args[1]`).
    pub const POINT_POS: u32 = 10;
    /// Interact with the object `object_id`.
    pub const INTERACT_ID: u32 = 11;
    /// Interact with what is seen at left-eye pixel (`args[0]`, `args[1]`).
    pub const INTERACT_POS: u32 = 12;
    /// Release the grasped object.
    pub const GRASP_RELEASE: u32 = 13;
    /// Reset the environment (`object_id` = reset type).
    pub const ENVIRONMENT_RESET: u32 = 14;
    /// Reset the trial (`object_id` = reset type).
    pub const TRIAL_RESET: u32 = 15;
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

/// A motor command, typed. The catalogue follows the original system's messages.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Command {
    /// Walk towards `heading_deg` (world frame, 0..360) for `distance` metres.
    Move {
        /// Heading in degrees, world frame.
        heading_deg: f32,
        /// Distance in metres.
        distance: f32,
    },
    /// Turn in place by `angle_deg` (positive = clockwise seen from above).
    Turn {
        /// Relative angle in degrees.
        angle_deg: f32,
    },
    /// Walk in a straight line to a world position.
    MoveTo {
        /// Target position in metres.
        target: Vec3,
    },
    /// Cancel the running movement.
    CancelMove,
    /// Move the eyes.
    EyeMovement {
        /// Pan of the left eye, degrees.
        pan_left_deg: f32,
        /// Pan of the right eye, degrees.
        pan_right_deg: f32,
        /// Tilt of both eyes, degrees.
        tilt_deg: f32,
    },
    /// Fixate a world point with both eyes.
    EyeFixation {
        /// Point in metres.
        target: Vec3,
    },
    /// Grasp an object by id.
    GraspId {
        /// Object id.
        object_id: u32,
    },
    /// Grasp what is seen at a left-eye pixel (0/0 = top left).
    GraspPos {
        /// Column in pixels.
        x_px: f32,
        /// Row in pixels.
        y_px: f32,
    },
    /// Point at an object by id.
    PointId {
        /// Object id.
        object_id: u32,
    },
    /// Point at what is seen at a left-eye pixel.
    PointPos {
        /// Column in pixels.
        x_px: f32,
        /// Row in pixels.
        y_px: f32,
    },
    /// Interact with an object by id.
    InteractId {
        /// Object id.
        object_id: u32,
    },
    /// Interact with what is seen at a left-eye pixel.
    InteractPos {
        /// Column in pixels.
        x_px: f32,
        /// Row in pixels.
        y_px: f32,
    },
    /// Release the grasped object.
    GraspRelease,
    /// Reset the environment.
    EnvironmentReset {
        /// Reset type (0 = default).
        reset_type: u32,
    },
    /// Reset the trial.
    TrialReset {
        /// Reset type (0 = default).
        reset_type: u32,
    },
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

impl Command {
    /// The wire tag of this command.
    pub fn kind(&self) -> u32 {
        match self {
            Self::Move { .. } => kind::MOVE,
            Self::Turn { .. } => kind::TURN,
            Self::MoveTo { .. } => kind::MOVE_TO,
            Self::CancelMove => kind::CANCEL_MOVE,
            Self::EyeMovement { .. } => kind::EYE_MOVEMENT,
            Self::EyeFixation { .. } => kind::EYE_FIXATION,
            Self::GraspId { .. } => kind::GRASP_ID,
            Self::GraspPos { .. } => kind::GRASP_POS,
            Self::PointId { .. } => kind::POINT_ID,
            Self::PointPos { .. } => kind::POINT_POS,
            Self::InteractId { .. } => kind::INTERACT_ID,
            Self::InteractPos { .. } => kind::INTERACT_POS,
            Self::GraspRelease => kind::GRASP_RELEASE,
            Self::EnvironmentReset { .. } => kind::ENVIRONMENT_RESET,
            Self::TrialReset { .. } => kind::TRIAL_RESET,
        }
    }

    /// A short lowercase name, for logs and recordings.
    pub fn name(&self) -> &'static str {
        kind_name(self.kind())
    }

    /// Encodes this command with the given action id.
    pub fn encode(&self, action_id: u32) -> MotorCommand {
        let mut m = MotorCommand {
            kind: self.kind(),
            action_id,
            ..MotorCommand::default()
        };
        match *self {
            Self::Move {
                heading_deg,
                distance,
            } => m.args[..2].copy_from_slice(&[heading_deg, distance]),
            Self::Turn { angle_deg } => m.args[0] = angle_deg,
            Self::MoveTo { target } | Self::EyeFixation { target } => {
                m.args[..3].copy_from_slice(&target.to_array())
            }
            Self::EyeMovement {
                pan_left_deg,
                pan_right_deg,
                tilt_deg,
            } => m.args[..3].copy_from_slice(&[pan_left_deg, pan_right_deg, tilt_deg]),
            Self::GraspId { object_id }
            | Self::PointId { object_id }
            | Self::InteractId { object_id } => m.object_id = object_id,
            Self::GraspPos { x_px, y_px }
            | Self::PointPos { x_px, y_px }
            | Self::InteractPos { x_px, y_px } => m.args[..2].copy_from_slice(&[x_px, y_px]),
            Self::EnvironmentReset { reset_type } | Self::TrialReset { reset_type } => {
                m.object_id = reset_type
            }
            Self::CancelMove | Self::GraspRelease => {}
        }
        m
    }
}

/// The lowercase name of a wire tag (`"unknown"` for unknown tags).
pub fn kind_name(tag: u32) -> &'static str {
    match tag {
        kind::MOVE => "move",
        kind::TURN => "turn",
        kind::MOVE_TO => "move_to",
        kind::CANCEL_MOVE => "cancel_move",
        kind::EYE_MOVEMENT => "eye_movement",
        kind::EYE_FIXATION => "eye_fixation",
        kind::GRASP_ID => "grasp_id",
        kind::GRASP_POS => "grasp_pos",
        kind::POINT_ID => "point_id",
        kind::POINT_POS => "point_pos",
        kind::INTERACT_ID => "interact_id",
        kind::INTERACT_POS => "interact_pos",
        kind::GRASP_RELEASE => "grasp_release",
        kind::ENVIRONMENT_RESET => "environment_reset",
        kind::TRIAL_RESET => "trial_reset",
        _ => "unknown",
    }
}

impl MotorCommand {
    /// Decodes the typed command. Unknown tags and non-finite arguments are errors;
    /// range checks belong to the simulator, which knows its world.
    ///
    /// # Errors
    /// [`CommandDecodeError`] naming the tag, the action id and what is wrong.
    pub fn decode(&self) -> Result<Command, CommandDecodeError> {
        let used = match self.kind {
            kind::MOVE | kind::GRASP_POS | kind::POINT_POS | kind::INTERACT_POS => 2,
            kind::TURN => 1,
            kind::MOVE_TO | kind::EYE_MOVEMENT | kind::EYE_FIXATION => 3,
            kind::CANCEL_MOVE
            | kind::GRASP_ID
            | kind::POINT_ID
            | kind::INTERACT_ID
            | kind::GRASP_RELEASE
            | kind::ENVIRONMENT_RESET
            | kind::TRIAL_RESET => 0,
            other => {
                return Err(CommandDecodeError::UnknownKind {
                    kind: other,
                    action_id: self.action_id,
                });
            }
        };
        if let Some(index) = self.args[..used].iter().position(|a| !a.is_finite()) {
            return Err(CommandDecodeError::NonFinite {
                kind: self.kind,
                action_id: self.action_id,
                index,
            });
        }
        let a = self.args;
        Ok(match self.kind {
            kind::MOVE => Command::Move {
                heading_deg: a[0],
                distance: a[1],
            },
            kind::TURN => Command::Turn { angle_deg: a[0] },
            kind::MOVE_TO => Command::MoveTo {
                target: Vec3::new(a[0], a[1], a[2]),
            },
            kind::CANCEL_MOVE => Command::CancelMove,
            kind::EYE_MOVEMENT => Command::EyeMovement {
                pan_left_deg: a[0],
                pan_right_deg: a[1],
                tilt_deg: a[2],
            },
            kind::EYE_FIXATION => Command::EyeFixation {
                target: Vec3::new(a[0], a[1], a[2]),
            },
            kind::GRASP_ID => Command::GraspId {
                object_id: self.object_id,
            },
            kind::GRASP_POS => Command::GraspPos {
                x_px: a[0],
                y_px: a[1],
            },
            kind::POINT_ID => Command::PointId {
                object_id: self.object_id,
            },
            kind::POINT_POS => Command::PointPos {
                x_px: a[0],
                y_px: a[1],
            },
            kind::INTERACT_ID => Command::InteractId {
                object_id: self.object_id,
            },
            kind::INTERACT_POS => Command::InteractPos {
                x_px: a[0],
                y_px: a[1],
            },
            kind::GRASP_RELEASE => Command::GraspRelease,
            kind::ENVIRONMENT_RESET => Command::EnvironmentReset {
                reset_type: self.object_id,
            },
            // The only tag left after the check above.
            _ => Command::TrialReset {
                reset_type: self.object_id,
            },
        })
    }
}
