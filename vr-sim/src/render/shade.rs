//! Shading an image row by row: the rows of one image (on the calling thread or the pool),
//! the row shader chosen for the CPU, and the packet walk over a tile's list.

use super::*;

/// Images with fewer pixels are shaded on the calling thread.
pub(super) const MIN_POOL_PIXELS: u32 = 4096;

/// Shades every row of one image into `data`.
pub(super) fn draw(
    view: &View<'_>,
    desc: &ImageDesc,
    format: PixelFormat,
    data: &mut [u8],
    pool: Option<&rayon::ThreadPool>,
    shade_row: RowShader,
) {
    let stride = desc.stride_bytes as usize;
    let rows = data.chunks_exact_mut(stride).take(desc.height_px as usize);
    match pool {
        Some(pool) if desc.width_px * desc.height_px >= MIN_POOL_PIXELS => {
            let height = desc.height_px as usize;
            pool.install(|| {
                data[..stride * height]
                    .par_chunks_exact_mut(stride)
                    .with_min_len(4)
                    .enumerate()
                    .for_each(|(y, row)| shade_row(view, y as u32, format, row));
            });
        }
        _ => {
            for (y, row) in rows.enumerate() {
                shade_row(view, y as u32, format, row);
            }
        }
    }
}

/// Shades one row of an image.
pub(super) type RowShader = fn(&View<'_>, u32, PixelFormat, &mut [u8]);

/// [`shade_row`] compiled for the widest vector instructions this CPU has: AVX2 (8 lanes
/// per instruction instead of SSE2's 4) where the CPU has it. The pixels are the same:
/// the lane loops do the same IEEE operations in the same order either way (Rust never
/// fuses a multiply and an add on its own).
pub(super) fn row_shader() -> RowShader {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        return shade_row_avx2;
    }
    shade_row
}

/// [`shade_row`] with AVX2. Only [`row_shader`] hands it out, after checking the CPU.
#[cfg(target_arch = "x86_64")]
pub(super) fn shade_row_avx2(view: &View<'_>, y: u32, format: PixelFormat, row: &mut [u8]) {
    #[target_feature(enable = "avx2")]
    fn with_avx2(view: &View<'_>, y: u32, format: PixelFormat, row: &mut [u8]) {
        shade_row_inline(view, y, format, row);
    }
    // SAFETY: `row_shader` returns this function only when the CPU has AVX2.
    unsafe { with_avx2(view, y, format, row) }
}

pub(super) fn shade_row(view: &View<'_>, y: u32, format: PixelFormat, row: &mut [u8]) {
    shade_row_inline(view, y, format, row);
}

#[inline(always)]
pub(super) fn shade_row_inline(view: &View<'_>, y: u32, format: PixelFormat, row: &mut [u8]) {
    match format {
        PixelFormat::Rgb8 => shade_row_as::<true>(view, y, row, 3, |px, c, _| {
            px[0] = c.x as u8;
            px[1] = c.y as u8;
            px[2] = c.z as u8;
        }),
        PixelFormat::Rgba8 => shade_row_as::<true>(view, y, row, 4, |px, c, _| {
            px[0] = c.x as u8;
            px[1] = c.y as u8;
            px[2] = c.z as u8;
            px[3] = 255;
        }),
        PixelFormat::Gray8 => shade_row_as::<true>(view, y, row, 1, |px, c, _| {
            px[0] = (0.299 * c.x + 0.587 * c.y + 0.114 * c.z) as u8;
        }),
        PixelFormat::Depth32f => shade_row_as::<false>(view, y, row, 4, |px, _, depth| {
            px.copy_from_slice(&depth.to_ne_bytes());
        }),
    }
}

