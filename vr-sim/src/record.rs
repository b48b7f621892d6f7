//! The run recording (`vr-sim run --record FILE`): JSON lines that hold everything a
//! replay needs (`vr-sim replay`).
//!
//! - first line, the header: `{"record":"header","format":"vr-sim-record","version":2,
//!   "vr_sim":…,"agents":[…],"sync_mode":…,"simulation_time_per_frame_s":…,"config":"<TOML>"}`
//!   (`config` = the effective config, as spawned agents get it);
//! - then one line per agent per cycle, in the order the run applied the agents' commands
//!   (the config's agent order): the world's state after the cycle (pose, eyes, held object,
//!   statuses, collisions, reward), the applied commands as `[name, action id]`
//!   (`commands`, as in version 1), and, new in version 2, `sensed` (the host wrote the
//!   agent's sensor frame at the start of the cycle, which hands over and clears its
//!   pending statuses, collisions and reward) and `sent` (every command of the cycle in
//!   application order with its arguments, rejected ones with `error`; one that did not
//!   decode as `"kind":"undecoded"` with its wire `tag`);
//! - last line, the end: `{"record":"end","cycles":…,"trajectory_hash":…,…}`, written when
//!   the run ends normally (also after Ctrl-C); a record without it is truncated.
//!
//! Agent lines have an `agent` key; the header and the end have `record` instead.

use serde::{Deserialize, Serialize};
use vrsync_bridge::{Command, Config};

use crate::world::Body;

/// The `format` of a header line.
pub const FORMAT: &str = "vr-sim-record";
/// The record format version this vr-sim writes and replays.
pub const VERSION: u32 = 2;

/// The first line.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Header {
    /// Always `"header"`.
    pub record: String,
    /// Always [`FORMAT`].
    pub format: String,
    /// [`VERSION`].
    pub version: u32,
    /// The vr-sim version that wrote the record.
    pub vr_sim: String,
    /// Agent ids, in the config's order.
    pub agents: Vec<u32>,
    /// `[sync] sync_mode` of the run.
    pub sync_mode: bool,
    /// `[sync] simulation_time_per_frame`, seconds.
    pub simulation_time_per_frame_s: f64,
    /// The effective config as TOML.
    pub config: String,
}

impl Header {
    /// The header of a run of `config`. The shared secrets (`tcp_token`, zenoh `token`)
    /// are left out: a record is meant to be passed around, and a replay connects nothing.
    pub fn of(config: &Config) -> Self {
        let mut shared = config.clone();
        shared.transport.forget_secrets();
        Self {
            record: "header".into(),
            format: FORMAT.into(),
            version: VERSION,
            vr_sim: env!("CARGO_PKG_VERSION").into(),
            agents: config.agents.iter().map(|a| a.id).collect(),
            sync_mode: config.sync.sync_mode,
            simulation_time_per_frame_s: config.sync.simulation_time_per_frame.as_secs_f64(),
            config: shared.to_toml_string(),
        }
    }
}

/// The last line.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct End {
    /// Always `"end"`.
    pub record: String,
    /// Cycles completed (= cycles recorded).
    pub cycles: u64,
    /// The run's trajectory hash (the summary's `trajectory_hash`).
    pub trajectory_hash: String,
    /// Ended by SIGINT/SIGTERM.
    pub interrupted: bool,
    /// Commands applied in the whole run.
    pub commands_applied: u64,
    /// Commands rejected in the whole run.
    pub commands_rejected: u64,
}

/// A float written so that reading it back as JSON gives the same `f32` bit for bit: the
/// shortest form when serde_json reads that back exactly (always, as far as tested), else
/// the exact `f64` value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct F32(pub f32);

impl Serialize for F32 {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let v = self.0;
        let exact = serde_json::to_string(&v)
            .ok()
            .and_then(|t| serde_json::from_str::<f32>(&t).ok())
            .is_some_and(|back| back.to_bits() == v.to_bits());
        if exact {
            s.serialize_f32(v)
        } else {
            s.serialize_f64(f64::from(v))
        }
    }
}

