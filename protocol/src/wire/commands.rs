//! The command catalogue, defined once: every command an agent can send, with its wire tag,
//! its name, its fields and where they lie in a [`MotorCommand`], and the names the bindings
//! and the original client give it.
//!
//! The one definition is the `catalogue!` invocation below (the macro is in
//! `catalogue.rs`). From it come the [`Command`] enum, the [`kind`] tags, [`Command::kind`],
//! [`Command::name`], [`kind_name`], [`Command::encode`], [`MotorCommand::decode`] and
//! [`CommandKind::ALL`], the table the bindings' copies (C headers, C++, C#, Python stubs
//! and compat layers) are checked against, every kind and every parameter
//! (`bridge/ffi/tests/command_catalogue.rs`).
//! Adding a command is one entry here plus its behaviour in the world (and its lines in
//! each binding, which that test names when they are missing).
//!
//! A command's fields fill the wire form in order: each `f32` takes the next of `args`, a
//! point (`Vec3`) the next three, and a `u32` goes to `object_id` (a command has at most
//! one).

use super::*;

catalogue! {
    /// Walk towards `heading_deg` (world frame, 0..360) for `distance` metres.
    #[kind(MOVE = 1, name = "move", original = "sendAgentMovement")]
    #[wire = "Walk `args[0]` degrees heading (world frame, 0..360) for `args[1]` metres."]
    Move {
        /// Heading in degrees, world frame.
        heading_deg: f32 as (heading_deg),
        /// Distance in metres.
        distance: f32 as (distance_m),
    },
    /// Turn in place by `angle_deg` (positive = clockwise seen from above).
    #[kind(TURN = 2, name = "turn", original = "sendAgentTurn")]
    #[wire = "Turn by `args[0]` degrees (clockwise, relative)."]
    Turn {
        /// Relative angle in degrees.
        angle_deg: f32 as (angle_deg),
    },
    /// Walk in a straight line to a world position.
    #[kind(MOVE_TO = 3, name = "move_to", original = "sendAgentMoveTo")]
    #[wire = "Walk straight to `args[0..3]` (world position)."]
    MoveTo {
        /// Target position in metres.
        target: Vec3 as (x, y, z),
    },
    /// Cancel the running movement.
    #[kind(CANCEL_MOVE = 4, name = "cancel_move", original = "sendAgentCancelMovement")]
    #[wire = "Cancel the running movement."]
    CancelMove,
    /// Move the eyes.
    #[kind(EYE_MOVEMENT = 5, name = "eye_movement", original = "sendEyeMovement")]
    #[wire = "Eye movement: pan left `args[0]`, pan right `args[1]`, tilt `args[2]` degrees."]
    EyeMovement {
        /// Pan of the left eye, degrees.
        pan_left_deg: f32 as (pan_left_deg),
        /// Pan of the right eye, degrees.
        pan_right_deg: f32 as (pan_right_deg),
        /// Tilt of both eyes, degrees.
        tilt_deg: f32 as (tilt_deg),
    },
    /// Fixate a world point with both eyes.
    #[kind(EYE_FIXATION = 6, name = "eye_fixation", original = "sendEyeFixation")]
    #[wire = "Fixate both eyes on the world point `args[0..3]`."]
    EyeFixation {
        /// Point in metres.
        target: Vec3 as (x, y, z),
    },
    /// Grasp an object by id.
    #[kind(GRASP_ID = 7, name = "grasp_id", original = "sendGraspID")]
    #[wire = "Grasp the object `object_id`."]
    GraspId {
        /// Object id.
        object_id: u32 as (object_id),
    },
    /// Grasp what is seen at a left-eye pixel (0/0 = top left).
    #[kind(GRASP_POS = 8, name = "grasp_pos", original = "sendGraspPos")]
    #[wire = "Grasp what is seen at left-eye pixel (`args[0]`, `args[1]`)."]
    GraspPos {
        /// Column in pixels.
        x_px: f32 as (x_px),
        /// Row in pixels.
        y_px: f32 as (y_px),
    },
    /// Point at an object by id.
    #[kind(POINT_ID = 9, name = "point_id", original = "sendPointID")]
    #[wire = "Point at the object `object_id`."]
    PointId {
        /// Object id.
        object_id: u32 as (object_id),
    },
    /// Point at what is seen at a left-eye pixel.
    #[kind(POINT_POS = 10, name = "point_pos", original = "sendPointPos")]
    #[wire = "Point at left-eye pixel (`args[0]`, `args[1]`)."]
    PointPos {
        /// Column in pixels.
        x_px: f32 as (x_px),
        /// Row in pixels.
        y_px: f32 as (y_px),
    },
    /// Interact with an object by id.
    #[kind(INTERACT_ID = 11, name = "interact_id", original = "sendInteractionID")]
    #[wire = "Interact with the object `object_id`."]
    InteractId {
        /// Object id.
        object_id: u32 as (object_id),
    },
    /// Interact with what is seen at a left-eye pixel.
    #[kind(INTERACT_POS = 12, name = "interact_pos", original = "sendInteractionPos")]
    #[wire = "Interact with what is seen at left-eye pixel (`args[0]`, `args[1]`)."]
    InteractPos {
        /// Column in pixels.
        x_px: f32 as (x_px),
        /// Row in pixels.
        y_px: f32 as (y_px),
    },
    /// Release the grasped object.
    #[kind(GRASP_RELEASE = 13, name = "grasp_release", original = "sendGraspRelease")]
    #[wire = "Release the grasped object."]
    GraspRelease,
    /// Reset the environment.
    #[kind(ENVIRONMENT_RESET = 14, name = "environment_reset", original = "sendEnvironmentReset")]
    #[wire = "Reset the environment (`object_id` = reset type)."]
    EnvironmentReset {
        /// Reset type (0 = default).
        reset_type: u32 as (reset_type),
    },
    /// Reset the trial.
    #[kind(TRIAL_RESET = 15, name = "trial_reset", original = "sendTrialReset")]
    #[wire = "Reset the trial (`object_id` = reset type)."]
    TrialReset {
        /// Reset type (0 = default).
        reset_type: u32 as (reset_type),
    },
}

