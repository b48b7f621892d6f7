//! The agents' commands: checked, then started (movements, eye movements) or resolved at
//! once (object actions, release, resets). One function per command; [`World::apply`]
//! dispatches.

use glam::{Vec2, Vec3};
use vrsync_bridge::{ActionState, Command, HeadMotion};

use super::{EyeAction, EyeGoal, Eyes, Motion, Object, RayHit, World};
use crate::geometry::{self, heading_of};
use crate::world_config::{GoalAction, GoalKind, Shape};

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

/// An action on an object, resolved at once.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum ObjectAction {
    Grasp,
    Point,
    Interact,
}

/// A command argument outside what this world accepts.
fn out_of_range(command: &'static str, reason: String) -> CommandRejected {
    CommandRejected::OutOfRange { command, reason }
}

impl World {
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
        match command {
            Command::Move {
                heading_deg,
                distance,
            } => self.apply_move(bi, action_id, heading_deg, distance),
            Command::Turn { angle_deg } => self.apply_turn(bi, action_id, angle_deg),
            Command::MoveTo { target } => self.apply_move_to(bi, action_id, target),
            Command::CancelMove => {
                self.cancel_move(bi, action_id);
                Ok(())
            }
            Command::EyeMovement {
                pan_left_deg,
                pan_right_deg,
                tilt_deg,
            } => self.apply_eye_movement(
                bi,
                action_id,
                Eyes {
                    pan_left_deg,
                    pan_right_deg,
                    tilt_deg,
                },
            ),
            Command::EyeFixation { target } => self.apply_eye_fixation(bi, action_id, target),
            Command::GraspId { object_id } => {
                self.object_action(bi, action_id, "grasp", object_id, ObjectAction::Grasp)
            }
            Command::PointId { object_id } => {
                self.object_action(bi, action_id, "point", object_id, ObjectAction::Point)
            }
            Command::InteractId { object_id } => {
                self.object_action(bi, action_id, "interact", object_id, ObjectAction::Interact)
            }
            Command::GraspPos { x_px, y_px } => {
                self.pixel_action(bi, action_id, "grasp_pos", x_px, y_px, ObjectAction::Grasp)
            }
            Command::PointPos { x_px, y_px } => {
                self.pixel_action(bi, action_id, "point_pos", x_px, y_px, ObjectAction::Point)
            }
            Command::InteractPos { x_px, y_px } => self.pixel_action(
                bi,
                action_id,
                "interact_pos",
                x_px,
                y_px,
                ObjectAction::Interact,
            ),
            Command::GraspRelease => {
                self.release(bi, action_id);
                Ok(())
            }
            Command::EnvironmentReset { reset_type } => {
                self.environment_reset(bi, action_id, reset_type)
            }
            Command::TrialReset { reset_type } => self.trial_reset(bi, action_id, reset_type),
        }
    }

    /// `move`: walk `distance` metres towards `heading_deg` (world heading).
    fn apply_move(
        &mut self,
        bi: usize,
        action_id: u32,
        heading_deg: f32,
        distance: f32,
    ) -> Result<(), CommandRejected> {
        let max_d = self.cfg.max_move_distance;
        if !(0.0..=max_d).contains(&distance) {
            return Err(out_of_range(
                "move",
                format!("distance {distance} m outside 0..={max_d}"),
            ));
        }
        if heading_deg.abs() > 3600.0 {
            return Err(out_of_range(
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
        Ok(())
    }

    /// `turn`: rotate the body by `angle_deg` (positive = clockwise seen from above).
    fn apply_turn(
        &mut self,
        bi: usize,
        action_id: u32,
        angle_deg: f32,
    ) -> Result<(), CommandRejected> {
        if angle_deg.abs() > 3600.0 {
            return Err(out_of_range(
                "turn",
                format!("angle {angle_deg}° is out of range"),
            ));
        }
        self.start_motion(
            bi,
            Motion::Turn {
                id: action_id,
                remaining_deg: angle_deg,
            },
        );
        Ok(())
    }

    /// `move_to`: walk in a straight line to `target` (on the floor), facing it.
    fn apply_move_to(
        &mut self,
        bi: usize,
        action_id: u32,
        target: Vec3,
    ) -> Result<(), CommandRejected> {
        let max_d = self.cfg.max_move_distance;
        let (min, max) = self.room_bounds();
        if target.x < min.x || target.x > max.x || target.z < min.z || target.z > max.z {
            return Err(out_of_range(
                "move_to",
                format!("target {target} is outside the room"),
            ));
        }
        let body = &self.bodies[bi];
        let to = Vec3::new(target.x - body.position.x, 0.0, target.z - body.position.z);
        let len = to.length();
        if len > max_d {
            return Err(out_of_range(
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
        Ok(())
    }

    /// `cancel_move`: the running movement is aborted; the cancel itself finishes.
    fn cancel_move(&mut self, bi: usize, action_id: u32) {
        let body = &mut self.bodies[bi];
        if let Some(m) = body.motion.take() {
            body.statuses.push((m.id(), ActionState::Aborted));
        }
        body.statuses.push((action_id, ActionState::Finished));
    }

    /// `eye_movement`: turn the eyes to these angles at `eye_speed_deg`.
    fn apply_eye_movement(
        &mut self,
        bi: usize,
        action_id: u32,
        eyes: Eyes,
    ) -> Result<(), CommandRejected> {
        let Eyes {
            pan_left_deg,
            pan_right_deg,
            tilt_deg,
        } = eyes;
        let (mp, mt) = (self.cfg.max_pan_deg, self.cfg.max_tilt_deg);
        if pan_left_deg.abs() > mp || pan_right_deg.abs() > mp || tilt_deg.abs() > mt {
            return Err(out_of_range(
                "eye_movement",
                format!(
                    "pan {pan_left_deg}°/{pan_right_deg}°, tilt {tilt_deg}° beyond ±{mp}°/±{mt}°"
                ),
            ));
        }
        self.start_eye_action(bi, action_id, EyeGoal::Angles(eyes));
        Ok(())
    }

    /// `eye_fixation`: turn both eyes towards `target` and keep tracking it.
    fn apply_eye_fixation(
        &mut self,
        bi: usize,
        action_id: u32,
        target: Vec3,
    ) -> Result<(), CommandRejected> {
        let (min, max) = self.room_bounds();
        if target.cmplt(min).any() || target.cmpgt(max).any() {
            return Err(out_of_range(
                "eye_fixation",
                format!("target {target} is outside the room"),
            ));
        }
        self.start_eye_action(bi, action_id, EyeGoal::Fixate(target));
        Ok(())
    }

    /// `grasp_release`: put the held object down (Aborted when nothing is held).
    fn release(&mut self, bi: usize, action_id: u32) {
        let state = match self.bodies[bi].held.take() {
            Some(object) => {
                self.put_down(bi, object);
                ActionState::Finished
            }
            None => ActionState::Aborted,
        };
        self.bodies[bi].statuses.push((action_id, state));
    }

    /// `environment_reset`: every object and every body back to its start.
    fn environment_reset(
        &mut self,
        bi: usize,
        action_id: u32,
        reset_type: u32,
    ) -> Result<(), CommandRejected> {
        if reset_type != 0 {
            return Err(out_of_range(
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
        Ok(())
    }

    /// `trial_reset`: this agent's body, and the object it holds, back to their start.
    fn trial_reset(
        &mut self,
        bi: usize,
        action_id: u32,
        reset_type: u32,
    ) -> Result<(), CommandRejected> {
        if reset_type != 0 {
            return Err(out_of_range(
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
    pub(super) fn carry(&mut self, bi: usize) {
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
}