impl<'de> Deserialize<'de> for F32 {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        // f64 → f32 is exact for an f64 that holds an f32 value.
        Ok(Self(f64::deserialize(d)? as f32))
    }
}

/// A command with its arguments, as recorded in `sent` (the wire command's fields, named).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
#[allow(missing_docs)]
pub enum RecordedCommand {
    Move {
        heading_deg: F32,
        distance: F32,
    },
    Turn {
        angle_deg: F32,
    },
    MoveTo {
        target: [F32; 3],
    },
    CancelMove,
    EyeMovement {
        pan_left_deg: F32,
        pan_right_deg: F32,
        tilt_deg: F32,
    },
    EyeFixation {
        target: [F32; 3],
    },
    GraspId {
        object_id: u32,
    },
    GraspPos {
        x_px: F32,
        y_px: F32,
    },
    PointId {
        object_id: u32,
    },
    PointPos {
        x_px: F32,
        y_px: F32,
    },
    InteractId {
        object_id: u32,
    },
    InteractPos {
        x_px: F32,
        y_px: F32,
    },
    GraspRelease,
    EnvironmentReset {
        reset_type: u32,
    },
    TrialReset {
        reset_type: u32,
    },
    /// A wire command that did not decode (unknown tag or non-finite argument): rejected
    /// before it reached the world, so a replay has nothing to apply.
    Undecoded {
        tag: u32,
    },
}

fn v3(v: glam::Vec3) -> [F32; 3] {
    [F32(v.x), F32(v.y), F32(v.z)]
}

impl From<Command> for RecordedCommand {
    fn from(c: Command) -> Self {
        match c {
            Command::Move {
                heading_deg,
                distance,
            } => Self::Move {
                heading_deg: F32(heading_deg),
                distance: F32(distance),
            },
            Command::Turn { angle_deg } => Self::Turn {
                angle_deg: F32(angle_deg),
            },
            Command::MoveTo { target } => Self::MoveTo { target: v3(target) },
            Command::CancelMove => Self::CancelMove,
            Command::EyeMovement {
                pan_left_deg,
                pan_right_deg,
                tilt_deg,
            } => Self::EyeMovement {
                pan_left_deg: F32(pan_left_deg),
                pan_right_deg: F32(pan_right_deg),
                tilt_deg: F32(tilt_deg),
            },
            Command::EyeFixation { target } => Self::EyeFixation { target: v3(target) },
            Command::GraspId { object_id } => Self::GraspId { object_id },
            Command::GraspPos { x_px, y_px } => Self::GraspPos {
                x_px: F32(x_px),
                y_px: F32(y_px),
            },
            Command::PointId { object_id } => Self::PointId { object_id },
            Command::PointPos { x_px, y_px } => Self::PointPos {
                x_px: F32(x_px),
                y_px: F32(y_px),
            },
            Command::InteractId { object_id } => Self::InteractId { object_id },
            Command::InteractPos { x_px, y_px } => Self::InteractPos {
                x_px: F32(x_px),
                y_px: F32(y_px),
            },
            Command::GraspRelease => Self::GraspRelease,
            Command::EnvironmentReset { reset_type } => Self::EnvironmentReset { reset_type },
            Command::TrialReset { reset_type } => Self::TrialReset { reset_type },
        }
    }
}

