//! The renderer's per-pixel loop as it was before the per-tile lists (test only): each
//! row lists the primitives whose rectangle covers it (all of them past 64), each pixel
//! tests, in collection order, every one of them whose rectangle covers its column and
//! keeps the first nearest hit. The fast renderer must give the same bytes.

use glam::Vec3;
use vrsync_bridge::{ImageMut, PixelFormat};

#[cfg(doc)]
use super::Renderer;
use super::{AGENT_COLORS, Prim, PrimKind, View, floor_i32, hit_prim, normal_at, rgb, shade};
use crate::geometry::{Camera, exit_box, recip};
use crate::world::{Body, World};
use crate::world_config::Shape;

/// The objects and bodies whose screen rectangle ([`Camera::screen_rect`]: the whole image
/// for a box reaching behind the near plane) overlaps the image, in collection order.
fn collect_prims(world: &World, me: &Body, cam: &Camera) -> Vec<Prim> {
    let mut prims = Vec::new();
    let mut push = |kind: PrimKind, color: [u8; 3], min: Vec3, max: Vec3| {
        if let Some((x0, x1, y0, y1)) = cam.screen_rect(min, max) {
            let index = prims.len() as u32;
            prims.push(Prim {
                kind,
                color: rgb(color),
                x0,
                x1,
                y0,
                y1,
                near: f32::NEG_INFINITY,
                index,
            });
        }
    };
    for o in world.objects() {
        let (min, max) = o.bounds();
        let kind = match o.shape {
            Shape::Sphere { radius } => PrimKind::Sphere {
                center: o.position,
                radius,
            },
            Shape::Box { .. } => PrimKind::Box { min, max },
        };
        push(kind, o.color, min, max);
    }
    let cfg = world.config();
    let (r, h) = (cfg.agent_radius, cfg.body_height);
    for b in world.bodies() {
        if b.id == me.id {
            continue;
        }
        let kind = PrimKind::Body {
            base: b.position,
            radius: r,
            height: h,
        };
        let color = AGENT_COLORS[b.id as usize % AGENT_COLORS.len()];
        push(
            kind,
            color,
            b.position - Vec3::new(r, 0.0, r),
            b.position + Vec3::new(r, h, r),
        );
    }
    prims
}

/// Renders one image like [`Renderer::render_image`], on the calling thread, the slow way.
pub(super) fn render_image(world: &World, body: &Body, image: ImageMut<'_>) {
    let desc = image.desc;
    if desc.width_px == 0 || desc.height_px == 0 {
        return;
    }
    let cam = super::camera_of(world, body, &desc);
    let prims = collect_prims(world, body, &cam);
    let tiles = super::Tiles::default();
    let view = super::view_of(world, cam, &prims, &tiles);
    let cfg = world.config();
    let room = Room {
        floor: cfg.floor_colors.map(super::rgb),
        walls: cfg.wall_colors.map(super::rgb),
        ceiling: super::rgb(cfg.ceiling_color),
    };
    let stride = desc.stride_bytes as usize;
    let format = desc.pixel_format().unwrap_or_default();
    for (y, row) in image
        .data
        .chunks_exact_mut(stride)
        .take(desc.height_px as usize)
        .enumerate()
    {
        let y = y as u32;
        match format {
            PixelFormat::Rgb8 => shade_row_as(&view, &room, y, row, 3, |px, c, _| {
                px[0] = c.x as u8;
                px[1] = c.y as u8;
                px[2] = c.z as u8;
            }),
            PixelFormat::Rgba8 => shade_row_as(&view, &room, y, row, 4, |px, c, _| {
                px[0] = c.x as u8;
                px[1] = c.y as u8;
                px[2] = c.z as u8;
                px[3] = 255;
            }),
            PixelFormat::Gray8 => shade_row_as(&view, &room, y, row, 1, |px, c, _| {
                px[0] = (0.299 * c.x + 0.587 * c.y + 0.114 * c.z) as u8;
            }),
            PixelFormat::Depth32f => shade_row_as(&view, &room, y, row, 4, |px, _, depth| {
                px.copy_from_slice(&depth.to_ne_bytes());
            }),
        }
    }
}

/// The room's colours, from the config.
struct Room {
    floor: [Vec3; 2],
    walls: [Vec3; 4],
    ceiling: Vec3,
}

/// Shades row `y`: `write(pixel bytes, colour 0..=255, depth m)` stores one pixel.
#[inline(always)]
fn shade_row_as(
    view: &View<'_>,
    room: &Room,
    y: u32,
    row: &mut [u8],
    bpp: usize,
    write: impl Fn(&mut [u8], Vec3, f32),
) {
    let cam = &view.cam;
    let row_dir = cam.forward + cam.v_of(y as f32 + 0.5) * cam.up;
    let du = 2.0 * cam.tan_half_h / cam.width_px as f32;
    let u0 = -cam.tan_half_h + 0.5 * du;
    let o = cam.origin;
    // The primitives that can cover this row (all of them past 64, which is only slower).
    let mut active = [0u16; 64];
    let mut n_active = 0;
    for (i, p) in view.prims.iter().enumerate() {
        if (p.y0..=p.y1).contains(&y) {
            if n_active == active.len() {
                n_active = usize::MAX;
                break;
            }
            active[n_active] = i as u16;
            n_active += 1;
        }
    }
    let all: [u16; 0] = [];
    let (candidates, all_prims) = if n_active == usize::MAX {
        (&all[..], true)
    } else {
        (&active[..n_active], false)
    };
    let width = cam.width_px as usize;
    for (x, px) in row.chunks_exact_mut(bpp).take(width).enumerate() {
        let d = row_dir + (u0 + x as f32 * du) * cam.right;
        let inv = recip(d);
        let (mut t, axis, positive) = exit_box(o, inv, view.room_min, view.room_max);
        let mut nearest = usize::MAX;
        let xs = x as u32;
        let mut consider = |i: usize| {
            let p = &view.prims[i];
            if xs >= p.x0
                && xs <= p.x1
                && let Some(th) = hit_prim(p, o, d, inv)
                && th < t
            {
                t = th;
                nearest = i;
            }
        };
        if all_prims {
            (0..view.prims.len()).for_each(&mut consider);
        } else {
            candidates.iter().for_each(|&i| consider(usize::from(i)));
        }
        let hit = (nearest != usize::MAX)
            .then(|| (nearest, normal_at(&view.prims[nearest], o, d, inv, t)));
        let color = match hit {
            Some((i, n)) => shade(view.prims[i].color, n),
            None => {
                let q = o + t * d;
                match (axis, positive) {
                    (1, false) => {
                        let parity = (floor_i32(q.x) + floor_i32(q.z)) & 1;
                        shade(room.floor[parity as usize], Vec3::Y)
                    }
                    (1, true) => room.ceiling,
                    (0, true) => shade(room.walls[1], Vec3::NEG_X),
                    (0, false) => shade(room.walls[3], Vec3::X),
                    (_, true) => shade(room.walls[0], Vec3::NEG_Z),
                    (_, false) => shade(room.walls[2], Vec3::Z),
                }
            }
        };
        write(px, color.min(Vec3::splat(255.0)), t);
    }
}