/// The type of one parameter of a command in the bindings.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ParamType {
    /// A 32-bit float (`float`, C# `float`, Python `float`): one of `args`.
    F32,
    /// A 32-bit unsigned integer (`uint32_t`, Python `int`): `object_id`.
    U32,
}

/// One parameter of a command as the bindings spell it (the C functions
/// `vrs_agent_send_<name>`, the C++ `send_<name>`, the Python classes' constructors): a
/// point field of [`Command`] is three parameters `x`, `y`, `z`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct CommandParam {
    /// The parameter's name (`heading_deg`, `distance_m`, `x`, `object_id`, …).
    pub name: &'static str,
    /// Its type.
    pub ty: ParamType,
}

/// One kind of the command catalogue: what every binding's copy of it must say.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub struct CommandKind {
    /// The wire tag ([`MotorCommand::kind`], one of [`kind`]).
    pub tag: u32,
    /// The lowercase name (`"move_to"`): [`Command::name`], logs and recordings, the C
    /// constants `VRS_COMMAND_<NAME>` and functions `vrs_agent_send_<name>`.
    pub name: &'static str,
    /// The [`Command`] variant (`"MoveTo"`): the C# enum member and the Python class.
    pub variant: &'static str,
    /// The original client's method (`"sendAgentMoveTo"`), kept by the compat layers
    /// (`vrsync.compat`, `vrsync/compat.hpp`).
    pub original: &'static str,
    /// Float arguments the kind uses (`args[..arg_count]`; [`MotorCommand::decode`]
    /// refuses a non-finite one).
    pub arg_count: usize,
    /// Its parameters, in the bindings' order.
    pub params: &'static [CommandParam],
}

/// The command as the bindings spell it: its variant and its parameters by name,
/// `Move(heading_deg=90, distance_m=0.5)`, `MoveTo(x=1, y=0, z=-2)`, `CancelMove()` (what
/// the Python classes' `repr` shows).
impl core::fmt::Display for Command {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let m = self.encode(0);
        let Some(k) = CommandKind::of(m.kind) else {
            return write!(f, "{self:?}");
        };
        write!(f, "{}(", k.variant)?;
        let mut args = m.args.iter();
        for (i, p) in k.params.iter().enumerate() {
            let sep = if i == 0 { "" } else { ", " };
            match p.ty {
                ParamType::F32 => {
                    let v = args.next().copied().unwrap_or_default();
                    write!(f, "{sep}{}={v}", p.name)?;
                }
                ParamType::U32 => write!(f, "{sep}{}={}", p.name, m.object_id)?,
            }
        }
        f.write_str(")")
    }
}

impl CommandKind {
    /// The kind with wire tag `tag`, if the catalogue has one.
    pub fn of(tag: u32) -> Option<&'static CommandKind> {
        Self::ALL.iter().find(|k| k.tag == tag)
    }
}

/// How a field of a [`Command`] lies in a [`MotorCommand`]: `at` is the next free index of
/// `args`.
trait WireField: Copy {
    /// Entries of `args` the field takes.
    const ARGS: usize;
    /// Parameters the field is in the bindings.
    const PARAMS: usize;
    /// The type of each of those parameters.
    const PARAM: ParamType;
    fn put(self, m: &mut MotorCommand, at: &mut usize);
    fn get(m: &MotorCommand, at: &mut usize) -> Self;
}

impl WireField for f32 {
    const ARGS: usize = 1;
    const PARAMS: usize = 1;
    const PARAM: ParamType = ParamType::F32;
    fn put(self, m: &mut MotorCommand, at: &mut usize) {
        m.args[*at] = self;
        *at += 1;
    }
    fn get(m: &MotorCommand, at: &mut usize) -> Self {
        *at += 1;
        m.args[*at - 1]
    }
}

impl WireField for Vec3 {
    const ARGS: usize = 3;
    const PARAMS: usize = 3;
    const PARAM: ParamType = ParamType::F32;
    fn put(self, m: &mut MotorCommand, at: &mut usize) {
        m.args[*at..*at + 3].copy_from_slice(&self.to_array());
        *at += 3;
    }
    fn get(m: &MotorCommand, at: &mut usize) -> Self {
        *at += 3;
        Vec3::from_slice(&m.args[*at - 3..*at])
    }
}

impl WireField for u32 {
    const ARGS: usize = 0;
    const PARAMS: usize = 1;
    const PARAM: ParamType = ParamType::U32;
    fn put(self, m: &mut MotorCommand, _: &mut usize) {
        m.object_id = self;
    }
    fn get(m: &MotorCommand, _: &mut usize) -> Self {
        m.object_id
    }
}

/// The first non-finite entry of `args[..used]`, as a decode error.
fn check_finite(m: &MotorCommand, used: usize) -> Result<(), CommandDecodeError> {
    match m.args[..used].iter().position(|a| !a.is_finite()) {
        Some(index) => Err(CommandDecodeError::NonFinite {
            kind: m.kind,
            action_id: m.action_id,
            index,
        }),
        None => Ok(()),
    }
}
