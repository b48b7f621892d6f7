//! The world: a room with walls and coloured objects, and the agents' bodies (pose, head,
//! two eyes), moved by motor commands with simulated time only. Nothing here reads the
//! wall clock or a random generator: the same commands give the same trajectory, bit for
//! bit.
//!
//! Conventions: y is up; heading 0° looks along +z, 90° along +x (clockwise seen from
//! above); a body's rotation is `Quat::from_rotation_y(heading)`. Eye pan is relative to
//! the body (positive = to the right), tilt positive = up.
//!
//! Commands (see [`World::apply`]): movements (move, turn, move-to) run over several
//! cycles at `movement_speed` / `turn_speed_deg`; a new movement aborts the running one.
//! Eye movement and fixation run at `eye_speed_deg`; a new one aborts the running one.
//! Grasp, point, interact, release and the resets take effect at once and report only
//! their final status (Finished, or Aborted when the world does not allow them: too far,
//! not graspable, hands full, nothing seen at that pixel).
//!
//! Bodies are upright cylinders. A move stops at the first wall, object (where it reaches
//! into the body's height band) or other body, reporting a collision `(action id,
//! collider id)` and Finished, as the original did. A grasped object is carried in front
//! of the body and is no obstacle until it is released (put down on the floor there).

mod collisions;
mod commands;
mod motion;
mod sensors;
#[cfg(test)]
mod tests;

pub use commands::CommandRejected;

use glam::{Quat, Vec3};
use vrsync_bridge::AgentConfig;
use vrsync_bridge::{ActionState, HeadMotion, Pose};

use crate::geometry::heading_of;
use crate::world_config::{Shape, WorldConfig, WorldConfigError};

/// Collider id of the north wall (+z); east, south and west follow (1001..=1003).
pub const WALL_COLLIDER_ID: u32 = 1000;
/// Collider id of agent `n` is `AGENT_COLLIDER_BASE + n`.
pub const AGENT_COLLIDER_BASE: u32 = 2000;

/// Intrinsics of one of an agent's cameras.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraSpec {
    /// Name: `left` and `right` are the eyes, anything else sits at the head's centre.
    pub name: String,
    /// Width in pixels.
    pub width_px: u32,
    /// Height in pixels.
    pub height_px: u32,
    /// Horizontal field of view, degrees.
    pub fov_h_deg: f32,
    /// Vertical field of view, degrees.
    pub fov_v_deg: f32,
}

impl From<&vrsync_bridge::CameraConfig> for CameraSpec {
    fn from(c: &vrsync_bridge::CameraConfig) -> Self {
        Self {
            name: c.name.clone(),
            width_px: c.width_px,
            height_px: c.height_px,
            fov_h_deg: c.fov_horizontal_deg,
            fov_v_deg: c.fov_vertical_deg,
        }
    }
}

/// Which viewpoint a camera renders.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Viewpoint {
    /// The left eye (pan left, tilt).
    LeftEye,
    /// The right eye (pan right, tilt).
    RightEye,
    /// The head's centre, looking along the body.
    Body,
}

impl Viewpoint {
    /// The viewpoint of a camera called `name`.
    pub fn of_name(name: &str) -> Self {
        match name {
            "left" => Self::LeftEye,
            "right" => Self::RightEye,
            _ => Self::Body,
        }
    }
}

/// One object of the room, as it is now.
#[derive(Debug, Clone, PartialEq)]
pub struct Object {
    /// Id (1..=999).
    pub id: u32,
    /// Shape and size.
    pub shape: Shape,
    /// Centre, metres.
    pub position: Vec3,
    /// Colour.
    pub color: [u8; 3],
    /// Whether it can be grasped.
    pub graspable: bool,
    /// The agent holding it.
    pub held_by: Option<u32>,
    start: Vec3,
}

impl Object {
    /// Axis-aligned bounds `(min, max)`.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        let he = self.shape.half_extents();
        (self.position - he, self.position + he)
    }
}

/// Eye angles, degrees.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Eyes {
    /// Pan of the left eye (positive = right).
    pub pan_left_deg: f32,
    /// Pan of the right eye.
    pub pan_right_deg: f32,
    /// Tilt of both eyes (positive = up).
    pub tilt_deg: f32,
}

