//! Culling by screen rectangle: a camera's frustum, and the pixel rectangle (with its
//! nearest depth) a box covers in an image, one box or a packet of them at once.

use super::*;

/// The side planes of a camera's view and its near plane: a cheap first test of whether
/// a primitive can show up in the image at all.
#[derive(Debug, Clone, Copy)]
pub(super) struct Frustum {
    pub(super) origin: Vec3,
    pub(super) forward: Vec3,
    /// Unit normals, pointing out of the view, of the planes through the image's left,
    /// right, top and bottom edges (every pixel's ray is strictly inside).
    pub(super) sides: [Vec3; 4],
}

impl Frustum {
    pub(super) fn new(cam: &Camera) -> Self {
        let side = |out: Vec3, tan_half: f32| (out - tan_half * cam.forward).normalize_or_zero();
        Self {
            origin: cam.origin,
            forward: cam.forward,
            sides: [
                side(-cam.right, cam.tan_half_h),
                side(cam.right, cam.tan_half_h),
                side(cam.up, cam.tan_half_v),
                side(-cam.up, cam.tan_half_v),
            ],
        }
    }

    /// Whether no pixel's ray can hit anything inside the ball: it lies wholly behind the
    /// near plane or wholly outside a side plane. The radius is widened far beyond the
    /// rounding error, so a ball that only touches the view is kept.
    pub(super) fn misses_ball(&self, center: Vec3, radius: f32) -> bool {
        let p = center - self.origin;
        let r = radius * (1.0 + 1e-3) + 1e-3;
        let [a, b, c, d] = self.sides;
        p.dot(self.forward) + r < NEAR_M
            || p.dot(a) > r
            || p.dot(b) > r
            || p.dot(c) > r
            || p.dot(d) > r
    }
}

/// How far (in pixels) outside a box's projection a pixel's centre may be and still be
/// in its rectangle: far above the rounding error of the projection and of the pixels'
/// rays and hit tests (a hit that rounding puts just outside a silhouette is off by
/// about 1e-7 of the distance over the size; a quarter pixel of a 8,192-pixel-wide
/// 120° image is 8e-5 rad).
pub(super) const RECT_MARGIN_PX: f32 = 0.25;

/// A pixel rectangle `(x0, x1, y0, y1)`, inclusive.
pub(super) type Rect = (u32, u32, u32, u32);

/// The pixel rectangle (inclusive, clamped) that can show a hit on what lies in the
/// axis-aligned box `min..max`, and a lower bound of such a hit's depth (ray parameter);
/// `None` when no pixel can show one. The rectangle holds the pixels whose centre (where
/// their ray goes through) is in the hull of the projections of the box's corners, or
/// within [`RECT_MARGIN_PX`] of it; when the box reaches behind the near plane,
/// of the part of the box in front of half the near distance (the corners there and
/// where the box's edges cross that plane), not the whole image: a hit is beyond the near
/// plane, so in that part, whose projection lies in the hull of those points'. The depth
/// bound is the nearest corner's depth less a margin far above the hit tests' rounding
/// error (about 1e-6 relative).
pub(super) fn clipped_rect(cam: &Camera, min: Vec3, max: Vec3) -> Option<(Rect, f32)> {
    // Each corner's coordinates along right, up and forward are sums of one term per
    // axis, taken from the box's min or max.
    let (a, b) = (min - cam.origin, max - cam.origin);
    let terms = |v: Vec3| [a * v, b * v];
    let (rx, uy, fz) = (terms(cam.right), terms(cam.up), terms(cam.forward));
    let coord = |t: &[Vec3; 2], i: usize| t[i & 1].x + t[(i >> 1) & 1].y + t[(i >> 2) & 1].z;
    let mut p = [Vec3::ZERO; 8];
    let (mut near, mut far) = (f32::MAX, f32::MIN);
    for (i, p) in p.iter_mut().enumerate() {
        *p = Vec3::new(coord(&rx, i), coord(&uy, i), coord(&fz, i));
        near = near.min(p.z);
        far = far.max(p.z);
    }
    if far < NEAR_M || far.is_nan() {
        return None;
    }
    let (mut u0, mut u1, mut v0, mut v1) = (f32::MAX, f32::MIN, f32::MAX, f32::MIN);
    let mut add = |q: Vec3, depth: f32| {
        let s = 1.0 / depth;
        let (u, v) = (q.x * s, q.y * s);
        u0 = u0.min(u);
        u1 = u1.max(u);
        v0 = v0.min(v);
        v1 = v1.max(v);
    };
    let clip = 0.5 * NEAR_M;
    if near >= clip {
        for q in p {
            add(q, q.z);
        }
    } else {
        for i in 0..8 {
            if p[i].z >= clip {
                add(p[i], p[i].z);
            }
            // The edges to the corners that differ in one coordinate (each edge once).
            for axis in 0..3 {
                let j = i ^ (1 << axis);
                if j > i && (p[i].z >= clip) != (p[j].z >= clip) {
                    let s = (clip - p[i].z) / (p[j].z - p[i].z);
                    add(p[i] + (p[j] - p[i]) * s, clip);
                }
            }
        }
    }
    rect_of(cam, near, (u0, u1, v0, v1))
}

