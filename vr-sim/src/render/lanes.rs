//! Packets of rays: [`LANES`] neighbouring pixels of a row traced together, in
//! straight-line lane loops the compiler turns into SIMD instructions (the room's walls,
//! the bodies' cylinders and colours).

use super::*;

/// Pixels traced together (a packet): neighbours in a row, all in one tile, each
/// primitive tested for all of them at once in straight-line lane loops that the compiler
/// turns into SIMD instructions. Tiles are a multiple of this wide.
pub(super) const LANES: usize = 8;

/// A packet's rays, one per lane (structure of arrays).
#[derive(Debug, Default)]
pub(super) struct Rays {
    pub(super) dx: [f32; LANES],
    pub(super) dy: [f32; LANES],
    pub(super) dz: [f32; LANES],
}

/// The rays of one image row: pixel `x`'s is `row_dir + (u0 + x · du) · right`
/// (computed this way, in this order, by every pixel).
#[derive(Debug, Clone, Copy)]
pub(super) struct RowRays {
    pub(super) row_dir: Vec3,
    pub(super) u0: f32,
    pub(super) du: f32,
}

impl RowRays {
    #[inline(always)]
    pub(super) fn of(cam: &Camera, y: u32) -> Self {
        let du = 2.0 * cam.tan_half_h / cam.width_px as f32;
        Self {
            row_dir: cam.forward + cam.v_of(y as f32 + 0.5) * cam.up,
            u0: -cam.tan_half_h + 0.5 * du,
            du,
        }
    }

    /// Pixel `x`'s ray (the row shader computes the same, component by component, per lane).
    #[cfg(test)]
    pub(super) fn dir(&self, right: Vec3, x: u32) -> Vec3 {
        self.row_dir + (self.u0 + x as i32 as f32 * self.du) * right
    }
}

/// Where every lane's ray leaves the room `min..max` (from `o` inside it), the same bits
/// as [`exit_box`](crate::geometry::exit_box) gives, and the [`RoomFace`] it sees there
/// (the floor's even squares for the whole floor: [`floor_face`] tells the square): the
/// same operations in the same order on every lane, the branches turned into selects.
#[inline(always)]
pub(super) fn room_exit_lanes(
    o: Vec3,
    rays: &Rays,
    min: Vec3,
    max: Vec3,
) -> ([f32; LANES], [u32; LANES]) {
    let mut t = [0.0f32; LANES];
    let mut face = [0u32; LANES];
    for k in 0..LANES {
        let (dx, dy, dz) = (rays.dx[k], rays.dy[k], rays.dz[k]);
        let (ix, iy, iz) = (1.0 / dx, 1.0 / dy, 1.0 / dz);
        let (px, py, pz) = (ix >= 0.0, iy >= 0.0, iz >= 0.0);
        let tx = (if px { max.x } else { min.x } - o.x) * ix;
        let ty = (if py { max.y } else { min.y } - o.y) * iy;
        let tz = (if pz { max.z } else { min.z } - o.z) * iz;
        let on_x = tx <= ty && tx <= tz;
        let on_y = !on_x && ty <= tz;
        let tk = if on_x {
            tx
        } else if on_y {
            ty
        } else {
            tz
        };
        let wall = |positive: bool, plus: RoomFace, minus: RoomFace| {
            if positive { plus } else { minus }
        };
        face[k] = if on_x {
            wall(px, RoomFace::MaxX, RoomFace::MinX) as u32
        } else if on_y {
            if py {
                RoomFace::Ceiling as u32
            } else {
                RoomFace::Floor as u32
            }
        } else {
            wall(pz, RoomFace::MaxZ, RoomFace::MinZ) as u32
        };
        t[k] = tk;
    }
    (t, face)
}

/// The floor's [`RoomFace`] where a ray from `o` along `d` meets it at depth `t`: its
/// square's parity.
#[inline(always)]
pub(super) fn floor_face(o: Vec3, d: Vec3, t: f32) -> usize {
    let q = o + t * d;
    RoomFace::Floor as usize + ((floor_i32(q.x).wrapping_add(floor_i32(q.z)) & 1) as usize)
}

