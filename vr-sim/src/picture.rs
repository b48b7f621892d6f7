//! Pictures for people: the agents' camera images as PNG files (`--dump-frames`) and a
//! top-down map of the room with every agent's trajectory (`--map`).

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use glam::{Vec2, Vec3};
use vrsync_bridge::ImageMut;
use vrsync_bridge::PixelFormat;

use crate::geometry;
use crate::render::AGENT_COLORS;
use crate::world::World;
use crate::world_config::{GoalKind, Shape};

/// Why a picture could not be written.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PictureWriteError {
    /// The file could not be created or written.
    #[error("cannot write {path}: {error}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error (in the message, so not also a `source()`: printed once).
        error: std::io::Error,
    },
    /// PNG encoding failed.
    #[error("cannot encode {path}: {error}")]
    Png {
        /// The file.
        path: PathBuf,
        /// The encoder's error (in the message, so not also a `source()`).
        error: png::EncodingError,
    },
}

/// Writes an 8-bit (or, for `Grayscale` with 2 bytes a sample, 16-bit) PNG.
///
/// # Errors
/// [`PictureWriteError`].
pub fn write_png(
    path: &Path,
    width: u32,
    height: u32,
    color: png::ColorType,
    depth: png::BitDepth,
    data: &[u8],
) -> Result<(), PictureWriteError> {
    let file = File::create(path).map_err(|error| PictureWriteError::Io {
        path: path.to_path_buf(),
        error,
    })?;
    let mut encoder = png::Encoder::new(BufWriter::new(file), width, height);
    encoder.set_color(color);
    encoder.set_depth(depth);
    let png_err = |error| PictureWriteError::Png {
        path: path.to_path_buf(),
        error,
    };
    let mut writer = encoder.write_header().map_err(png_err)?;
    writer.write_image_data(data).map_err(png_err)?;
    writer.finish().map_err(png_err)
}

/// Writes one camera image of a frame as `DIR/c<cycle>_a<agent>_<camera>.png`. Depth
/// images become 16-bit grey in millimetres (0 to 65.535 m).
///
/// # Errors
/// [`PictureWriteError`].
pub fn dump_image(
    dir: &Path,
    cycle: u64,
    agent: u32,
    image: &ImageMut<'_>,
) -> Result<PathBuf, PictureWriteError> {
    let d = image.desc;
    let path = dir.join(format!("c{cycle:06}_a{agent}_{}.png", d.name()));
    let (w, h) = (d.width_px, d.height_px);
    let format = d.pixel_format().unwrap_or_default();
    let bpp = format.bytes_per_pixel();
    let stride = d.stride_bytes as usize;
    // PNG wants tightly packed rows; copy only when the stride has padding.
    let packed: std::borrow::Cow<'_, [u8]> = if stride == w as usize * bpp {
        std::borrow::Cow::Borrowed(&image.data[..stride * h as usize])
    } else {
        std::borrow::Cow::Owned(
            image
                .data
                .chunks_exact(stride)
                .take(h as usize)
                .flat_map(|row| &row[..w as usize * bpp])
                .copied()
                .collect(),
        )
    };
    match format {
        PixelFormat::Rgb8 => write_png(
            &path,
            w,
            h,
            png::ColorType::Rgb,
            png::BitDepth::Eight,
            &packed,
        )?,
        PixelFormat::Rgba8 => {
            write_png(
                &path,
                w,
                h,
                png::ColorType::Rgba,
                png::BitDepth::Eight,
                &packed,
            )?;
        }
        PixelFormat::Gray8 => write_png(
            &path,
            w,
            h,
            png::ColorType::Grayscale,
            png::BitDepth::Eight,
            &packed,
        )?,
        PixelFormat::Depth32f => {
            let mm: Vec<u8> = packed
                .chunks_exact(4)
                .flat_map(|b| {
                    let m = f32::from_ne_bytes([b[0], b[1], b[2], b[3]]);
                    ((m * 1000.0).clamp(0.0, 65535.0) as u16).to_be_bytes()
                })
                .collect();
            write_png(
                &path,
                w,
                h,
                png::ColorType::Grayscale,
                png::BitDepth::Sixteen,
                &mm,
            )?;
        }
    }
    Ok(path)
}

