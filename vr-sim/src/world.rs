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

use glam::{Quat, Vec2, Vec3};
use vrsync_bridge::AgentConfig;
use vrsync_bridge::{
    ActionState, Command, EyePosition, GridPosition, HeadMotion, Pose, SensorHeader,
};

use crate::geometry::{
    self, Camera, angle_diff_deg, enter_box, heading_of, hit_cylinder, hit_sphere, recip,
};
use crate::world_config::{GoalAction, GoalKind, Shape, WorldConfig, WorldConfigError};

/// Collider id of the north wall (+z); east, south and west follow (1001..=1003).
pub const WALL_COLLIDER_ID: u32 = 1000;
/// Collider id of agent `n` is `AGENT_COLLIDER_BASE + n`.
pub const AGENT_COLLIDER_BASE: u32 = 2000;

/// Why a command was not applied. The world is untouched then.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum CommandRejected {
    /// The command cannot be decoded.
    #[error(transparent)]
    Decode(#[from] vrsync_bridge::CommandDecodeError),
    /// An argument is outside what this world accepts.
    #[error("{command}: {reason}")]
    OutOfRange {
        /// Command name.
        command: &'static str,
        /// What is wrong.
        reason: String,
    },
    /// No object has this id.
    #[error("{command}: no object with id {object}")]
    UnknownObject {
        /// Command name.
        command: &'static str,
        /// The id asked for.
        object: u32,
    },
    /// No such agent.
    #[error("unknown agent {0}")]
    UnknownAgent(u32),
}

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