/// Shades row `y`: `write(pixel bytes, colour 0..=255, depth m)` stores one pixel; the
/// colour is only computed when `COLOR` (a depth image has none), and a colour image's
/// bytes for each [`RoomFace`] are written once per row, then copied.
///
/// The row is traced in packets of [`LANES`] pixels. A packet walks its tile's list until
/// every one of its rays has a hit nearer than the next entry; a ray keeps being tested
/// past the entry where it alone would have stopped, but no later primitive can be
/// nearer than its hit (the list is by nearest possible depth), so every pixel is what
/// tracing it alone gives.
#[inline(always)]
pub(super) fn shade_row_as<const COLOR: bool>(
    view: &View<'_>,
    y: u32,
    row: &mut [u8],
    bpp: usize,
    write: impl Fn(&mut [u8], Vec3, f32),
) {
    let cam = &view.cam;
    let RowRays { row_dir, u0, du } = RowRays::of(cam, y);
    let o = cam.origin;
    let tiles = view.tiles;
    let tile_row = (y / tiles.height * tiles.cols) as usize;
    let width = cam.width_px as usize;
    let ye = y as u16;
    let mut room_px = [[0u8; 4]; ROOM_FACES];
    if COLOR {
        for (px, &c) in room_px.iter_mut().zip(&view.room_colors) {
            write(&mut px[..bpp], c, 0.0);
        }
    }
    let mut rays = Rays::default();
    for x0 in (0..width).step_by(LANES) {
        let n = LANES.min(width - x0);
        for k in 0..LANES {
            // `row_dir + s · right`, component by component.
            // (As i32: the same value, converted by one instruction.)
            let s = u0 + (x0 + k) as i32 as f32 * du;
            rays.dx[k] = row_dir.x + s * cam.right.x;
            rays.dy[k] = row_dir.y + s * cam.right.y;
            rays.dz[k] = row_dir.z + s * cam.right.z;
        }
        let (mut t, face) = room_exit_lanes(o, &rays, view.room_min, view.room_max);
        let ray = |k: usize| Vec3::new(rays.dx[k], rays.dy[k], rays.dz[k]);
        // Per lane, the nearest hit so far (`u32::MAX`: the room) and its collection
        // index (0 for the room, so that no primitive at the room's depth replaces it).
        let mut nearest = [u32::MAX; LANES];
        let mut nearest_index = [0u32; LANES];
        // Lanes past the image's edge are never hit (and never drawn).
        t[n..].fill(f32::NEG_INFINITY);
        let far = |t: &[f32; LANES]| t.iter().fold(f32::MIN, |m, &v| m.max(v));
        let mut t_far = far(&t);
        let tile = tile_row + x0 / tiles.width as usize;
        let list = &tiles.items[tiles.start[tile] as usize..tiles.start[tile + 1] as usize];
        let (first, last) = (x0 as u16, (x0 + n - 1) as u16);
        for e in list {
            if e.near > t_far {
                // This one and all after it are farther than every lane's hit.
                break;
            }
            if ye < e.y0 || ye > e.y1 || last < e.x0 || first > e.x1 {
                continue;
            }
            let p = &view.prims[e.index as usize];
            let th = match p.kind {
                PrimKind::Body {
                    base,
                    radius,
                    height,
                } => hit_cylinder_lanes(o, &rays, base, radius, height),
                _ => std::array::from_fn(|k| {
                    let d = ray(k);
                    hit_prim(p, o, d, recip(d)).unwrap_or(f32::INFINITY)
                }),
            };
            let mut changed = false;
            for k in 0..LANES {
                let xe = first.wrapping_add(k as u16);
                if xe >= e.x0
                    && xe <= e.x1
                    && (th[k] < t[k] || (th[k] == t[k] && e.index < nearest_index[k]))
                {
                    t[k] = th[k];
                    nearest[k] = e.index;
                    nearest_index[k] = e.index;
                    changed = true;
                }
            }
            if changed {
                t_far = far(&t);
            }
        }
        let bodies = if COLOR && nearest.iter().any(|&i| i != u32::MAX) {
            body_colors_lanes(o, &rays, &t, &nearest, view.prims)
        } else {
            BodyColors::default()
        };
        for k in 0..n {
            let at = (x0 + k) * bpp;
            let Some(px) = row.get_mut(at..at + bpp) else {
                continue;
            };
            if !COLOR {
                write(px, Vec3::ZERO, t[k]);
            } else if bodies.hit[k] {
                let c = Vec3::new(bodies.rgb[0][k], bodies.rgb[1][k], bodies.rgb[2][k]);
                write(px, c, t[k]);
            } else if let Some(p) = view.prims.get(nearest[k] as usize) {
                let d = ray(k);
                let color = shade(p.color, normal_at(p, o, d, recip(d), t[k]));
                write(px, color.min(Vec3::splat(255.0)), t[k]);
            } else {
                let face = match face[k] as usize {
                    f if f == RoomFace::Floor as usize => floor_face(o, ray(k), t[k]),
                    f => f % ROOM_FACES,
                };
                px.copy_from_slice(&room_px[face][..bpp]);
            }
        }
    }
}