/// Every agent's floor positions, one per cycle, for the map.
#[derive(Debug, Clone, Default)]
pub struct Trails {
    trails: Vec<(u32, Vec<Vec2>)>,
}

impl Trails {
    /// Starts trails at the bodies' current positions.
    pub fn new(world: &World) -> Self {
        Self {
            trails: world
                .bodies()
                .iter()
                .map(|b| (b.id, vec![Vec2::new(b.position.x, b.position.z)]))
                .collect(),
        }
    }

    /// Appends the bodies' current positions.
    pub fn push(&mut self, world: &World) {
        for (b, (_, trail)) in world.bodies().iter().zip(&mut self.trails) {
            trail.push(Vec2::new(b.position.x, b.position.z));
        }
    }
}

/// An RGB raster with metre coordinates mapped to pixels.
struct Canvas {
    width: u32,
    height: u32,
    px: Vec<u8>,
    scale: f32,
    min: Vec2,
    margin: f32,
}

impl Canvas {
    fn to_px(&self, p: Vec2) -> Vec2 {
        // North (+z) is up on the map, east (+x) to the right.
        Vec2::new(
            self.margin + (p.x - self.min.x) * self.scale,
            self.height as f32 - self.margin - (p.y - self.min.y) * self.scale,
        )
    }

    fn put(&mut self, x: i64, y: i64, c: [u8; 3], alpha: f32) {
        if x < 0 || y < 0 || x >= i64::from(self.width) || y >= i64::from(self.height) {
            return;
        }
        let i = (y as usize * self.width as usize + x as usize) * 3;
        for (dst, &src) in self.px[i..i + 3].iter_mut().zip(&c) {
            let old = f32::from(*dst);
            *dst = (old + (f32::from(src) - old) * alpha) as u8;
        }
    }

    /// Fills the pixels whose centre satisfies `inside` (in metres) within a box.
    fn fill(&mut self, lo: Vec2, hi: Vec2, c: [u8; 3], alpha: f32, inside: impl Fn(Vec2) -> bool) {
        let (a, b) = (
            self.to_px(Vec2::new(lo.x, hi.y)),
            self.to_px(Vec2::new(hi.x, lo.y)),
        );
        for y in a.y.floor() as i64..=b.y.ceil() as i64 {
            for x in a.x.floor() as i64..=b.x.ceil() as i64 {
                let m = Vec2::new(
                    (x as f32 + 0.5 - self.margin) / self.scale + self.min.x,
                    (self.height as f32 - self.margin - (y as f32 + 0.5)) / self.scale + self.min.y,
                );
                if inside(m) {
                    self.put(x, y, c, alpha);
                }
            }
        }
    }

    fn disc(&mut self, center: Vec2, radius_m: f32, c: [u8; 3], alpha: f32) {
        let r = Vec2::splat(radius_m);
        self.fill(center - r, center + r, c, alpha, |m| {
            m.distance_squared(center) <= radius_m * radius_m
        });
    }

    fn ring(&mut self, center: Vec2, radius_m: f32, width_m: f32, c: [u8; 3]) {
        let r = Vec2::splat(radius_m + width_m);
        self.fill(center - r, center + r, c, 1.0, |m| {
            let d = m.distance(center);
            (radius_m - width_m / 2.0..=radius_m + width_m / 2.0).contains(&d)
        });
    }

    /// A line `width_px` wide, drawn with discs along it.
    fn line(&mut self, a: Vec2, b: Vec2, width_px: f32, c: [u8; 3]) {
        let (pa, pb) = (self.to_px(a), self.to_px(b));
        let steps = (pa.distance(pb) * 2.0).ceil().max(1.0) as usize;
        let r = width_px / 2.0;
        for s in 0..=steps {
            let p = pa.lerp(pb, s as f32 / steps as f32);
            for y in (p.y - r).floor() as i64..=(p.y + r).ceil() as i64 {
                for x in (p.x - r).floor() as i64..=(p.x + r).ceil() as i64 {
                    if Vec2::new(x as f32 + 0.5, y as f32 + 0.5).distance_squared(p) <= r * r {
                        self.put(x, y, c, 1.0);
                    }
                }
            }
        }
    }
}

