//! Rays, cameras and the ray–primitive intersections shared by the renderer and by the
//! *by image position* commands (which cast the ray through a pixel of the left eye).
//!
//! Conventions (as the wire types): x right, y up, z forward; heading 0° looks along +z,
//! 90° along +x (clockwise seen from above); positive tilt looks up.
//!
//! Ray directions are *not* normalised: a camera ray is `forward + u·right + v·up`, so its
//! parameter `t` at a hit is the hit's depth along the optical axis (what depth images
//! store), and no square root is spent per pixel.

use glam::Vec3;

/// Nearest distance along the optical axis that is drawn, metres.
pub const NEAR_M: f32 = 0.05;

/// A pinhole camera: pose and intrinsics.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    /// Centre of projection, world frame.
    pub origin: Vec3,
    /// Unit optical axis.
    pub forward: Vec3,
    /// Unit vector to the image's right.
    pub right: Vec3,
    /// Unit vector to the image's top.
    pub up: Vec3,
    /// `tan(fov_horizontal / 2)`.
    pub tan_half_h: f32,
    /// `tan(fov_vertical / 2)`.
    pub tan_half_v: f32,
    /// Width in pixels.
    pub width_px: u32,
    /// Height in pixels.
    pub height_px: u32,
}

/// The unit forward vector of a yaw (heading) and pitch (tilt), degrees.
pub fn forward_of(yaw_deg: f32, pitch_deg: f32) -> Vec3 {
    let (sy, cy) = yaw_deg.to_radians().sin_cos();
    let (sp, cp) = pitch_deg.to_radians().sin_cos();
    Vec3::new(sy * cp, sp, cy * cp)
}

/// The unit right vector of a yaw, degrees (horizontal).
pub fn right_of(yaw_deg: f32) -> Vec3 {
    let (sy, cy) = yaw_deg.to_radians().sin_cos();
    Vec3::new(cy, 0.0, -sy)
}

/// The heading (degrees, `[0, 360)`) of a horizontal direction.
pub fn heading_of(dx: f32, dz: f32) -> f32 {
    dx.atan2(dz).to_degrees().rem_euclid(360.0)
}

/// `a - b` wrapped into `(-180, 180]` degrees.
pub fn angle_diff_deg(a: f32, b: f32) -> f32 {
    let d = (a - b).rem_euclid(360.0);
    if d > 180.0 { d - 360.0 } else { d }
}

impl Camera {
    /// A camera at `origin` looking along yaw/pitch, with the given fields of view (degrees)
    /// and image size.
    pub fn new(
        origin: Vec3,
        yaw_deg: f32,
        pitch_deg: f32,
        fov_h_deg: f32,
        fov_v_deg: f32,
        width_px: u32,
        height_px: u32,
    ) -> Self {
        let forward = forward_of(yaw_deg, pitch_deg);
        let right = right_of(yaw_deg);
        let up = forward.cross(right);
        Self {
            origin,
            forward,
            right,
            up,
            tan_half_h: (fov_h_deg.to_radians() / 2.0).tan(),
            tan_half_v: (fov_v_deg.to_radians() / 2.0).tan(),
            width_px,
            height_px,
        }
    }

    /// The image-plane coordinate `u` of pixel column `x` (continuous: pixel centres are at
    /// `x + 0.5`).
    pub fn u_of(&self, x: f32) -> f32 {
        (2.0 * x / self.width_px as f32 - 1.0) * self.tan_half_h
    }

    /// The image-plane coordinate `v` of pixel row `y` (continuous, 0 = top edge).
    pub fn v_of(&self, y: f32) -> f32 {
        (1.0 - 2.0 * y / self.height_px as f32) * self.tan_half_v
    }

    /// The (unnormalised, unit depth) ray direction through continuous pixel position
    /// (`x`, `y`); 0/0 is the top-left corner of the image.
    pub fn ray_through(&self, x: f32, y: f32) -> Vec3 {
        self.forward + self.u_of(x) * self.right + self.v_of(y) * self.up
    }

