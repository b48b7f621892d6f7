//! Motion over simulated time: walking and turning (stopped by the first obstacle) and
//! the eyes moving towards their goal or tracking a fixation point.

use glam::{Vec2, Vec3};
use vrsync_bridge::ActionState;

use super::{EyeAction, EyeGoal, Eyes, Motion, Viewpoint, World};
use crate::geometry::{angle_diff_deg, heading_of};

impl World {
    pub(super) fn step_motion(&mut self, bi: usize) {
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

    pub(super) fn step_eyes(&mut self, bi: usize) {
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
}