/// The rectangle and depth bound of [`clipped_rect`] from the bounds `(u0, u1, v0, v1)` of
/// the projection (at unit depth) and the nearest corner's depth.
#[inline(always)]
pub(super) fn rect_of(
    cam: &Camera,
    near: f32,
    (u0, u1, v0, v1): (f32, f32, f32, f32),
) -> Option<(Rect, f32)> {
    let (w, h) = (cam.width_px as f32, cam.height_px as f32);
    // Pixel x's ray is at x + 0.5 in these coordinates; keep the pixels whose centre is
    // within RECT_MARGIN_PX of the projection.
    let lo = |c: f32| -floor_f32(-(c - 0.5 - RECT_MARGIN_PX));
    let hi = |c: f32| floor_f32(c - 0.5 + RECT_MARGIN_PX);
    let x0 = lo((u0 / cam.tan_half_h + 1.0) * 0.5 * w);
    let x1 = hi((u1 / cam.tan_half_h + 1.0) * 0.5 * w);
    let y0 = lo((1.0 - v1 / cam.tan_half_v) * 0.5 * h);
    let y1 = hi((1.0 - v0 / cam.tan_half_v) * 0.5 * h);
    if !(x1 >= 0.0 && y1 >= 0.0 && x0 < w && y0 < h && x0 <= x1 && y0 <= y1) {
        return None;
    }
    let rect = (
        x0.max(0.0) as u32,
        x1.min(w - 1.0) as u32,
        y0.max(0.0) as u32,
        y1.min(h - 1.0) as u32,
    );
    Some((rect, near - 1e-3 * (1.0 + near.abs())))
}

/// Up to [`LANES`] axis-aligned boxes, by lane (structure of arrays).
#[derive(Debug, Default)]
pub(super) struct BoxLanes {
    pub(super) min: [[f32; LANES]; 3],
    pub(super) max: [[f32; LANES]; 3],
}

impl BoxLanes {
    pub(super) fn set(&mut self, k: usize, min: Vec3, max: Vec3) {
        for axis in 0..3 {
            (self.min[axis][k], self.max[axis][k]) = (min[axis], max[axis]);
        }
    }
}

/// For each of the first `n` boxes of `boxes`, what [`clipped_rect`] gives for it (`None`
/// past `n`): the corners' projections and bounds of every box at once (the same
/// operations in the same order on every lane), [`clipped_rect`] itself for a box that
/// reaches behind half the near distance.
pub(super) fn clipped_rects_lanes(
    cam: &Camera,
    boxes: &BoxLanes,
    n: usize,
) -> [Option<(Rect, f32)>; LANES] {
    let o = cam.origin;
    // Per axis, the box's min and max less the origin, times each camera axis' component.
    let mut lo = [[[0.0f32; LANES]; 3]; 3];
    let mut hi = [[[0.0f32; LANES]; 3]; 3];
    for (c, dir) in [cam.right, cam.up, cam.forward].into_iter().enumerate() {
        for axis in 0..3 {
            for k in 0..LANES {
                lo[c][axis][k] = (boxes.min[axis][k] - o[axis]) * dir[axis];
                hi[c][axis][k] = (boxes.max[axis][k] - o[axis]) * dir[axis];
            }
        }
    }
    let coord = |c: usize, i: usize, k: usize| {
        let pick = |axis: usize| {
            if (i >> axis) & 1 == 0 {
                lo[c][axis][k]
            } else {
                hi[c][axis][k]
            }
        };
        pick(0) + pick(1) + pick(2)
    };
    let (mut near, mut far) = ([f32::MAX; LANES], [f32::MIN; LANES]);
    let (mut u0, mut u1, mut v0, mut v1) = (
        [f32::MAX; LANES],
        [f32::MIN; LANES],
        [f32::MAX; LANES],
        [f32::MIN; LANES],
    );
    for i in 0..8 {
        for k in 0..LANES {
            let (x, y, z) = (coord(0, i, k), coord(1, i, k), coord(2, i, k));
            near[k] = near[k].min(z);
            far[k] = far[k].max(z);
            let s = 1.0 / z;
            let (u, v) = (x * s, y * s);
            u0[k] = u0[k].min(u);
            u1[k] = u1[k].max(u);
            v0[k] = v0[k].min(v);
            v1[k] = v1[k].max(v);
        }
    }
    std::array::from_fn(|k| {
        if k >= n || far[k] < NEAR_M || far[k].is_nan() {
            None
        } else if near[k] >= 0.5 * NEAR_M {
            rect_of(cam, near[k], (u0[k], u1[k], v0[k], v1[k]))
        } else {
            let corner = |c: &[[f32; LANES]; 3]| Vec3::new(c[0][k], c[1][k], c[2][k]);
            clipped_rect(cam, corner(&boxes.min), corner(&boxes.max))
        }
    })
}