/// An action on an object, resolved at once.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum ObjectAction {
    Grasp,
    Point,
    Interact,
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
            let cameras = a
                .cameras
                .iter()
                .map(|c| CameraSpec {
                    name: c.name.clone(),
                    width_px: c.width_px,
                    height_px: c.height_px,
                    fov_h_deg: c.fov_horizontal_deg,
                    fov_v_deg: c.fov_vertical_deg,
                })
                .collect();
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

    /// The centre of agent `body`'s head.
    pub fn head_of(&self, body: &Body) -> Vec3 {
        body.position + Vec3::new(0.0, self.cfg.eye_height, 0.0)
    }

    /// Position, yaw and pitch (degrees) of a viewpoint of `body`.
    pub fn eye_pose(&self, body: &Body, view: Viewpoint) -> (Vec3, f32, f32) {
        let head = self.head_of(body);
        let side = geometry::right_of(body.heading_deg) * (self.cfg.eye_separation / 2.0);
        match view {
            Viewpoint::LeftEye => (
                head - side,
                body.heading_deg + body.eyes.pan_left_deg,
                body.eyes.tilt_deg,
            ),
            Viewpoint::RightEye => (
                head + side,
                body.heading_deg + body.eyes.pan_right_deg,
                body.eyes.tilt_deg,
            ),
            Viewpoint::Body => (head, body.heading_deg, 0.0),
        }
    }

    /// The camera `spec` of `body` as it is now.
    pub fn camera(&self, body: &Body, spec: &CameraSpec) -> Camera {
        let (origin, yaw, pitch) = self.eye_pose(body, Viewpoint::of_name(&spec.name));
        Camera::new(
            origin,
            yaw,
            pitch,
            spec.fov_h_deg,
            spec.fov_v_deg,
            spec.width_px,
            spec.height_px,
        )
    }

    /// The first thing a ray from `origin` along `dir` hits (ignoring agent `skip`'s body
    /// and what it holds).
    pub fn cast_ray(&self, origin: Vec3, dir: Vec3, skip: Option<u32>) -> (f32, RayHit) {
        let inv = recip(dir);
        let (min, max) = self.room_bounds();
        let (mut best_t, mut best) = (geometry::exit_box(origin, inv, min, max).0, RayHit::Room);
        for o in &self.objects {
            if skip.is_some() && o.held_by == skip {
                continue;
            }
            let t = match o.shape {
                Shape::Sphere { radius } => hit_sphere(origin, dir, o.position, radius, 0.0),
                Shape::Box { .. } => {
                    let (lo, hi) = o.bounds();
                    enter_box(origin, inv, lo, hi, 0.0).map(|h| h.0)
                }
            };
            if let Some(t) = t
                && t < best_t
            {
                (best_t, best) = (t, RayHit::Object(o.id));
            }
        }
        for b in &self.bodies {
            if Some(b.id) == skip {
                continue;
            }
            if let Some((t, _)) = hit_cylinder(
                origin,
                dir,
                b.position,
                self.cfg.agent_radius,
                self.cfg.body_height,
                0.0,
            ) && t < best_t
            {
                (best_t, best) = (t, RayHit::Agent(b.id));
            }
        }
        (best_t, best)
    }

    /// The first obstacle body `skip` would overlap at `p`: a wall, an object standing in
    /// the body's height band, or another body.
    fn collider_at(&self, skip: Option<usize>, p: Vec3) -> Option<u32> {
        let r = self.cfg.agent_radius;
        let (hw, hd) = (self.cfg.room_width / 2.0, self.cfg.room_depth / 2.0);
        if p.z + r > hd {
            return Some(WALL_COLLIDER_ID);
        }
        if p.x + r > hw {
            return Some(WALL_COLLIDER_ID + 1);
        }
        if p.z - r < -hd {
            return Some(WALL_COLLIDER_ID + 2);
        }
        if p.x - r < -hw {
            return Some(WALL_COLLIDER_ID + 3);
        }
        let band = self.cfg.body_height;
        for o in &self.objects {
            if o.held_by.is_some() {
                continue;
            }
            let hit = match o.shape {
                Shape::Box { size } => {
                    let (lo, hi) = (o.position - size * 0.5, o.position + size * 0.5);
                    if hi.y <= 0.0 || lo.y >= band {
                        false
                    } else {
                        let cx = p.x.clamp(lo.x, hi.x);
                        let cz = p.z.clamp(lo.z, hi.z);
                        Vec2::new(p.x - cx, p.z - cz).length_squared() < r * r
                    }
                }
                Shape::Sphere { radius } => {
                    // Radius of the sphere's widest cut inside the body's height band.
                    let dy = if o.position.y < 0.0 {
                        -o.position.y
                    } else if o.position.y > band {
                        o.position.y - band
                    } else {
                        0.0
                    };
                    let cut2 = radius * radius - dy * dy;
                    cut2 > 0.0 && {
                        let reach = cut2.sqrt() + r;
                        Vec2::new(p.x - o.position.x, p.z - o.position.z).length_squared()
                            < reach * reach
                    }
                }
            };
            if hit {
                return Some(o.id);
            }
        }
        for (i, b) in self.bodies.iter().enumerate() {
            if Some(i) == skip {
                continue;
            }
            if Vec2::new(p.x - b.position.x, p.z - b.position.z).length_squared() < 4.0 * r * r {
                return Some(AGENT_COLLIDER_BASE + b.id);
            }
        }
        None
    }

    /// Region goals whose circle contains `p`.
    fn regions_containing(&self, p: Vec3) -> Vec<bool> {
        (0..self.cfg.goals.len())
            .map(|gi| self.in_region(gi, p))
            .collect()
    }

    /// Whether goal `gi` is a region containing `p`.
    fn in_region(&self, gi: usize, p: Vec3) -> bool {
        match self.cfg.goals[gi].kind {
            GoalKind::Region { center, radius } => {
                Vec2::new(p.x - center.x, p.z - center.y).length_squared() <= radius * radius
            }
            GoalKind::Object { .. } => false,
        }
    }

    /// Applies one command of agent `agent`. Movements and eye movements start here and run
    /// in [`World::step`]; everything else takes effect at once.
    ///
    /// # Errors
    /// [`CommandRejected`] for arguments out of range, unknown objects or agents; the world
    /// is untouched then.
    pub fn apply(
        &mut self,
        agent: u32,
        action_id: u32,
        command: Command,
    ) -> Result<(), CommandRejected> {
        let bi = self.body_index(agent)?;
        let max_d = self.cfg.max_move_distance;
        let (min, max) = self.room_bounds();
        let out =
            |command: &'static str, reason: String| CommandRejected::OutOfRange { command, reason };
        match command {
            Command::Move {
                heading_deg,
                distance,
            } => {
                if !(0.0..=max_d).contains(&distance) {
                    return Err(out(
                        "move",
                        format!("distance {distance} m outside 0..={max_d}"),
                    ));
                }
                if heading_deg.abs() > 3600.0 {
                    return Err(out(
                        "move",
                        format!("heading {heading_deg}° is not an angle"),
                    ));
                }
                let face_deg = heading_deg.rem_euclid(360.0);
                self.start_motion(
                    bi,
                    Motion::Move {
                        id: action_id,
                        direction: geometry::forward_of(face_deg, 0.0),
                        remaining_m: distance,
                        face_deg,
                    },
                );
            }
            Command::Turn { angle_deg } => {
                if angle_deg.abs() > 3600.0 {
                    return Err(out("turn", format!("angle {angle_deg}° is out of range")));
                }
                self.start_motion(
                    bi,
                    Motion::Turn {
                        id: action_id,
                        remaining_deg: angle_deg,
                    },
                );
            }
            Command::MoveTo { target } => {
                if target.x < min.x || target.x > max.x || target.z < min.z || target.z > max.z {
                    return Err(out(
                        "move_to",
                        format!("target {target} is outside the room"),
                    ));
                }
                let body = &self.bodies[bi];
                let to = Vec3::new(target.x - body.position.x, 0.0, target.z - body.position.z);
                let len = to.length();
                if len > max_d {
                    return Err(out(
                        "move_to",
                        format!("target {len} m away, more than {max_d}"),
                    ));
                }
                let face_deg = if len > 1e-6 {
                    heading_of(to.x, to.z)
                } else {
                    body.heading_deg
                };
                self.start_motion(
                    bi,
                    Motion::Move {
                        id: action_id,
                        direction: to.normalize_or_zero(),
                        remaining_m: len,
                        face_deg,
                    },
                );
            }
            Command::CancelMove => {
                let body = &mut self.bodies[bi];
                if let Some(m) = body.motion.take() {
                    body.statuses.push((m.id(), ActionState::Aborted));
                }
                body.statuses.push((action_id, ActionState::Finished));
            }
            Command::EyeMovement {
                pan_left_deg,
                pan_right_deg,
                tilt_deg,
            } => {
                let (mp, mt) = (self.cfg.max_pan_deg, self.cfg.max_tilt_deg);
                if pan_left_deg.abs() > mp || pan_right_deg.abs() > mp || tilt_deg.abs() > mt {
                    return Err(out(
                        "eye_movement",
                        format!(
                            "pan {pan_left_deg}°/{pan_right_deg}°, tilt {tilt_deg}° beyond ±{mp}°/±{mt}°"
                        ),
                    ));
                }
                self.start_eye_action(
                    bi,
                    action_id,
                    EyeGoal::Angles(Eyes {
                        pan_left_deg,
                        pan_right_deg,
                        tilt_deg,
                    }),
                );
            }
            Command::EyeFixation { target } => {
                if target.cmplt(min).any() || target.cmpgt(max).any() {
                    return Err(out(
                        "eye_fixation",
                        format!("target {target} is outside the room"),
                    ));
                }
                self.start_eye_action(bi, action_id, EyeGoal::Fixate(target));
            }
            Command::GraspId { object_id } => {
                self.object_action(bi, action_id, "grasp", object_id, ObjectAction::Grasp)?;
            }
            Command::PointId { object_id } => {
                self.object_action(bi, action_id, "point", object_id, ObjectAction::Point)?;
            }
            Command::InteractId { object_id } => {
                self.object_action(bi, action_id, "interact", object_id, ObjectAction::Interact)?;
            }
            Command::GraspPos { x_px, y_px } => {
                self.pixel_action(bi, action_id, "grasp_pos", x_px, y_px, ObjectAction::Grasp)?;
            }
            Command::PointPos { x_px, y_px } => {
                self.pixel_action(bi, action_id, "point_pos", x_px, y_px, ObjectAction::Point)?;
            }
            Command::InteractPos { x_px, y_px } => {
                self.pixel_action(
                    bi,
                    action_id,
                    "interact_pos",
                    x_px,
                    y_px,
                    ObjectAction::Interact,
                )?;
            }
            Command::GraspRelease => {
                let state = match self.bodies[bi].held.take() {
                    Some(object) => {
                        self.put_down(bi, object);
                        ActionState::Finished
                    }
                    None => ActionState::Aborted,
                };
                self.bodies[bi].statuses.push((action_id, state));
            }
            Command::EnvironmentReset { reset_type } => {
                if reset_type != 0 {
                    return Err(out(
                        "environment_reset",
                        format!("reset type {reset_type} (only 0 exists)"),
                    ));
                }
                for o in &mut self.objects {
                    o.position = o.start;
                    o.held_by = None;
                }
                for i in 0..self.bodies.len() {
                    self.reset_body(i);
                }
                self.bodies[bi]
                    .statuses
                    .push((action_id, ActionState::Finished));
            }
            Command::TrialReset { reset_type } => {
                if reset_type != 0 {
                    return Err(out(
                        "trial_reset",
                        format!("reset type {reset_type} (only 0 exists)"),
                    ));
                }
                if let Some(object) = self.bodies[bi].held
                    && let Some(o) = self.objects.iter_mut().find(|o| o.id == object)
                {
                    o.position = o.start;
                    o.held_by = None;
                }
                self.reset_body(bi);
                self.bodies[bi]
                    .statuses
                    .push((action_id, ActionState::Finished));
            }
        }
        Ok(())
    }

    fn start_motion(&mut self, bi: usize, motion: Motion) {
        let body = &mut self.bodies[bi];
        if let Some(old) = body.motion.replace(motion) {
            body.statuses.push((old.id(), ActionState::Aborted));
        }
        body.statuses.push((motion.id(), ActionState::InExecution));
    }

    fn start_eye_action(&mut self, bi: usize, id: u32, goal: EyeGoal) {
        let body = &mut self.bodies[bi];
        let new = EyeAction {
            id,
            goal,
            reported: false,
        };
        if let Some(old) = body.eye_action.replace(new)
            && !old.reported
        {
            body.statuses.push((old.id, ActionState::Aborted));
        }
        body.statuses.push((id, ActionState::InExecution));
    }

    /// Back to the start pose, eyes straight, nothing held, running actions aborted.
    fn reset_body(&mut self, bi: usize) {
        let in_region = {
            let start = self.bodies[bi].start.0;
            self.regions_containing(start)
        };
        let body = &mut self.bodies[bi];
        body.abort_all();
        (body.position, body.heading_deg) = body.start;
        body.eyes = Eyes::default();
        body.held = None;
        body.in_region = in_region;
        body.previous = (body.position, body.heading_deg, body.eyes);
        body.head_motion = HeadMotion::default();
        body.eye_velocity_deg = [0.0; 3];
    }

    fn object_action(
        &mut self,
        bi: usize,
        action_id: u32,
        command: &'static str,
        object: u32,
        action: ObjectAction,
    ) -> Result<(), CommandRejected> {
        if !self.objects.iter().any(|o| o.id == object) {
            return Err(CommandRejected::UnknownObject { command, object });
        }
        self.resolve_object_action(bi, action_id, object, action);
        Ok(())
    }

    fn pixel_action(
        &mut self,
        bi: usize,
        action_id: u32,
        command: &'static str,
        x_px: f32,
        y_px: f32,
        action: ObjectAction,
    ) -> Result<(), CommandRejected> {
        let body = &self.bodies[bi];
        let Some(spec) = body.left_camera() else {
            return Err(CommandRejected::OutOfRange {
                command,
                reason: format!("agent {} has no camera", body.id),
            });
        };
        if !(0.0..spec.width_px as f32).contains(&x_px)
            || !(0.0..spec.height_px as f32).contains(&y_px)
        {
            return Err(CommandRejected::OutOfRange {
                command,
                reason: format!(
                    "pixel ({x_px}, {y_px}) outside the {}x{} left image",
                    spec.width_px, spec.height_px
                ),
            });
        }
        let mut spec = spec.clone();
        spec.name = "left".into();
        let cam = self.camera(body, &spec);
        let (_, hit) = self.cast_ray(cam.origin, cam.ray_through(x_px, y_px), Some(body.id));
        match hit {
            RayHit::Object(object) => self.resolve_object_action(bi, action_id, object, action),
            RayHit::Room | RayHit::Agent(_) => self.bodies[bi]
                .statuses
                .push((action_id, ActionState::Aborted)),
        }
        Ok(())
    }

    /// Distance from body `bi`'s surface to object `o`'s surface, on the floor plane.
    fn gap_to(&self, bi: usize, o: &Object) -> f32 {
        let p = self.bodies[bi].position;
        let d = match o.shape {
            Shape::Box { size } => {
                let (lo, hi) = (o.position - size * 0.5, o.position + size * 0.5);
                Vec2::new(p.x - p.x.clamp(lo.x, hi.x), p.z - p.z.clamp(lo.z, hi.z)).length()
            }
            Shape::Sphere { radius } => {
                (Vec2::new(p.x - o.position.x, p.z - o.position.z).length() - radius).max(0.0)
            }
        };
        (d - self.cfg.agent_radius).max(0.0)
    }

    fn resolve_object_action(
        &mut self,
        bi: usize,
        action_id: u32,
        object: u32,
        action: ObjectAction,
    ) {
        let Some(oi) = self.objects.iter().position(|o| o.id == object) else {
            self.bodies[bi]
                .statuses
                .push((action_id, ActionState::Aborted));
            return;
        };
        let me = self.bodies[bi].id;
        let o = &self.objects[oi];
        let near = o.held_by == Some(me) || self.gap_to(bi, o) <= self.cfg.reach_distance;
        let ok = match action {
            ObjectAction::Point => true,
            ObjectAction::Interact => near,
            ObjectAction::Grasp => {
                near && o.graspable && o.held_by.is_none() && self.bodies[bi].held.is_none()
            }
        };
        if ok {
            if action == ObjectAction::Grasp {
                self.objects[oi].held_by = Some(me);
                self.bodies[bi].held = Some(object);
                self.carry(bi);
            }
            let goal_action = match action {
                ObjectAction::Grasp => GoalAction::Grasp,
                ObjectAction::Point => GoalAction::Point,
                ObjectAction::Interact => GoalAction::Interact,
            };
            let reward: f32 = self
                .cfg
                .goals
                .iter()
                .filter(|g| {
                    g.kind
                        == GoalKind::Object {
                            object,
                            action: goal_action,
                        }
                })
                .map(|g| g.reward)
                .sum();
            self.bodies[bi].reward += reward;
        }
        let state = if ok {
            ActionState::Finished
        } else {
            ActionState::Aborted
        };
        self.bodies[bi].statuses.push((action_id, state));
    }

    /// Where body `bi`'s hand holds an object with these half extents.
    fn hand_position(&self, bi: usize, half: Vec3) -> Vec3 {
        let b = &self.bodies[bi];
        let reach = self.cfg.agent_radius + half.x.max(half.z) + 0.05;
        let mut p = b.position + geometry::forward_of(b.heading_deg, 0.0) * reach;
        p.y = (self.cfg.body_height * 0.6).max(half.y);
        p
    }

    /// Moves body `bi`'s held object to its hand.
    fn carry(&mut self, bi: usize) {
        let Some(object) = self.bodies[bi].held else {
            return;
        };
        if let Some(oi) = self.objects.iter().position(|o| o.id == object) {
            let p = self.hand_position(bi, self.objects[oi].shape.half_extents());
            self.objects[oi].position = p;
        }
    }

    /// Puts `object` down on the floor below body `bi`'s hand, inside the room.
    fn put_down(&mut self, bi: usize, object: u32) {
        let Some(oi) = self.objects.iter().position(|o| o.id == object) else {
            return;
        };
        let half = self.objects[oi].shape.half_extents();
        let mut p = self.hand_position(bi, half);
        let (min, max) = self.room_bounds();
        p.x = p.x.clamp(min.x + half.x, max.x - half.x);
        p.z = p.z.clamp(min.z + half.z, max.z - half.z);
        p.y = half.y;
        self.objects[oi].position = p;
        self.objects[oi].held_by = None;
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

    fn step_motion(&mut self, bi: usize) {
        let dt = self.dt_s;
        let Some(motion) = self.bodies[bi].motion else {
            return;
        };
        let turn_step = self.cfg.turn_speed_deg * dt;
        match motion {
            Motion::Turn { id, remaining_deg } => {
                let step = turn_step.min(remaining_deg.abs()) * remaining_deg.signum();
                let body = &mut self.bodies[bi];
                body.heading_deg = (body.heading_deg + step).rem_euclid(360.0);
                let left = remaining_deg - step;
                if left.abs() <= 1e-3 {
                    body.statuses.push((id, ActionState::Finished));
                    body.motion = None;
                } else {
                    body.statuses.push((id, ActionState::Rotating));
                    body.motion = Some(Motion::Turn {
                        id,
                        remaining_deg: left,
                    });
                }
            }
            Motion::Move {
                id,
                direction,
                remaining_m,
                face_deg,
            } => {
                // Turn towards the walking direction while walking.
                let diff = angle_diff_deg(face_deg, self.bodies[bi].heading_deg);
                let rot = turn_step.min(diff.abs()) * diff.signum();
                let rotating_left = (diff - rot).abs() > 1e-3;
                {
                    let body = &mut self.bodies[bi];
                    body.heading_deg = if rotating_left {
                        (body.heading_deg + rot).rem_euclid(360.0)
                    } else {
                        face_deg
                    };
                }
                let step = (self.cfg.movement_speed * dt).min(remaining_m);
                let from = self.bodies[bi].position;
                let (to, collider) = self.walk(bi, from, direction * step);
                let walked = step > 0.0;
                let body = &mut self.bodies[bi];
                body.position = to;
                if let Some(c) = collider {
                    body.collisions.push((id, c));
                    body.statuses.push((id, ActionState::Finished));
                    body.motion = None;
                    return;
                }
                let remaining_m = remaining_m - step;
                let walking_left = remaining_m > 1e-4;
                if !walking_left && !rotating_left {
                    body.statuses.push((id, ActionState::Finished));
                    body.motion = None;
                    return;
                }
                let state = match (walked, rot.abs() > 0.0) {
                    (true, true) => ActionState::WalkingRotating,
                    (true, false) => ActionState::Walking,
                    (false, _) => ActionState::Rotating,
                };
                body.statuses.push((id, state));
                body.motion = Some(Motion::Move {
                    id,
                    direction,
                    remaining_m: remaining_m.max(0.0),
                    face_deg,
                });
            }
        }
    }

    /// Moves body `bi` from `from` by `delta` until the first obstacle it runs into: the
    /// reachable position and the obstacle's id. A body that already overlaps something
    /// (an object put down against it) walks freely until it is clear.
    fn walk(&self, bi: usize, from: Vec3, delta: Vec3) -> (Vec3, Option<u32>) {
        let free_at_start = self.collider_at(Some(bi), from).is_none();
        let blocked = |p: Vec3| self.collider_at(Some(bi), p).filter(|_| free_at_start);
        let Some(collider) = blocked(from + delta) else {
            return (from + delta, None);
        };
        // Bisection for the contact point: deterministic, and exact to ~delta/4096.
        let (mut lo, mut hi) = (0.0f32, 1.0f32);
        for _ in 0..12 {
            let mid = (lo + hi) / 2.0;
            if blocked(from + delta * mid).is_some() {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        (from + delta * lo, Some(collider))
    }

    fn step_eyes(&mut self, bi: usize) {
        let Some(action) = self.bodies[bi].eye_action else {
            return;
        };
        let target = match action.goal {
            EyeGoal::Angles(e) => e,
            EyeGoal::Fixate(point) => {
                let body = &self.bodies[bi];
                let (mp, mt) = (self.cfg.max_pan_deg, self.cfg.max_tilt_deg);
                let pan = |view| {
                    let (eye, _, _) = self.eye_pose(body, view);
                    let to = point - eye;
                    angle_diff_deg(heading_of(to.x, to.z), body.heading_deg).clamp(-mp, mp)
                };
                let to = point - self.head_of(body);
                let tilt =
                    to.y.atan2(Vec2::new(to.x, to.z).length())
                        .to_degrees()
                        .clamp(-mt, mt);
                Eyes {
                    pan_left_deg: pan(Viewpoint::LeftEye),
                    pan_right_deg: pan(Viewpoint::RightEye),
                    tilt_deg: tilt,
                }
            }
        };
        let max_step = self.cfg.eye_speed_deg * self.dt_s;
        let toward = |from: f32, to: f32| {
            let d = to - from;
            if d.abs() <= max_step {
                to
            } else {
                from + max_step * d.signum()
            }
        };
        let body = &mut self.bodies[bi];
        body.eyes = Eyes {
            pan_left_deg: toward(body.eyes.pan_left_deg, target.pan_left_deg),
            pan_right_deg: toward(body.eyes.pan_right_deg, target.pan_right_deg),
            tilt_deg: toward(body.eyes.tilt_deg, target.tilt_deg),
        };
        if body.eyes == target && !action.reported {
            body.statuses.push((action.id, ActionState::Finished));
            body.eye_action = match action.goal {
                // A fixation keeps tracking its point until the next eye command.
                EyeGoal::Fixate(_) => Some(EyeAction {
                    reported: true,
                    ..action
                }),
                EyeGoal::Angles(_) => None,
            };
        }
    }

    /// Head motion and eye sensors (differences per cycle), and region rewards.
    fn step_sensors(&mut self, bi: usize) {
        let dt = self.dt_s;
        // Region rewards, updating the flags in place (no allocation per cycle).
        for gi in 0..self.cfg.goals.len() {
            let inside = self.in_region(gi, self.bodies[bi].position);
            let body = &mut self.bodies[bi];
            if inside && !body.in_region[gi] {
                body.reward += self.cfg.goals[gi].reward;
            }
            body.in_region[gi] = inside;
        }
        let body = &mut self.bodies[bi];
        let (p0, h0, e0) = body.previous;
        let velocity = (body.position - p0) / dt;
        let old = body.head_motion;
        let acceleration = (velocity - Vec3::from_array(old.velocity)) / dt;
        let yaw_rate = angle_diff_deg(body.heading_deg, h0) / dt;
        let yaw_acc = (yaw_rate - old.angular_velocity_deg[1]) / dt;
        body.head_motion = HeadMotion {
            velocity: velocity.to_array(),
            acceleration: acceleration.to_array(),
            angular_velocity_deg: [0.0, yaw_rate, 0.0],
            angular_acceleration_deg: [0.0, yaw_acc, 0.0],
        };
        let (e, p) = (body.eyes.to_array(), e0.to_array());
        body.eye_velocity_deg = [e[0] - p[0], e[1] - p[1], e[2] - p[2]];
        body.previous = (body.position, body.heading_deg, body.eyes);
    }

    /// Writes agent `id`'s sensors into a frame header and forgets the reported events.
    pub fn write_sensors(&mut self, id: u32, header: &mut SensorHeader) {
        let Ok(bi) = self.body_index(id) else {
            return;
        };
        let body = &mut self.bodies[bi];
        header.pose = body.pose();
        header.grid = GridPosition {
            position: body.position.to_array(),
            rotation_deg: [0.0, body.heading_deg, 0.0],
        };
        header.head_motion = body.head_motion;
        header.eye = EyePosition {
            rotation_deg: body.eyes.to_array(),
            rotation_velocity_deg: body.eye_velocity_deg,
        };
        header.reward = body.reward;
        header.status_count = 0;
        header.collision_count = 0;
        for &(action, state) in &body.statuses {
            header.push_status(action, state);
        }
        for &(action, collider) in &body.collisions {
            header.push_collision(action, collider);
        }
        body.statuses.clear();
        body.collisions.clear();
        body.reward = 0.0;
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

fn describe_collider(id: u32) -> String {
    match id {
        WALL_COLLIDER_ID => "the north wall".into(),
        1001 => "the east wall".into(),
        1002 => "the south wall".into(),
        1003 => "the west wall".into(),
        n if n >= AGENT_COLLIDER_BASE => format!("agent {}", n - AGENT_COLLIDER_BASE),
        n => format!("object {n}"),
    }
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::*;
    use vrsync_bridge::Config;

    const CAMS: &str = "[[agent.camera]]\nname = \"left\"\nwidth = 64\nheight = 48\nfov_horizontal_deg = 90.0\nfov_vertical_deg = 73.74\n";

    /// A 10 × 10 room, dt 0.1 s, speed 3 m/s, turning 180°/s, eyes 300°/s; a red sphere
    /// (id 1, graspable) at (0, 0.4, 3) and a box (id 2) at (-3, 0.5, 0); agents as given.
    fn world_with(agents: &[(u32, [f32; 2], f32)], extra: &str) -> World {
        let mut text = String::from("session = \"w\"\n");
        for &(id, _, _) in agents {
            text += &format!("[[agent]]\nid = {id}\n{CAMS}");
        }
        text += "[world]\n";
        text += extra;
        text += "[[world.object]]\nid = 1\nshape = \"sphere\"\nposition = [0.0, 0.4, 3.0]\nradius = 0.4\ncolor = [220, 30, 30]\ngraspable = true\n";
        text += "[[world.object]]\nid = 2\nshape = \"box\"\nposition = [-3.0, 0.5, 0.0]\nsize = [1.0, 1.0, 1.0]\ncolor = [40, 90, 220]\n";
        text += "[[world.goal]]\ncenter = [0.0, 1.5]\nradius = 0.5\nreward = 1.0\n";
        text += "[[world.goal]]\nobject = 1\naction = \"grasp\"\nreward = 5.0\n";
        for &(id, [x, z], h) in agents {
            text += &format!(
                "[[world.agent]]\nid = {id}\nposition = [{x:?}, {z:?}]\nheading_deg = {h:?}\n"
            );
        }
        let config = Config::from_toml_str(&text, Path::new("t.toml")).unwrap();
        World::from_config(&config).unwrap()
    }

    fn world() -> World {
        world_with(&[(0, [0.0, 0.0], 0.0)], "")
    }

    fn sensors(w: &mut World, id: u32) -> SensorHeader {
        let mut h = SensorHeader::default();
        w.write_sensors(id, &mut h);
        h
    }

    fn statuses(h: &SensorHeader) -> Vec<(u32, ActionState)> {
        h.statuses()
            .iter()
            .map(|s| (s.action_id, ActionState::from_u32(s.state).unwrap()))
            .collect()
    }

    fn close(a: Vec3, b: Vec3) -> bool {
        (a - b).length() < 1e-4
    }

    use ActionState::{Aborted, Finished, InExecution, Rotating, Walking, WalkingRotating};

    #[test]
    fn move_walks_speed_times_dt_per_cycle_and_finishes() {
        let mut w = world();
        let mv = Command::Move {
            heading_deg: 0.0,
            distance: 0.75,
        };
        w.apply(0, 1, mv).unwrap();
        w.step(); // 0.3 m
        assert!(close(w.bodies()[0].position, Vec3::new(0.0, 0.0, 0.3)));
        assert_eq!(
            statuses(&sensors(&mut w, 0)),
            [(1, InExecution), (1, Walking)]
        );
        w.step(); // 0.6 m
        let h = sensors(&mut w, 0);
        assert_eq!(statuses(&h), [(1, Walking)]);
        assert!(
            (h.head_motion.velocity[2] - 3.0).abs() < 1e-3,
            "{:?}",
            h.head_motion
        );
        w.step(); // 0.75 m, done
        assert_eq!(statuses(&sensors(&mut w, 0)), [(1, Finished)]);
        assert!(close(w.bodies()[0].position, Vec3::new(0.0, 0.0, 0.75)));
        w.step();
        let h = sensors(&mut w, 0);
        assert!(h.statuses().is_empty());
        assert_eq!(h.head_motion.velocity, [0.0; 3]);
    }

    #[test]
    fn move_turns_towards_its_heading_while_walking() {
        let mut w = world();
        w.apply(
            0,
            1,
            Command::Move {
                heading_deg: 90.0,
                distance: 0.6,
            },
        )
        .unwrap();
        w.step(); // walks east 0.3 m, turns 18° of 90°
        w.step(); // walks 0.6 m: walking done, still turning
        w.step(); // turning only
        let h = sensors(&mut w, 0);
        assert_eq!(
            statuses(&h),
            [
                (1, InExecution),
                (1, WalkingRotating),
                (1, WalkingRotating),
                (1, Rotating)
            ]
        );
        assert!(close(w.bodies()[0].position, Vec3::new(0.6, 0.0, 0.0)));
        assert!((w.bodies()[0].heading_deg - 54.0).abs() < 1e-3);
        assert!((h.head_motion.angular_velocity_deg[1] - 180.0).abs() < 1e-2);
        w.step();
        w.step();
        assert_eq!(
            statuses(&sensors(&mut w, 0)),
            [(1, Rotating), (1, Finished)]
        );
        assert_eq!(w.bodies()[0].heading_deg, 90.0);
    }

    #[test]
    fn turn_rotates_at_turn_speed_both_ways() {
        let mut w = world();
        w.apply(0, 4, Command::Turn { angle_deg: -45.0 }).unwrap();
        w.step();
        w.step();
        w.step();
        assert_eq!(
            statuses(&sensors(&mut w, 0)),
            [
                (4, InExecution),
                (4, Rotating),
                (4, Rotating),
                (4, Finished)
            ]
        );
        assert!((w.bodies()[0].heading_deg - 315.0).abs() < 1e-3);
        assert_eq!(w.bodies()[0].position, Vec3::ZERO);
    }

    #[test]
    fn move_to_walks_a_straight_line_to_the_target() {
        let mut w = world();
        let target = Vec3::new(1.2, 5.0, 1.6); // y is ignored
        w.apply(0, 3, Command::MoveTo { target }).unwrap();
        for _ in 0..10 {
            w.step();
            let p = w.bodies()[0].position;
            assert!((p.x * 1.6 - p.z * 1.2).abs() < 1e-4, "off the line: {p}");
        }
        let s = statuses(&sensors(&mut w, 0));
        assert_eq!(s.last(), Some(&(3, Finished)));
        assert!(close(w.bodies()[0].position, Vec3::new(1.2, 0.0, 1.6)));
        assert!((w.bodies()[0].heading_deg - heading_of(1.2, 1.6)).abs() < 1e-3);
    }

    #[test]
    fn a_new_move_aborts_the_running_one_and_cancel_stops() {
        let mut w = world();
        w.apply(
            0,
            1,
            Command::Move {
                heading_deg: 0.0,
                distance: 2.0,
            },
        )
        .unwrap();
        w.step();
        w.apply(0, 2, Command::Turn { angle_deg: 90.0 }).unwrap();
        w.step();
        w.apply(0, 3, Command::CancelMove).unwrap();
        let before = w.bodies()[0].clone();
        w.step();
        assert_eq!(
            statuses(&sensors(&mut w, 0)),
            [
                (1, InExecution),
                (1, Walking),
                (1, Aborted),
                (2, InExecution),
                (2, Rotating),
                (2, Aborted),
                (3, Finished)
            ]
        );
        assert_eq!(w.bodies()[0].position, before.position);
        assert_eq!(w.bodies()[0].heading_deg, before.heading_deg);
    }

    #[test]
    fn walls_objects_and_agents_stop_a_move_with_a_collision() {
        // Wall: north (+z), from z = 3.5 with radius 0.3 the contact is at z = 4.7.
        let mut w = world_with(&[(0, [2.0, 3.5], 0.0)], "");
        w.apply(
            0,
            7,
            Command::Move {
                heading_deg: 0.0,
                distance: 5.0,
            },
        )
        .unwrap();
        for _ in 0..10 {
            w.step();
        }
        let h = sensors(&mut w, 0);
        assert_eq!(h.collisions().len(), 1);
        assert_eq!(
            (h.collisions()[0].action_id, h.collisions()[0].collider_id),
            (7, WALL_COLLIDER_ID)
        );
        assert_eq!(statuses(&h).last(), Some(&(7, Finished)));
        let z = w.bodies()[0].position.z;
        assert!(z <= 4.7 && z > 4.69, "{z}");

        // Object: the box (id 2) spans x -3.5..-2.5; from x = 0 westwards the contact is at
        // x = -2.2.
        let mut w = world();
        w.apply(
            0,
            8,
            Command::Move {
                heading_deg: 270.0,
                distance: 5.0,
            },
        )
        .unwrap();
        for _ in 0..20 {
            w.step();
        }
        let h = sensors(&mut w, 0);
        assert_eq!(h.collisions()[0].collider_id, 2);
        let x = w.bodies()[0].position.x;
        assert!((-2.2..-2.19).contains(&x), "{x}");

        // Another agent: agent 1 stands 1.5 m east of agent 0.
        let mut w = world_with(&[(0, [0.0, 0.0], 0.0), (1, [1.5, 0.0], 0.0)], "");
        w.apply(
            0,
            9,
            Command::Move {
                heading_deg: 90.0,
                distance: 2.0,
            },
        )
        .unwrap();
        for _ in 0..10 {
            w.step();
        }
        let h = sensors(&mut w, 0);
        assert_eq!(h.collisions()[0].collider_id, AGENT_COLLIDER_BASE + 1);
        assert!(w.bodies()[0].position.x <= 0.9 + 1e-4);
        assert!(sensors(&mut w, 1).collisions().is_empty());
    }

    #[test]
    fn eye_movement_runs_at_eye_speed_and_reports_positions() {
        let mut w = world();
        w.apply(
            0,
            5,
            Command::EyeMovement {
                pan_left_deg: 40.0,
                pan_right_deg: -20.0,
                tilt_deg: -10.0,
            },
        )
        .unwrap();
        w.step(); // 30° per cycle at most
        let h = sensors(&mut w, 0);
        assert_eq!(h.eye.rotation_deg, [30.0, -20.0, -10.0]);
        assert_eq!(h.eye.rotation_velocity_deg, [30.0, -20.0, -10.0]);
        assert_eq!(statuses(&h), [(5, InExecution)]);
        w.step();
        let h = sensors(&mut w, 0);
        assert_eq!(h.eye.rotation_deg, [40.0, -20.0, -10.0]);
        assert_eq!(h.eye.rotation_velocity_deg, [10.0, 0.0, 0.0]);
        assert_eq!(statuses(&h), [(5, Finished)]);
        // A new eye command aborts an unfinished one.
        w.apply(
            0,
            6,
            Command::EyeMovement {
                pan_left_deg: -90.0,
                pan_right_deg: 0.0,
                tilt_deg: 0.0,
            },
        )
        .unwrap();
        w.step();
        w.apply(
            0,
            7,
            Command::EyeMovement {
                pan_left_deg: 0.0,
                pan_right_deg: 0.0,
                tilt_deg: 0.0,
            },
        )
        .unwrap();
        assert_eq!(
            statuses(&sensors(&mut w, 0)),
            [(6, InExecution), (6, Aborted), (7, InExecution)]
        );
    }

    #[test]
    fn eye_fixation_converges_on_a_near_point_and_keeps_tracking() {
        let mut w = world();
        // 0.5 m ahead at eye height: the left eye turns right, the right eye left.
        w.apply(
            0,
            1,
            Command::EyeFixation {
                target: Vec3::new(0.0, 1.6, 0.5),
            },
        )
        .unwrap();
        w.step();
        let h = sensors(&mut w, 0);
        assert_eq!(statuses(&h), [(1, InExecution), (1, Finished)]);
        let [l, r, t] = h.eye.rotation_deg;
        let expected = (0.0325f32 / 0.5).atan().to_degrees();
        assert!(
            (l - expected).abs() < 1e-3 && (r + expected).abs() < 1e-3,
            "{l} {r}"
        );
        assert!(t.abs() < 1e-3);
        // The body turns 90° right: the eyes keep the point, now 90° to the left.
        w.apply(0, 2, Command::Turn { angle_deg: 90.0 }).unwrap();
        for _ in 0..5 {
            w.step();
        }
        let h = sensors(&mut w, 0);
        assert!(
            h.eye.rotation_deg[0] < -80.0 && h.eye.rotation_deg[1] < -80.0,
            "{:?}",
            h.eye
        );
        assert!(!statuses(&h).iter().any(|s| s.0 == 1), "reported once");
    }

    #[test]
    fn grasp_carry_release_and_rewards() {
        // From the origin the sphere at z = 3 is 3 - 0.4 - 0.3 = 2.3 m away: out of reach;
        // from z = 1.5 it is 0.8 m away: within the 1 m reach.
        let mut w = world_with(&[(0, [0.0, 0.0], 0.0)], "");
        w.apply(0, 1, Command::GraspId { object_id: 1 }).unwrap();
        assert_eq!(statuses(&sensors(&mut w, 0)), [(1, Aborted)]); // 3 - 0.7 = 2.3 m gap
        w.apply(
            0,
            2,
            Command::Move {
                heading_deg: 0.0,
                distance: 1.5,
            },
        )
        .unwrap();
        for _ in 0..5 {
            w.step();
        }
        let h = sensors(&mut w, 0);
        assert_eq!(h.reward, 1.0, "entered the region around (0, 1.5)");
        w.apply(0, 3, Command::GraspId { object_id: 1 }).unwrap();
        assert_eq!(w.bodies()[0].held, Some(1));
        let h = sensors(&mut w, 0);
        assert_eq!(statuses(&h), [(3, Finished)]);
        assert_eq!(h.reward, 5.0);
        // Hands full; box 2 is not graspable anyway.
        w.apply(0, 4, Command::GraspId { object_id: 1 }).unwrap();
        assert_eq!(statuses(&sensors(&mut w, 0)), [(4, Aborted)]);
        // The held object moves with the body and no longer blocks.
        w.apply(
            0,
            5,
            Command::Move {
                heading_deg: 0.0,
                distance: 1.0,
            },
        )
        .unwrap();
        for _ in 0..4 {
            w.step();
        }
        let h = sensors(&mut w, 0);
        assert!(h.collisions().is_empty());
        let body = w.bodies()[0].position;
        let ball = w.objects()[0].position;
        assert!(
            (ball.z - body.z - 0.75).abs() < 1e-4 && ball.y > 0.5,
            "{ball} {body}"
        );
        w.apply(0, 6, Command::GraspRelease).unwrap();
        assert_eq!(w.objects()[0].position.y, 0.4);
        assert_eq!(w.objects()[0].held_by, None);
        w.apply(0, 7, Command::GraspRelease).unwrap();
        assert_eq!(statuses(&sensors(&mut w, 0)), [(6, Finished), (7, Aborted)]);
        // Passing through the region pays once; coming back pays again; staying does not.
        w.apply(0, 8, Command::MoveTo { target: Vec3::ZERO })
            .unwrap();
        for _ in 0..10 {
            w.step();
        }
        assert_eq!(sensors(&mut w, 0).reward, 1.0);
        w.apply(
            0,
            9,
            Command::MoveTo {
                target: Vec3::new(0.0, 0.0, 1.5),
            },
        )
        .unwrap();
        for _ in 0..10 {
            w.step();
        }
        assert_eq!(sensors(&mut w, 0).reward, 1.0);
        w.apply(0, 10, Command::Turn { angle_deg: 90.0 }).unwrap();
        for _ in 0..10 {
            w.step();
        }
        assert_eq!(sensors(&mut w, 0).reward, 0.0);
    }

    #[test]
    fn point_and_interact_by_image_position_use_the_left_eye_ray() {
        // 1.2 m south of the sphere, facing it: the sphere covers the image centre.
        let mut w = world_with(&[(0, [0.0, 1.8], 0.0)], "");
        w.apply(
            0,
            1,
            Command::EyeMovement {
                pan_left_deg: 0.0,
                pan_right_deg: 0.0,
                tilt_deg: -45.0,
            },
        )
        .unwrap();
        w.step();
        w.step();
        sensors(&mut w, 0);
        w.apply(
            0,
            2,
            Command::GraspPos {
                x_px: 32.0,
                y_px: 24.0,
            },
        )
        .unwrap();
        assert_eq!(w.bodies()[0].held, Some(1));
        w.apply(0, 3, Command::GraspRelease).unwrap();
        // The top-left pixel sees a wall: nothing to point at.
        w.apply(
            0,
            4,
            Command::PointPos {
                x_px: 0.0,
                y_px: 0.0,
            },
        )
        .unwrap();
        w.apply(
            0,
            5,
            Command::InteractPos {
                x_px: 32.0,
                y_px: 24.0,
            },
        )
        .unwrap();
        assert_eq!(
            statuses(&sensors(&mut w, 0)),
            [(2, Finished), (3, Finished), (4, Aborted), (5, Finished)]
        );
        // Outside the 64 × 48 image: rejected.
        let before = w.bodies().to_vec();
        assert!(
            w.apply(
                0,
                6,
                Command::PointPos {
                    x_px: 64.0,
                    y_px: 0.0
                }
            )
            .is_err()
        );
        assert!(
            w.apply(
                0,
                6,
                Command::GraspPos {
                    x_px: -0.5,
                    y_px: 0.0
                }
            )
            .is_err()
        );
        assert_eq!(w.bodies(), &before[..]);
    }

    #[test]
    fn resets_restore_the_start() {
        let mut w = world_with(&[(0, [0.0, 0.0], 0.0), (1, [2.0, 0.0], 90.0)], "");
        w.apply(
            0,
            1,
            Command::Move {
                heading_deg: 0.0,
                distance: 1.5,
            },
        )
        .unwrap();
        w.apply(
            1,
            1,
            Command::Move {
                heading_deg: 180.0,
                distance: 3.0,
            },
        )
        .unwrap();
        for _ in 0..5 {
            w.step();
        }
        w.apply(0, 2, Command::GraspId { object_id: 1 }).unwrap();
        w.apply(
            1,
            2,
            Command::EyeMovement {
                pan_left_deg: 10.0,
                pan_right_deg: 10.0,
                tilt_deg: 0.0,
            },
        )
        .unwrap();
        w.step();
        sensors(&mut w, 0);
        sensors(&mut w, 1);
        // Trial reset: agent 0 only, its object back in place.
        w.apply(0, 3, Command::TrialReset { reset_type: 0 })
            .unwrap();
        assert_eq!(w.bodies()[0].position, Vec3::ZERO);
        assert_eq!(w.objects()[0].position, Vec3::new(0.0, 0.4, 3.0));
        assert_ne!(w.bodies()[1].position, Vec3::new(2.0, 0.0, 0.0));
        assert_eq!(statuses(&sensors(&mut w, 0)), [(3, Finished)]);
        // Environment reset: everyone, running actions aborted.
        w.apply(
            1,
            4,
            Command::Move {
                heading_deg: 0.0,
                distance: 3.0,
            },
        )
        .unwrap();
        w.apply(0, 4, Command::EnvironmentReset { reset_type: 0 })
            .unwrap();
        assert_eq!(w.bodies()[1].position, Vec3::new(2.0, 0.0, 0.0));
        assert_eq!(w.bodies()[1].heading_deg, 90.0);
        assert_eq!(w.bodies()[1].eyes, Eyes::default());
        assert_eq!(
            statuses(&sensors(&mut w, 1)),
            [(1, Aborted), (4, InExecution), (4, Aborted)]
        );
        assert!(
            w.apply(0, 5, Command::EnvironmentReset { reset_type: 3 })
                .is_err()
        );
    }

    #[test]
    fn bad_commands_are_rejected_and_leave_the_world_untouched() {
        let mut w = world();
        w.apply(
            0,
            1,
            Command::Move {
                heading_deg: 0.0,
                distance: 1.0,
            },
        )
        .unwrap();
        let before = (w.bodies().to_vec(), w.objects().to_vec());
        let bad = [
            Command::Move {
                heading_deg: 0.0,
                distance: -1.0,
            },
            Command::Move {
                heading_deg: 0.0,
                distance: 1e9,
            },
            Command::Turn { angle_deg: 1e9 },
            Command::MoveTo {
                target: Vec3::new(9.0, 0.0, 0.0),
            },
            Command::EyeMovement {
                pan_left_deg: 136.0,
                pan_right_deg: 0.0,
                tilt_deg: 0.0,
            },
            Command::EyeMovement {
                pan_left_deg: 0.0,
                pan_right_deg: 0.0,
                tilt_deg: -91.0,
            },
            Command::EyeFixation {
                target: Vec3::new(0.0, 9.0, 0.0),
            },
            Command::GraspId { object_id: 77 },
            Command::PointId { object_id: 0 },
            Command::InteractId { object_id: 1000 },
            Command::TrialReset { reset_type: 1 },
        ];
        for c in bad {
            assert!(w.apply(0, 2, c).is_err(), "{c:?} accepted");
        }
        assert!(w.apply(9, 2, Command::CancelMove).is_err());
        assert_eq!((w.bodies().to_vec(), w.objects().to_vec()), before);
    }

    #[test]
    fn same_commands_same_hash() {
        let run = || {
            let mut w = world_with(&[(0, [0.0, 0.0], 0.0), (1, [2.0, -2.0], 300.0)], "");
            let mut h = blake3::Hasher::new();
            for cycle in 0..50u32 {
                let heading = (cycle * 37 % 360) as f32;
                w.apply(
                    cycle % 2,
                    cycle,
                    Command::Move {
                        heading_deg: heading,
                        distance: 1.0,
                    },
                )
                .unwrap();
                w.step();
                w.hash_into(&mut h);
                sensors(&mut w, 0);
                sensors(&mut w, 1);
            }
            h.finalize()
        };
        assert_eq!(run(), run());
    }

    #[test]
    fn agents_without_a_start_get_free_places_facing_the_centre() {
        let text = format!(
            "[[agent]]\nid = 0\n{CAMS}[[agent]]\nid = 1\n[[agent]]\nid = 2\n[world]\n[[world.object]]\nid = 1\nshape = \"box\"\nposition = [0.0, 0.5, 2.5]\nsize = [1.0, 1.0, 1.0]\ncolor = [1, 2, 3]\n"
        );
        let config = Config::from_toml_str(&text, Path::new("t.toml")).unwrap();
        let w = World::from_config(&config).unwrap();
        for (i, b) in w.bodies().iter().enumerate() {
            assert!(w.collider_at(Some(i), b.position).is_none(), "{b:?}");
            let to_centre = heading_of(-b.position.x, -b.position.z);
            assert!(angle_diff_deg(b.heading_deg, to_centre).abs() < 1e-3);
        }
        // An explicit start inside the box is a config error naming the key.
        let text = "[[agent]]\nid = 0\n[world]\n[[world.object]]\nid = 1\nshape = \"box\"\nposition = [0.0, 0.5, 0.0]\nsize = [1.0, 1.0, 1.0]\ncolor = [1, 2, 3]\n[[world.agent]]\nid = 0\nposition = [0.2, 0.0]\n";
        let config = Config::from_toml_str(text, Path::new("t.toml")).unwrap();
        let e = World::from_config(&config).unwrap_err().to_string();
        assert!(
            e.contains("world.agent[0].position") && e.contains("object 1"),
            "{e}"
        );
    }
}