impl RecordedCommand {
    /// The command to apply (`None` for [`RecordedCommand::Undecoded`]).
    pub fn command(self) -> Option<Command> {
        let v = |t: [F32; 3]| glam::Vec3::new(t[0].0, t[1].0, t[2].0);
        use Command as C;
        use RecordedCommand as R;
        Some(match self {
            R::Move {
                heading_deg,
                distance,
            } => C::Move {
                heading_deg: heading_deg.0,
                distance: distance.0,
            },
            R::Turn { angle_deg } => C::Turn {
                angle_deg: angle_deg.0,
            },
            R::MoveTo { target } => C::MoveTo { target: v(target) },
            R::CancelMove => C::CancelMove,
            R::EyeMovement {
                pan_left_deg,
                pan_right_deg,
                tilt_deg,
            } => C::EyeMovement {
                pan_left_deg: pan_left_deg.0,
                pan_right_deg: pan_right_deg.0,
                tilt_deg: tilt_deg.0,
            },
            R::EyeFixation { target } => C::EyeFixation { target: v(target) },
            R::GraspId { object_id } => C::GraspId { object_id },
            R::GraspPos { x_px, y_px } => C::GraspPos {
                x_px: x_px.0,
                y_px: y_px.0,
            },
            R::PointId { object_id } => C::PointId { object_id },
            R::PointPos { x_px, y_px } => C::PointPos {
                x_px: x_px.0,
                y_px: y_px.0,
            },
            R::InteractId { object_id } => C::InteractId { object_id },
            R::InteractPos { x_px, y_px } => C::InteractPos {
                x_px: x_px.0,
                y_px: y_px.0,
            },
            R::GraspRelease => C::GraspRelease,
            R::EnvironmentReset { reset_type } => C::EnvironmentReset { reset_type },
            R::TrialReset { reset_type } => C::TrialReset { reset_type },
            R::Undecoded { .. } => return None,
        })
    }
}