/// Draws the room from above (north up): walls, a 1 m grid, goal regions (green), objects
/// in their colours, and each agent's trajectory in its body colour from a ring (start)
/// to a dot with a heading tick (end).
///
/// # Errors
/// [`PictureWriteError`].
pub fn write_map(path: &Path, world: &World, trails: &Trails) -> Result<(), PictureWriteError> {
    let cfg = world.config();
    let (min, max) = world.room_bounds();
    let (min, max) = (Vec2::new(min.x, min.z), Vec2::new(max.x, max.z));
    let size = max - min;
    let scale = (900.0 / size.max_element()).clamp(10.0, 120.0);
    let margin = 20.0;
    let width = (size.x * scale + 2.0 * margin).ceil() as u32;
    let height = (size.y * scale + 2.0 * margin).ceil() as u32;
    let mut c = Canvas {
        width,
        height,
        px: vec![255; width as usize * height as usize * 3],
        scale,
        min,
        margin,
    };
    // Floor and grid.
    c.fill(min, max, [238, 238, 232], 1.0, |_| true);
    let mut x = min.x.ceil();
    while x < max.x {
        c.line(
            Vec2::new(x, min.y),
            Vec2::new(x, max.y),
            1.0,
            [215, 215, 210],
        );
        x += 1.0;
    }
    let mut z = min.y.ceil();
    while z < max.y {
        c.line(
            Vec2::new(min.x, z),
            Vec2::new(max.x, z),
            1.0,
            [215, 215, 210],
        );
        z += 1.0;
    }
    for g in &cfg.goals {
        if let GoalKind::Region { center, radius } = g.kind {
            c.disc(center, radius, [70, 200, 90], 0.3);
            c.ring(center, radius, 2.0 / scale, [50, 150, 70]);
        }
    }
    for o in world.objects() {
        let p = Vec2::new(o.position.x, o.position.z);
        match o.shape {
            Shape::Box { size } => {
                let h = Vec2::new(size.x, size.z) / 2.0;
                c.fill(p - h, p + h, [40, 40, 40], 1.0, |_| true);
                let inset = Vec2::splat(2.0 / scale);
                c.fill(p - h + inset, p + h - inset, o.color, 1.0, |_| true);
            }
            Shape::Sphere { radius } => {
                c.disc(p, radius, [40, 40, 40], 1.0);
                c.disc(p, radius - 2.0 / scale, o.color, 1.0);
            }
        }
    }
    for (id, trail) in &trails.trails {
        let color = AGENT_COLORS[*id as usize % AGENT_COLORS.len()];
        let dark = color.map(|v| (f32::from(v) * 0.6) as u8);
        for w in trail.windows(2) {
            c.line(w[0], w[1], 3.0, dark);
        }
        if let (Some(&first), Some(&last)) = (trail.first(), trail.last()) {
            c.ring(first, cfg.agent_radius, 3.0 / scale, dark);
            c.disc(last, cfg.agent_radius, color, 1.0);
            c.ring(last, cfg.agent_radius, 2.0 / scale, dark);
            if let Some(b) = world.bodies().iter().find(|b| b.id == *id) {
                let f: Vec3 = geometry::forward_of(b.heading_deg, 0.0);
                let tip = last + Vec2::new(f.x, f.z) * cfg.agent_radius * 1.8;
                c.line(last, tip, 3.0, [30, 30, 30]);
            }
        }
    }
    // Walls last, on top of everything.
    let corners = [
        Vec2::new(min.x, min.y),
        Vec2::new(max.x, min.y),
        Vec2::new(max.x, max.y),
        Vec2::new(min.x, max.y),
    ];
    for i in 0..4 {
        c.line(corners[i], corners[(i + 1) % 4], 4.0, [60, 60, 70]);
    }
    write_png(
        path,
        width,
        height,
        png::ColorType::Rgb,
        png::BitDepth::Eight,
        &c.px,
    )
}