impl Eyes {
    fn to_array(self) -> [f32; 3] {
        [self.pan_left_deg, self.pan_right_deg, self.tilt_deg]
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Motion {
    /// Walk along `direction` for `remaining_m` while turning the body to `face_deg`.
    Move {
        id: u32,
        direction: Vec3,
        remaining_m: f32,
        face_deg: f32,
    },
    Turn {
        id: u32,
        remaining_deg: f32,
    },
}

impl Motion {
    fn id(&self) -> u32 {
        match *self {
            Self::Move { id, .. } | Self::Turn { id, .. } => id,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum EyeGoal {
    Angles(Eyes),
    Fixate(Vec3),
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct EyeAction {
    id: u32,
    goal: EyeGoal,
    reported: bool,
}

/// One agent's body.
#[derive(Debug, Clone, PartialEq)]
pub struct Body {
    /// Agent id.
    pub id: u32,
    /// Position on the floor, metres (y = 0).
    pub position: Vec3,
    /// Heading, degrees in `[0, 360)`.
    pub heading_deg: f32,
    /// Eye angles.
    pub eyes: Eyes,
    /// The object held.
    pub held: Option<u32>,
    cameras: Vec<CameraSpec>,
    motion: Option<Motion>,
    eye_action: Option<EyeAction>,
    statuses: Vec<(u32, ActionState)>,
    collisions: Vec<(u32, u32)>,
    reward: f32,
    in_region: Vec<bool>,
    start: (Vec3, f32),
    head_motion: HeadMotion,
    eye_velocity_deg: [f32; 3],
    previous: (Vec3, f32, Eyes),
}

impl Body {
    /// Status changes not yet reported to the agent.
    pub fn pending_statuses(&self) -> &[(u32, ActionState)] {
        &self.statuses
    }

    /// Collisions not yet reported to the agent: `(action id, collider id)`.
    pub fn pending_collisions(&self) -> &[(u32, u32)] {
        &self.collisions
    }

    /// Reward earned since the last sensor frame.
    pub fn pending_reward(&self) -> f32 {
        self.reward
    }

    /// The pose for the sensor header.
    pub fn pose(&self) -> Pose {
        Pose::from_glam(
            self.position,
            Quat::from_rotation_y(self.heading_deg.to_radians()),
        )
    }

    /// The agent's cameras, in image order.
    pub fn cameras(&self) -> &[CameraSpec] {
        &self.cameras
    }

    /// This body seen through other cameras (for rendering only: commands that name a
    /// pixel keep resolving against the body's own cameras in the world).
    pub fn with_cameras(&self, cameras: Vec<CameraSpec>) -> Self {
        Self {
            cameras,
            ..self.clone()
        }
    }

    fn left_camera(&self) -> Option<&CameraSpec> {
        self.cameras
            .iter()
            .find(|c| c.name == "left")
            .or(self.cameras.first())
    }

    fn abort_all(&mut self) {
        if let Some(m) = self.motion.take() {
            self.statuses.push((m.id(), ActionState::Aborted));
        }
        if let Some(e) = self.eye_action.take()
            && !e.reported
        {
            self.statuses.push((e.id, ActionState::Aborted));
        }
    }
}

/// The world state.
#[derive(Debug, Clone)]
pub struct World {
    cfg: WorldConfig,
    dt_s: f32,
    objects: Vec<Object>,
    bodies: Vec<Body>,
}

/// What a ray hit first.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RayHit {
    /// A wall, the floor or the ceiling.
    Room,
    /// The object with this id.
    Object(u32),
    /// The body of agent `n`.
    Agent(u32),
}

impl World {
    /// Builds the world of `config`: its `[world]` section and one body per configured
    /// agent, placed where `[[world.agent]]` says or, for agents not listed there, at the
    /// first free spot on rings around the centre, facing it.
    ///
    /// # Errors
    /// [`WorldConfigError`] for a bad `[world]` section or an agent that does not fit.
    pub fn from_config(config: &vrsync_bridge::Config) -> Result<Self, WorldConfigError> {
        let cfg = WorldConfig::from_config(config)?;
        Self::new(
            cfg,
            &config.agents,
            config.sync.simulation_time_per_frame.as_secs_f32(),
        )
        .map_err(|(key, reason)| WorldConfigError::Invalid {
            path: config.source.clone(),
            line: crate::world_config::line_in_source(config, &key),
            key,
            reason,
        })
    }

    /// Builds a world from a validated config; errors are `(key, reason)`, turned into a
    /// [`WorldConfigError`] by [`World::from_config`].
    fn new(cfg: WorldConfig, agents: &[AgentConfig], dt_s: f32) -> Result<Self, (String, String)> {
        let objects = cfg
            .objects
            .iter()
            .map(|o| Object {
                id: o.id,
                shape: o.shape,
                position: o.position,
                color: o.color,
                graspable: o.graspable,
                held_by: None,
                start: o.position,
            })
            .collect();
        let mut world = Self {
            cfg,
            dt_s,
            objects,
            bodies: Vec::with_capacity(agents.len()),
        };
        let n = agents.len().max(1);
        for (i, a) in agents.iter().enumerate() {
            let (position, heading_deg) = match world.cfg.start_of(a.id) {
                Some(s) => {
                    let p = Vec3::new(s.position.x, 0.0, s.position.y);
                    let idx = world
                        .cfg
                        .agents
                        .iter()
                        .position(|x| x.id == a.id)
                        .unwrap_or(0);
                    if let Some(c) = world.collider_at(None, p) {
                        return Err((
                            format!("world.agent[{idx}].position"),
                            format!(
                                "agent {} at {:?} overlaps {}",
                                a.id,
                                s.position.to_array(),
                                describe_collider(c)
                            ),
                        ));
                    }
                    (p, s.heading_deg)
                }
                None => world.free_spot(i, n).ok_or_else(|| {
                    (
                        "world.agent".to_string(),
                        format!(
                            "no free place for agent {}: give it a start with [[world.agent]]",
                            a.id
                        ),
                    )
                })?,
            };
            let cameras = a.cameras.iter().map(CameraSpec::from).collect();
            world.bodies.push(Body {
                id: a.id,
                position,
                heading_deg,
                eyes: Eyes::default(),
                held: None,
                cameras,
                motion: None,
                eye_action: None,
                statuses: Vec::with_capacity(8),
                collisions: Vec::with_capacity(4),
                reward: 0.0,
                in_region: Vec::new(),
                start: (position, heading_deg),
                head_motion: HeadMotion::default(),
                eye_velocity_deg: [0.0; 3],
                previous: (position, heading_deg, Eyes::default()),
            });
        }
        world.bodies.sort_by_key(|b| b.id);
        for i in 0..world.bodies.len() {
            world.bodies[i].in_region = world.regions_containing(world.bodies[i].position);
        }
        Ok(world)
    }

    /// A free start for the `i`-th of `n` agents without an explicit start: on rings of
    /// decreasing preference, facing the centre.
    fn free_spot(&self, i: usize, n: usize) -> Option<(Vec3, f32)> {
        let (hw, hd) = (self.cfg.room_width / 2.0, self.cfg.room_depth / 2.0);
        for ring in [0.5f32, 0.3, 0.7, 0.15, 0.85] {
            for k in 0..24 {
                let angle = (i as f32 / n as f32 + k as f32 / 24.0) * std::f32::consts::TAU;
                let p = Vec3::new(hw * ring * angle.sin(), 0.0, hd * ring * angle.cos());
                if self.collider_at(None, p).is_none() {
                    let heading = if p.length() > 1e-3 {
                        heading_of(-p.x, -p.z)
                    } else {
                        0.0
                    };
                    return Some((p, heading));
                }
            }
        }
        None
    }

    /// The validated world configuration.
    pub fn config(&self) -> &WorldConfig {
        &self.cfg
    }

    /// All bodies, in agent id order.
    pub fn bodies(&self) -> &[Body] {
        &self.bodies
    }

    /// All objects, in config order.
    pub fn objects(&self) -> &[Object] {
        &self.objects
    }

    /// The room's bounds `(min, max)`.
    pub fn room_bounds(&self) -> (Vec3, Vec3) {
        let (hw, hd) = (self.cfg.room_width / 2.0, self.cfg.room_depth / 2.0);
        (
            Vec3::new(-hw, 0.0, -hd),
            Vec3::new(hw, self.cfg.wall_height, hd),
        )
    }

    fn body_index(&self, id: u32) -> Result<usize, CommandRejected> {
        self.bodies
            .binary_search_by_key(&id, |b| b.id)
            .map_err(|_| CommandRejected::UnknownAgent(id))
    }

    /// Advances every body by one cycle of simulated time, in agent id order.
    pub fn step(&mut self) {
        for bi in 0..self.bodies.len() {
            self.step_motion(bi);
            self.carry(bi);
            // After the body moved: a fixation tracks its point from the new pose.
            self.step_eyes(bi);
            self.step_sensors(bi);
        }
    }

    /// Feeds every body's pose, eyes, held object, pending statuses, collisions and reward,
    /// and every object's position, into `hasher` (the trajectory hash).
    pub fn hash_into(&self, hasher: &mut blake3::Hasher) {
        let f = |h: &mut blake3::Hasher, v: f32| {
            h.update(&v.to_bits().to_le_bytes());
        };
        for b in &self.bodies {
            hasher.update(&b.id.to_le_bytes());
            for v in b.position.to_array() {
                f(hasher, v);
            }
            f(hasher, b.heading_deg);
            for v in b.eyes.to_array() {
                f(hasher, v);
            }
            hasher.update(&b.held.map_or(u32::MAX, |o| o).to_le_bytes());
            for &(action, state) in &b.statuses {
                hasher.update(&action.to_le_bytes());
                hasher.update(&(state as u32).to_le_bytes());
            }
            for &(action, collider) in &b.collisions {
                hasher.update(&action.to_le_bytes());
                hasher.update(&collider.to_le_bytes());
            }
            f(hasher, b.reward);
        }
        for o in &self.objects {
            for v in o.position.to_array() {
                f(hasher, v);
            }
        }
    }
}

/// What collider `id` is, in words ("the north wall", "agent 2", "object 7").
pub fn describe_collider(id: u32) -> String {
    match id {
        WALL_COLLIDER_ID => "the north wall".into(),
        1001 => "the east wall".into(),
        1002 => "the south wall".into(),
        1003 => "the west wall".into(),
        n if n >= AGENT_COLLIDER_BASE => format!("agent {}", n - AGENT_COLLIDER_BASE),
        n => format!("object {n}"),
    }
}