/// One agent's cycle as the recording (and the Rerun log) writes it.
#[derive(Debug)]
pub struct AgentCommands {
    /// The agent.
    pub agent: u32,
    /// The barrier's outcome for the agent.
    pub outcome: vrsync_bridge::AgentOutcome,
    /// Applied commands: name and action id, in the order sent.
    pub applied: Vec<(&'static str, u32)>,
    /// Commands rejected.
    pub rejected: u32,
    /// Every command, in the order applied, with its arguments and rejection.
    pub sent: Vec<Sent>,
}

/// One command of an agent's cycle as recorded in `sent`: its kind and arguments (or
/// `"kind":"undecoded"` and the wire tag), and why it was rejected if it was.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Sent {
    /// The agent's action id.
    pub action: u32,
    /// The command.
    #[serde(flatten)]
    pub command: RecordedCommand,
    /// Why the world rejected it (absent: applied).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

/// One agent's cycle (an agent line).
#[derive(Debug, Serialize)]
pub struct AgentLine<'a> {
    /// The cycle.
    pub cycle: u64,
    /// Simulated time at the end of the cycle, seconds.
    pub sim_time_s: f64,
    /// Agent id.
    pub agent: u32,
    /// The barrier's outcome for the agent (`AgentOutcome::as_str`).
    pub outcome: &'a str,
    /// Body position after the cycle, metres.
    pub position: [f32; 3],
    /// Body rotation (quaternion x, y, z, w).
    pub rotation: [f32; 4],
    /// Heading, degrees.
    pub heading_deg: f32,
    /// Eye pan left, pan right, tilt, degrees.
    pub eyes_deg: [f32; 3],
    /// The object held.
    pub held: Option<u32>,
    /// Applied commands: `[name, action id]`, in application order.
    pub commands: Vec<(&'static str, u32)>,
    /// Commands rejected this cycle.
    pub rejected: u32,
    /// Pending `(action id, state)` statuses after the cycle.
    pub statuses: Vec<(u32, u32)>,
    /// Pending `(action id, collider id)` collisions after the cycle.
    pub collisions: Vec<(u32, u32)>,
    /// Pending reward after the cycle.
    pub reward: f32,
    /// The host wrote this agent's sensor frame at the start of the cycle.
    pub sensed: bool,
    /// Every command of the cycle, in application order, with arguments.
    pub sent: &'a [Sent],
}

/// The keys of an agent line that the world's state determines: what a replay compares.
pub const STATE_KEYS: [&str; 10] = [
    "position",
    "rotation",
    "heading_deg",
    "eyes_deg",
    "held",
    "statuses",
    "collisions",
    "reward",
    "commands",
    "rejected",
];

impl<'a> AgentLine<'a> {
    /// The line of `body` after cycle `cycle`.
    #[allow(clippy::too_many_arguments)]
    pub fn of(
        body: &Body,
        cycle: u64,
        sim_time_s: f64,
        outcome: &'a str,
        sensed: bool,
        commands: Vec<(&'static str, u32)>,
        rejected: u32,
        sent: &'a [Sent],
    ) -> Self {
        let pose = body.pose();
        Self {
            cycle,
            sim_time_s,
            agent: body.id,
            outcome,
            position: pose.position,
            rotation: pose.rotation,
            heading_deg: body.heading_deg,
            eyes_deg: [
                body.eyes.pan_left_deg,
                body.eyes.pan_right_deg,
                body.eyes.tilt_deg,
            ],
            held: body.held,
            commands,
            rejected,
            statuses: body
                .pending_statuses()
                .iter()
                .map(|&(a, s)| (a, s as u32))
                .collect(),
            collisions: body.pending_collisions().to_vec(),
            reward: body.pending_reward(),
            sensed,
            sent,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn f32_arguments_read_back_bit_for_bit() {
        // A spread of magnitudes and awkward values, and a walk over many bit patterns.
        let mut values = vec![0.1f32, -0.0, 1e-38, 3.4e38, 1.0 / 3.0, 359.99997, 2.5e-7];
        let mut bits = 0x0000_1234u32;
        for _ in 0..200_000 {
            bits = bits.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            let v = f32::from_bits(bits);
            if v.is_finite() {
                values.push(v);
            }
        }
        for v in values {
            let text = serde_json::to_string(&F32(v)).unwrap();
            let back: F32 = serde_json::from_str(&text).unwrap();
            assert_eq!(back.0.to_bits(), v.to_bits(), "{v:e} written as {text}");
        }
    }

    #[test]
    fn the_header_keeps_the_config_but_not_its_secrets() {
        let text = "session = \"s\"\n[transport]\nkind = \"tcp\"\ntcp_token = \"tcp-secret\"\n\
                    [transport.zenoh]\ntoken = \"zenoh-secret\"\n[[agent]]\nid = 3\n\
                    [world]\nroom_width = 7.0\n";
        let config = Config::from_toml_str(text, std::path::Path::new("t.toml")).unwrap();
        let header = Header::of(&config);
        assert!(!header.config.contains("secret"), "{}", header.config);
        assert_eq!(header.agents, [3]);
        let back = Config::from_toml_str(&header.config, std::path::Path::new("h")).unwrap();
        assert_eq!(back.world, config.world);
        assert_eq!(back.agents, config.agents);
        assert_eq!(back.sync, config.sync);
    }

    #[test]
    fn every_command_survives_the_record() {
        let v = glam::Vec3::new(0.1, -2.5, 1e-3);
        let all = [
            Command::Move {
                heading_deg: 12.345,
                distance: 0.7,
            },
            Command::Turn { angle_deg: -33.3 },
            Command::MoveTo { target: v },
            Command::CancelMove,
            Command::EyeMovement {
                pan_left_deg: 1.5,
                pan_right_deg: -2.25,
                tilt_deg: 0.1,
            },
            Command::EyeFixation { target: v },
            Command::GraspId { object_id: 7 },
            Command::GraspPos {
                x_px: 10.5,
                y_px: 3.0,
            },
            Command::PointId { object_id: 8 },
            Command::PointPos {
                x_px: 1.0,
                y_px: 2.0,
            },
            Command::InteractId { object_id: 9 },
            Command::InteractPos {
                x_px: 4.0,
                y_px: 5.0,
            },
            Command::GraspRelease,
            Command::EnvironmentReset { reset_type: 0 },
            Command::TrialReset { reset_type: 1 },
        ];
        for c in all {
            let sent = Sent {
                action: 42,
                command: c.into(),
                error: Some("x".into()),
            };
            let text = serde_json::to_string(&sent).unwrap();
            let value: serde_json::Value = serde_json::from_str(&text).unwrap();
            assert_eq!(value["kind"], c.name(), "{text}");
            let back: Sent = serde_json::from_str(&text).unwrap();
            assert_eq!(back, sent, "{text}");
            assert_eq!(back.command.command(), Some(c));
        }
        let undecoded = Sent {
            action: 3,
            command: RecordedCommand::Undecoded { tag: 99 },
            error: Some("unknown command kind 99".into()),
        };
        let text = serde_json::to_string(&undecoded).unwrap();
        assert_eq!(serde_json::from_str::<Sent>(&text).unwrap(), undecoded);
    }
}
