//! What the agents sense: viewpoints and cameras, head motion and eye sensors, region
//! rewards, and the frame header they are written into.

use glam::{Vec2, Vec3};
use vrsync_bridge::{EyePosition, GridPosition, HeadMotion, SensorHeader};

use super::{Body, CameraSpec, Viewpoint, World};
use crate::geometry::{self, Camera, angle_diff_deg};
use crate::world_config::GoalKind;

impl World {
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

    /// Region goals whose circle contains `p`.
    pub(super) fn regions_containing(&self, p: Vec3) -> Vec<bool> {
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

    /// Head motion and eye sensors (differences per cycle), and region rewards.
    pub(super) fn step_sensors(&mut self, bi: usize) {
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
}
