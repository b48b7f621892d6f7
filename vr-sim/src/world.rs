//! The world: agents' bodies in a square room, moved by motor commands with simulated time
//! only. Nothing here reads the wall clock or an unseeded random generator.
//!
//! Conventions: y is up; heading 0° looks along +z, 90° along +x (clockwise seen from
//! above); a body's rotation is `Quat::from_rotation_y(heading)`.

use glam::{Quat, Vec3};
use vrsync_bridge::wire::{ActionState, Command, Pose, SensorHeader};

/// Id reported as collider when an agent walks into a wall.
pub const WALL_COLLIDER_ID: u32 = 1000;

/// Parameters of the world.
#[derive(Debug, Clone, PartialEq)]
pub struct WorldParams {
    /// Half the side of the square room, metres.
    pub room_half_m: f32,
    /// Walking speed, metres per simulated second.
    pub movement_speed: f32,
    /// Turning speed, degrees per simulated second.
    pub turn_speed_deg: f32,
    /// Longest accepted move, metres.
    pub max_distance_m: f32,
}

impl Default for WorldParams {
    fn default() -> Self {
        Self {
            room_half_m: 5.0,
            movement_speed: 3.0,
            turn_speed_deg: 180.0,
            max_distance_m: 50.0,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Action {
    Move {
        id: u32,
        direction: Vec3,
        remaining_m: f32,
    },
    Turn {
        id: u32,
        remaining_deg: f32,
    },
}

impl Action {
    fn id(&self) -> u32 {
        match *self {
            Self::Move { id, .. } | Self::Turn { id, .. } => id,
        }
    }
}

/// One agent's body.
#[derive(Debug, Clone, PartialEq)]
pub struct Body {
    /// Agent id.
    pub id: u32,
    /// Position, metres.
    pub position: Vec3,
    /// Heading, degrees in `[0, 360)`.
    pub heading_deg: f32,
    action: Option<Action>,
    statuses: Vec<(u32, ActionState)>,
    collisions: Vec<(u32, u32)>,
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

    /// The pose for the sensor header.
    pub fn pose(&self) -> Pose {
        Pose::from_glam(
            self.position,
            Quat::from_rotation_y(self.heading_deg.to_radians()),
        )
    }
}

/// Why a command was not applied.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CommandRejected {
    /// The command cannot be decoded.
    #[error("{0}")]
    Decode(#[from] vrsync_bridge::CommandDecodeError),
    /// An argument is outside what this world accepts.
    #[error("{command}: {reason}")]
    OutOfRange {
        /// Command name.
        command: &'static str,
        /// What is wrong.
        reason: String,
    },
    /// This world does not implement the command yet.
    #[error("{0} is not supported by this world")]
    Unsupported(&'static str),
    /// No such agent.
    #[error("unknown agent {0}")]
    UnknownAgent(u32),
}

/// The world state.
#[derive(Debug, Clone)]
pub struct World {
    params: WorldParams,
    bodies: Vec<Body>,
    dt_s: f32,
}

impl World {
    /// A world with agents `ids` placed on a circle around the centre, facing it.
    pub fn new(params: WorldParams, ids: &[u32], dt_s: f32) -> Self {
        let n = ids.len().max(1) as f32;
        let radius = params.room_half_m * 0.5;
        let bodies = ids
            .iter()
            .enumerate()
            .map(|(i, &id)| {
                let angle = i as f32 / n * std::f32::consts::TAU;
                let position = Vec3::new(radius * angle.sin(), 0.0, radius * angle.cos());
                // Face the centre: heading of the vector -position.
                let heading_deg = (-position.x)
                    .atan2(-position.z)
                    .to_degrees()
                    .rem_euclid(360.0);
                Body {
                    id,
                    position,
                    heading_deg,
                    action: None,
                    statuses: Vec::with_capacity(8),
                    collisions: Vec::with_capacity(4),
                }
            })
            .collect();
        Self {
            params,
            bodies,
            dt_s,
        }
    }

    /// All bodies, in agent id order.
    pub fn bodies(&self) -> &[Body] {
        &self.bodies
    }

    fn body_mut(&mut self, id: u32) -> Result<&mut Body, CommandRejected> {
        self.bodies
            .iter_mut()
            .find(|b| b.id == id)
            .ok_or(CommandRejected::UnknownAgent(id))
    }

    /// Applies one command of agent `agent`. A new movement aborts the running one.
    ///
    /// # Errors
    /// [`CommandRejected`]; the world is untouched then.
    pub fn apply(
        &mut self,
        agent: u32,
        action_id: u32,
        command: Command,
    ) -> Result<(), CommandRejected> {
        let max_d = self.params.max_distance_m;
        let body = self.body_mut(agent)?;
        let new_action = match command {
            Command::Move {
                heading_deg,
                distance,
            } => {
                if !(0.0..=max_d).contains(&distance) {
                    return Err(CommandRejected::OutOfRange {
                        command: "move",
                        reason: format!("distance {distance} m outside 0..={max_d}"),
                    });
                }
                if heading_deg.abs() > 3600.0 {
                    return Err(CommandRejected::OutOfRange {
                        command: "move",
                        reason: format!("heading {heading_deg}° is not an angle"),
                    });
                }
                let h = heading_deg.rem_euclid(360.0);
                body.heading_deg = h;
                let r = h.to_radians();
                Action::Move {
                    id: action_id,
                    direction: Vec3::new(r.sin(), 0.0, r.cos()),
                    remaining_m: distance,
                }
            }
            Command::Turn { angle_deg } => {
                if angle_deg.abs() > 3600.0 {
                    return Err(CommandRejected::OutOfRange {
                        command: "turn",
                        reason: format!("angle {angle_deg}° is out of range"),
                    });
                }
                Action::Turn {
                    id: action_id,
                    remaining_deg: angle_deg,
                }
            }
            Command::MoveTo { target } => {
                let to = target - body.position;
                let d = Vec3::new(to.x, 0.0, to.z);
                let len = d.length();
                if len > max_d {
                    return Err(CommandRejected::OutOfRange {
                        command: "move_to",
                        reason: format!("target {len} m away, more than {max_d}"),
                    });
                }
                if len > 0.0 {
                    body.heading_deg = d.x.atan2(d.z).to_degrees().rem_euclid(360.0);
                }
                Action::Move {
                    id: action_id,
                    direction: d.normalize_or_zero(),
                    remaining_m: len,
                }
            }
            Command::CancelMove => {
                if let Some(a) = body.action.take() {
                    body.statuses.push((a.id(), ActionState::Aborted));
                }
                body.statuses.push((action_id, ActionState::Finished));
                return Ok(());
            }
            other => return Err(CommandRejected::Unsupported(other.name())),
        };
        if let Some(old) = body.action.replace(new_action) {
            body.statuses.push((old.id(), ActionState::Aborted));
        }
        body.statuses.push((action_id, ActionState::InExecution));
        Ok(())
    }

    /// Advances every body by one cycle of simulated time.
    pub fn step(&mut self) {
        let dt = self.dt_s;
        let speed = self.params.movement_speed;
        let turn_speed = self.params.turn_speed_deg;
        let half = self.params.room_half_m;
        for body in &mut self.bodies {
            let Some(action) = body.action else { continue };
            match action {
                Action::Move {
                    id,
                    direction,
                    remaining_m,
                } => {
                    let step = (speed * dt).min(remaining_m);
                    let next = body.position + direction * step;
                    if next.x.abs() > half || next.z.abs() > half {
                        body.position = next.clamp(Vec3::splat(-half), Vec3::splat(half));
                        body.collisions.push((id, WALL_COLLIDER_ID));
                        body.statuses.push((id, ActionState::Finished));
                        body.action = None;
                    } else if remaining_m - step <= 1e-4 {
                        body.position = next;
                        body.statuses.push((id, ActionState::Finished));
                        body.action = None;
                    } else {
                        body.position = next;
                        body.statuses.push((id, ActionState::Walking));
                        body.action = Some(Action::Move {
                            id,
                            direction,
                            remaining_m: remaining_m - step,
                        });
                    }
                }
                Action::Turn { id, remaining_deg } => {
                    let step = (turn_speed * dt).min(remaining_deg.abs()) * remaining_deg.signum();
                    body.heading_deg = (body.heading_deg + step).rem_euclid(360.0);
                    let left = remaining_deg - step;
                    if left.abs() <= 1e-3 {
                        body.statuses.push((id, ActionState::Finished));
                        body.action = None;
                    } else {
                        body.statuses.push((id, ActionState::Rotating));
                        body.action = Some(Action::Turn {
                            id,
                            remaining_deg: left,
                        });
                    }
                }
            }
        }
    }

    /// Writes agent `id`'s sensors into a frame header and forgets the reported events.
    pub fn write_sensors(&mut self, id: u32, header: &mut SensorHeader) {
        let Some(body) = self.bodies.iter_mut().find(|b| b.id == id) else {
            return;
        };
        header.pose = body.pose();
        header.grid.position = body.position.to_array();
        header.grid.rotation_deg = [0.0, body.heading_deg, 0.0];
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
    }

    /// Feeds every body's pose and pending statuses into `hasher` (the trajectory hash).
    pub fn hash_into(&self, hasher: &mut blake3::Hasher) {
        for b in &self.bodies {
            hasher.update(&b.id.to_le_bytes());
            for v in b.position.to_array() {
                hasher.update(&v.to_bits().to_le_bytes());
            }
            hasher.update(&b.heading_deg.to_bits().to_le_bytes());
            for &(action, state) in &b.statuses {
                hasher.update(&action.to_le_bytes());
                hasher.update(&(state as u32).to_le_bytes());
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn world() -> World {
        World::new(WorldParams::default(), &[0], 0.1)
    }

    #[test]
    fn move_walks_at_speed_times_dt_and_finishes() {
        let mut w = world();
        let start = w.bodies()[0].position;
        w.apply(
            0,
            1,
            Command::Move {
                heading_deg: 90.0,
                distance: 0.75,
            },
        )
        .unwrap();
        w.step(); // 0.3 m
        w.step(); // 0.6 m
        let mut h = SensorHeader::default();
        w.write_sensors(0, &mut h);
        assert_eq!(h.statuses().len(), 3);
        assert_eq!(h.statuses()[2].state, ActionState::Walking as u32);
        w.step(); // 0.75 m, finished
        w.write_sensors(0, &mut h);
        assert_eq!(h.statuses()[0].state, ActionState::Finished as u32);
        let moved = w.bodies()[0].position - start;
        assert!(
            (moved.x - 0.75).abs() < 1e-5 && moved.z.abs() < 1e-5,
            "{moved}"
        );
    }

    #[test]
    fn a_new_move_aborts_the_running_one() {
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
        w.apply(0, 2, Command::Turn { angle_deg: 90.0 }).unwrap();
        let mut h = SensorHeader::default();
        w.write_sensors(0, &mut h);
        let s: Vec<_> = h
            .statuses()
            .iter()
            .map(|s| (s.action_id, s.state))
            .collect();
        assert_eq!(
            s,
            [
                (1, ActionState::InExecution as u32),
                (1, ActionState::Aborted as u32),
                (2, ActionState::InExecution as u32)
            ]
        );
    }

    #[test]
    fn walls_stop_and_report_a_collision() {
        let mut w = world();
        w.apply(
            0,
            7,
            Command::Move {
                heading_deg: 0.0,
                distance: 40.0,
            },
        )
        .unwrap();
        for _ in 0..100 {
            w.step();
        }
        let mut h = SensorHeader::default();
        w.write_sensors(0, &mut h);
        assert_eq!(h.collisions()[0].action_id, 7);
        assert_eq!(h.collisions()[0].collider_id, WALL_COLLIDER_ID);
        assert!(w.bodies()[0].position.z <= 5.0);
    }

    #[test]
    fn out_of_range_commands_leave_the_world_untouched() {
        let mut w = world();
        let before = w.bodies().to_vec();
        assert!(
            w.apply(
                0,
                1,
                Command::Move {
                    heading_deg: 0.0,
                    distance: -1.0
                }
            )
            .is_err()
        );
        assert!(
            w.apply(
                0,
                1,
                Command::Move {
                    heading_deg: 0.0,
                    distance: 1e9
                }
            )
            .is_err()
        );
        assert!(w.apply(0, 1, Command::Turn { angle_deg: 1e9 }).is_err());
        assert!(w.apply(9, 1, Command::CancelMove).is_err());
        assert_eq!(w.bodies(), &before[..]);
    }
}