    /// The pixel rectangle `(x0, x1, y0, y1)` (inclusive, clamped) that can show an
    /// axis-aligned box: `None` when it is wholly behind the near plane or off screen, the
    /// whole image when only some corners are behind.
    /// Conservative: the projection of a convex body lies inside the hull of its corners'
    /// projections when all of them are in front of the camera. (The renderer's brute-force
    /// reference uses it; the renderer clips boxes that reach behind the camera instead.)
    #[cfg(test)]
    pub fn screen_rect(&self, min: Vec3, max: Vec3) -> Option<(u32, u32, u32, u32)> {
        let (w, h) = (self.width_px as f32, self.height_px as f32);
        let full = Some((0, self.width_px - 1, 0, self.height_px - 1));
        let (mut u0, mut u1, mut v0, mut v1) = (f32::MAX, f32::MIN, f32::MAX, f32::MIN);
        let mut behind = 0;
        for i in 0..8 {
            let c = Vec3::new(
                if i & 1 == 0 { min.x } else { max.x },
                if i & 2 == 0 { min.y } else { max.y },
                if i & 4 == 0 { min.z } else { max.z },
            );
            let p = c - self.origin;
            let z = p.dot(self.forward);
            if z < NEAR_M {
                behind += 1;
                continue;
            }
            let (u, v) = (p.dot(self.right) / z, p.dot(self.up) / z);
            u0 = u0.min(u);
            u1 = u1.max(u);
            v0 = v0.min(v);
            v1 = v1.max(v);
        }
        match behind {
            0 => {}
            8 => return None,
            _ => return full,
        }
        let x0 = ((u0 / self.tan_half_h + 1.0) * 0.5 * w).floor() - 1.0;
        let x1 = ((u1 / self.tan_half_h + 1.0) * 0.5 * w).ceil() + 1.0;
        let y0 = ((1.0 - v1 / self.tan_half_v) * 0.5 * h).floor() - 1.0;
        let y1 = ((1.0 - v0 / self.tan_half_v) * 0.5 * h).ceil() + 1.0;
        if x1 < 0.0 || y1 < 0.0 || x0 >= w || y0 >= h {
            return None;
        }
        Some((
            x0.max(0.0) as u32,
            (x1 as u32).min(self.width_px - 1),
            y0.max(0.0) as u32,
            (y1 as u32).min(self.height_px - 1),
        ))
    }
}

/// Component-wise reciprocal of a direction (±∞ for zero components).
#[inline]
pub fn recip(d: Vec3) -> Vec3 {
    Vec3::new(1.0 / d.x, 1.0 / d.y, 1.0 / d.z)
}

/// Where a ray from inside the box `min..max` leaves it: `(t, axis, positive side)`.
#[inline]
pub fn exit_box(o: Vec3, inv_d: Vec3, min: Vec3, max: Vec3) -> (f32, usize, bool) {
    let tx = if inv_d.x >= 0.0 {
        (max.x - o.x) * inv_d.x
    } else {
        (min.x - o.x) * inv_d.x
    };
    let ty = if inv_d.y >= 0.0 {
        (max.y - o.y) * inv_d.y
    } else {
        (min.y - o.y) * inv_d.y
    };
    let tz = if inv_d.z >= 0.0 {
        (max.z - o.z) * inv_d.z
    } else {
        (min.z - o.z) * inv_d.z
    };
    if tx <= ty && tx <= tz {
        (tx, 0, inv_d.x >= 0.0)
    } else if ty <= tz {
        (ty, 1, inv_d.y >= 0.0)
    } else {
        (tz, 2, inv_d.z >= 0.0)
    }
}

/// Where a ray from outside enters the box `min..max`, if at `t > t_min`:
/// `(t, axis, positive face)`.
#[inline]
pub fn enter_box(
    o: Vec3,
    inv_d: Vec3,
    min: Vec3,
    max: Vec3,
    t_min: f32,
) -> Option<(f32, usize, bool)> {
    let t1 = (min - o) * inv_d;
    let t2 = (max - o) * inv_d;
    let tn = t1.min(t2);
    let tf = t1.max(t2);
    let t_near = tn.max_element();
    let t_far = tf.min_element();
    if t_near > t_far || t_near <= t_min || t_near.is_nan() {
        return None;
    }
    let axis = if tn.x >= tn.y && tn.x >= tn.z {
        0
    } else if tn.y >= tn.z {
        1
    } else {
        2
    };
    // The ray enters through the face it moves away from: moving +x enters at min.x.
    Some((t_near, axis, inv_d[axis] < 0.0))
}

/// Nearest hit of a ray with a sphere at `t > t_min`.
#[inline]
pub fn hit_sphere(o: Vec3, d: Vec3, center: Vec3, radius: f32, t_min: f32) -> Option<f32> {
    let oc = o - center;
    let a = d.length_squared();
    let b = oc.dot(d);
    let c = oc.length_squared() - radius * radius;
    let disc = b * b - a * c;
    if disc < 0.0 {
        return None;
    }
    let t = (-b - disc.sqrt()) / a;
    (t > t_min).then_some(t)
}

