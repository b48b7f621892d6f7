//! What is where: rays against the room, objects and bodies; what a body would overlap.

use glam::{Vec2, Vec3};

use super::{AGENT_COLLIDER_BASE, RayHit, WALL_COLLIDER_ID, World};
use crate::geometry::{self, enter_box, hit_cylinder, hit_sphere, recip};
use crate::world_config::Shape;

impl World {
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
    pub(super) fn collider_at(&self, skip: Option<usize>, p: Vec3) -> Option<u32> {
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
}