/// The shaded colours (at most 255) of the lanes whose nearest hit is a body.
#[derive(Debug, Default)]
pub(super) struct BodyColors {
    /// Whether the lane's nearest hit is a body (else its colour is meaningless).
    pub(super) hit: [bool; LANES],
    /// Red, green and blue, by lane.
    pub(super) rgb: [[f32; LANES]; 3],
}

/// [`shade()`] of [`normal_at`] for every lane whose nearest hit (`nearest`, an index into
/// `prims`, at depth `t`) is a body, at once: the same operations in the same order on
/// every lane (so the same bits), the branches turned into selects.
#[inline(always)]
pub(super) fn body_colors_lanes(
    o: Vec3,
    rays: &Rays,
    t: &[f32; LANES],
    nearest: &[u32; LANES],
    prims: &[Prim],
) -> BodyColors {
    let mut out = BodyColors::default();
    // Each lane's body (a harmless one where there is none).
    let (mut bx, mut bz, mut top, mut radius) =
        ([0.0f32; LANES], [0.0; LANES], [0.0; LANES], [1.0; LANES]);
    let mut color = [[0.0f32; LANES]; 3];
    for k in 0..LANES {
        if let Some(&Prim {
            kind:
                PrimKind::Body {
                    base,
                    radius: r,
                    height,
                },
            color: c,
            ..
        }) = prims.get(nearest[k] as usize)
        {
            out.hit[k] = true;
            (bx[k], bz[k], radius[k]) = (base.x, base.z, r);
            top[k] = base.y + height - 1e-4;
            (color[0][k], color[1][k], color[2][k]) = (c.x, c.y, c.z);
        }
    }
    for k in 0..LANES {
        let tk = t[k];
        let (qx, qy, qz) = (
            o.x + tk * rays.dx[k],
            o.y + tk * rays.dy[k],
            o.z + tk * rays.dz[k],
        );
        let cap = qy >= top[k];
        let r = radius[k];
        let (nx, ny, nz) = if cap {
            (0.0, 1.0, 0.0)
        } else {
            ((qx - bx[k]) / r, 0.0 / r, (qz - bz[k]) / r)
        };
        let s = 0.7 + 0.3 * ((nx * LIGHT.x) + (ny * LIGHT.y) + (nz * LIGHT.z));
        for (rgb, c) in out.rgb.iter_mut().zip(&color) {
            let v = c[k] * s;
            rgb[k] = if v < 255.0 { v } else { 255.0 };
        }
    }
    out
}

/// [`hit_cylinder`]'s depth for every lane at once, `f32::INFINITY` where it has none:
/// the same operations in the same order on every lane (so the same bits), the branches
/// turned into selects.
#[inline(always)]
pub(super) fn hit_cylinder_lanes(
    o: Vec3,
    rays: &Rays,
    base: Vec3,
    radius: f32,
    height: f32,
) -> [f32; LANES] {
    let (ox, oz) = (o.x - base.x, o.z - base.z);
    let rr = radius * radius;
    let c = ox * ox + oz * oz - rr;
    let cap = base.y + height - o.y;
    let mut out = [f32::INFINITY; LANES];
    for (k, out) in out.iter_mut().enumerate() {
        let (dx, dy, dz) = (rays.dx[k], rays.dy[k], rays.dz[k]);
        let a = dx * dx + dz * dz;
        let b = ox * dx + oz * dz;
        let disc = b * b - a * c;
        let ts = (-b - disc.sqrt()) / a;
        let y = o.y + ts * dy - base.y;
        let side = a > 0.0 && disc >= 0.0 && ts > NEAR_M && y >= 0.0 && y <= height;
        let best = if side { ts } else { f32::INFINITY };
        let tc = cap / dy;
        let (x, z) = (ox + tc * dx, oz + tc * dz);
        let top = dy != 0.0 && tc > NEAR_M && tc < best && x * x + z * z <= rr;
        *out = if top { tc } else { best };
    }
    out
}