/// Nearest hit of a ray with an upright closed cylinder standing on `base` (its bottom
/// centre) at `t > t_min`: `(t, on the top cap)`.
#[inline]
pub fn hit_cylinder(
    o: Vec3,
    d: Vec3,
    base: Vec3,
    radius: f32,
    height: f32,
    t_min: f32,
) -> Option<(f32, bool)> {
    let (ox, oz) = (o.x - base.x, o.z - base.z);
    let a = d.x * d.x + d.z * d.z;
    let mut best: Option<(f32, bool)> = None;
    if a > 0.0 {
        let b = ox * d.x + oz * d.z;
        let c = ox * ox + oz * oz - radius * radius;
        let disc = b * b - a * c;
        if disc >= 0.0 {
            let t = (-b - disc.sqrt()) / a;
            let y = o.y + t * d.y - base.y;
            if t > t_min && (0.0..=height).contains(&y) {
                best = Some((t, false));
            }
        }
    }
    if d.y != 0.0 {
        let t = (base.y + height - o.y) / d.y;
        if t > t_min && best.is_none_or(|(bt, _)| t < bt) {
            let (x, z) = (ox + t * d.x, oz + t * d.z);
            if x * x + z * z <= radius * radius {
                best = Some((t, true));
            }
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn angles_and_bases_follow_the_conventions() {
        assert!((forward_of(0.0, 0.0) - Vec3::Z).length() < 1e-6);
        assert!((forward_of(90.0, 0.0) - Vec3::X).length() < 1e-6);
        assert!((right_of(0.0) - Vec3::X).length() < 1e-6);
        assert!((forward_of(0.0, 90.0) - Vec3::Y).length() < 1e-6);
        assert_eq!(heading_of(1.0, 0.0), 90.0);
        assert_eq!(angle_diff_deg(10.0, 350.0), 20.0);
        assert_eq!(angle_diff_deg(350.0, 10.0), -20.0);
        let cam = Camera::new(Vec3::ZERO, 0.0, 0.0, 90.0, 90.0, 100, 100);
        assert!((cam.up - Vec3::Y).length() < 1e-6);
        // Top-left corner ray points left and up.
        let r = cam.ray_through(0.0, 0.0);
        assert!((r - Vec3::new(-1.0, 1.0, 1.0)).length() < 1e-5, "{r}");
    }

    #[test]
    fn intersections() {
        let o = Vec3::ZERO;
        let d = Vec3::Z;
        assert!((hit_sphere(o, d, Vec3::new(0.0, 0.0, 5.0), 1.0, 0.0).unwrap() - 4.0).abs() < 1e-5);
        assert!(hit_sphere(o, d, Vec3::new(3.0, 0.0, 5.0), 1.0, 0.0).is_none());
        let (t, axis, pos) = enter_box(
            o,
            recip(d),
            Vec3::new(-1.0, -1.0, 2.0),
            Vec3::new(1.0, 1.0, 3.0),
            0.0,
        )
        .unwrap();
        assert_eq!((axis, pos), (2, false));
        assert!((t - 2.0).abs() < 1e-6);
        let (t, axis, pos) = exit_box(
            o,
            recip(Vec3::new(0.1, 0.0, 1.0)),
            Vec3::splat(-5.0),
            Vec3::splat(5.0),
        );
        assert_eq!((axis, pos), (2, true));
        assert!((t - 5.0).abs() < 1e-5);
        let (t, top) =
            hit_cylinder(Vec3::new(0.0, 1.0, -5.0), d, Vec3::ZERO, 0.5, 1.5, 0.0).unwrap();
        assert!(!top && (t - 4.5).abs() < 1e-5);
        let (t, top) = hit_cylinder(
            Vec3::new(0.0, 3.0, 0.0),
            -Vec3::Y,
            Vec3::ZERO,
            0.5,
            1.5,
            0.0,
        )
        .unwrap();
        assert!(top && (t - 1.5).abs() < 1e-5);
    }

    #[test]
    fn screen_rect_covers_the_box() {
        let cam = Camera::new(Vec3::ZERO, 0.0, 0.0, 90.0, 90.0, 100, 100);
        let (x0, x1, y0, y1) = cam
            .screen_rect(Vec3::new(-0.5, -0.5, 4.5), Vec3::new(0.5, 0.5, 5.5))
            .unwrap();
        assert!(
            x0 <= 44 && x1 >= 55 && y0 <= 44 && y1 >= 55,
            "{x0} {x1} {y0} {y1}"
        );
        assert!(x0 > 30 && x1 < 70);
        assert!(
            cam.screen_rect(Vec3::new(-0.5, -0.5, -5.5), Vec3::new(0.5, 0.5, -4.5))
                .is_none()
        ); // behind
        assert_eq!(
            cam.screen_rect(Vec3::new(-0.5, -0.5, -1.0), Vec3::new(0.5, 0.5, 1.0)),
            Some((0, 99, 0, 99))
        ); // straddles the camera: the whole image
        assert!(
            cam.screen_rect(Vec3::new(10.0, -0.5, 1.0), Vec3::new(11.0, 0.5, 2.0))
                .is_none()
        );
    }
}
