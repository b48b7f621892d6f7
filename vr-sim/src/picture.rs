//! Pictures for people: the agents' camera images as PNG files (`--dump-frames`) and a
//! top-down map of the room with every agent's trajectory, labels and a legend (`--map`).

mod font;

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use glam::{Vec2, Vec3};
use vrsync_bridge::ImageMut;
use vrsync_bridge::PixelFormat;

use crate::geometry;
use crate::render::AGENT_COLORS;
use crate::world::World;
use crate::world_config::{GoalAction, GoalKind, Shape};

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

/// The pixels of `image`, rows tightly packed (copied only when the stride has padding).
pub fn packed_pixels<'a>(image: &'a ImageMut<'_>) -> std::borrow::Cow<'a, [u8]> {
    let d = image.desc;
    let (w, h) = (d.width_px as usize, d.height_px as usize);
    let row = w * d.pixel_format().unwrap_or_default().bytes_per_pixel();
    let stride = d.stride_bytes as usize;
    if stride == row {
        std::borrow::Cow::Borrowed(&image.data[..stride * h])
    } else {
        std::borrow::Cow::Owned(
            image
                .data
                .chunks_exact(stride)
                .take(h)
                .flat_map(|r| &r[..row])
                .copied()
                .collect(),
        )
    }
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
    // PNG wants tightly packed rows.
    let packed = packed_pixels(image);
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

/// Margin around the room on the map, pixels.
const MARGIN: f32 = 20.0;
/// Each font pixel is drawn as a square of this many image pixels.
const TEXT_SCALE: i64 = 2;
/// Height of the text, pixels.
const TEXT_H: i64 = font::GLYPH_H as i64 * TEXT_SCALE;
/// Height of one legend row, pixels.
const ROW_H: i64 = 22;
/// Longest scale bar, pixels.
const SCALE_BAR_MAX_PX: f32 = 160.0;
/// Colour of text, the scale bar and the legend's markers.
const INK: [u8; 3] = [30, 30, 30];
/// Background of the picture outside the room and of the legend.
const PAPER: [u8; 3] = [255, 255, 255];
const GRID: [u8; 3] = [215, 215, 210];
const GOAL_FILL: [u8; 3] = [70, 200, 90];
const GOAL_EDGE: [u8; 3] = [50, 150, 70];
const OBJECT_EDGE: [u8; 3] = [40, 40, 40];

/// An RGB raster with metre coordinates mapped to pixels.
struct Canvas {
    width: u32,
    height: u32,
    px: Vec<u8>,
    /// Pixels per metre.
    scale: f32,
    /// The room's south-west corner (x, z), metres.
    min: Vec2,
    /// Pixel row of the room's south wall (`min.y`).
    map_bottom: f32,
}

impl Canvas {
    fn to_px(&self, p: Vec2) -> Vec2 {
        // North (+z) is up on the map, east (+x) to the right.
        Vec2::new(
            MARGIN + (p.x - self.min.x) * self.scale,
            self.map_bottom - (p.y - self.min.y) * self.scale,
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
                    (x as f32 + 0.5 - MARGIN) / self.scale + self.min.x,
                    (self.map_bottom - (y as f32 + 0.5)) / self.scale + self.min.y,
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
        self.line_px(pa, pb, width_px, c);
    }

    /// [`Canvas::line`] in pixel coordinates.
    fn line_px(&mut self, pa: Vec2, pb: Vec2, width_px: f32, c: [u8; 3]) {
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

    /// A `w` × `h` pixel rectangle with its top-left corner at `(x, y)`.
    fn rect(&mut self, x: i64, y: i64, w: i64, h: i64, c: [u8; 3], alpha: f32) {
        for yy in y..y + h {
            for xx in x..x + w {
                self.put(xx, yy, c, alpha);
            }
        }
    }

    /// The pixels whose centre is between `r_in` and `r_out` pixels from `center`.
    fn annulus_px(&mut self, center: Vec2, r_in: f32, r_out: f32, c: [u8; 3]) {
        let reach = r_out.ceil() as i64 + 1;
        let (cx, cy) = (center.x.floor() as i64, center.y.floor() as i64);
        for y in cy - reach..=cy + reach {
            for x in cx - reach..=cx + reach {
                let d = Vec2::new(x as f32 + 0.5, y as f32 + 0.5).distance(center);
                if (r_in..=r_out).contains(&d) {
                    self.put(x, y, c, 1.0);
                }
            }
        }
    }

    /// `text` in the built-in font with its top-left corner at `(x, y)`.
    fn text(&mut self, x: i64, y: i64, text: &str, c: [u8; 3]) {
        for (i, ch) in text.chars().enumerate() {
            let left = x + i as i64 * i64::from(font::ADVANCE) * TEXT_SCALE;
            for fy in 0..font::GLYPH_H {
                for fx in 0..font::GLYPH_W {
                    if font::is_set(ch, fx, fy) {
                        self.rect(
                            left + i64::from(fx) * TEXT_SCALE,
                            y + i64::from(fy) * TEXT_SCALE,
                            TEXT_SCALE,
                            TEXT_SCALE,
                            c,
                            1.0,
                        );
                    }
                }
            }
        }
    }

    /// `text` on a light box, for labels drawn over the room.
    fn label(&mut self, x: i64, y: i64, text: &str) {
        self.rect(x - 2, y - 2, text_px(text) + 4, TEXT_H + 4, PAPER, 0.85);
        self.text(x, y, text, INK);
    }
}

/// Width of `text` in the built-in font, pixels.
fn text_px(text: &str) -> i64 {
    i64::from(font::text_width(text)) * TEXT_SCALE
}

/// The longest of 1, 2 and 5 times a power of ten metres that fits in the scale bar.
fn scale_bar_metres(px_per_m: f32) -> f32 {
    let mut best = 0.1;
    for exp in -1..=4 {
        for step in [1.0, 2.0, 5.0] {
            let m = step * 10f32.powi(exp);
            if m * px_per_m <= SCALE_BAR_MAX_PX {
                best = m;
            }
        }
    }
    best
}

/// Where [`render_map`] put the scale bar: pixels `x0..x1` on rows `y..y + 4`, `metres` long.
#[derive(Debug, Clone, Copy)]
struct ScaleBar {
    x0: i64,
    x1: i64,
    y: i64,
    #[cfg_attr(not(test), allow(dead_code))]
    metres: f32,
}

/// The map and where its legend's parts are (read by the tests).
struct Map {
    canvas: Canvas,
    /// First pixel column of the legend panel (right of the room).
    #[cfg_attr(not(test), allow(dead_code))]
    legend_x: i64,
    #[cfg_attr(not(test), allow(dead_code))]
    scale_bar: ScaleBar,
}

/// The goals' labels, in config order: `G<n> REGION +<reward>` or `G<n> <ACTION>
/// #<object> +<reward>` (the map's legend, the Rerun log's goals).
pub fn goal_labels(cfg: &crate::world_config::WorldConfig) -> Vec<String> {
    cfg.goals
        .iter()
        .enumerate()
        .map(|(i, g)| match g.kind {
            GoalKind::Region { .. } => format!("G{} REGION {:+}", i + 1, g.reward),
            GoalKind::Object { object, action } => {
                format!(
                    "G{} {} #{object} {:+}",
                    i + 1,
                    action_name(action),
                    g.reward
                )
            }
        })
        .collect()
}

/// The name of a goal's action in the legend.
fn action_name(a: GoalAction) -> &'static str {
    match a {
        GoalAction::Grasp => "GRASP",
        GoalAction::Point => "POINT",
        GoalAction::Interact => "INTERACT",
    }
}

/// Draws the room from above (north up): walls, a 1 m grid, goal regions (green, labelled
/// `G<n>` in config order), objects in their colours (labelled `#<id>` and the goals on
/// them), and each agent's trajectory in its body colour from a hollow circle (start) to a
/// filled one with a heading tick (end). A legend right of the room names each agent's
/// colour, the markers, the goals, and has a scale bar in metres.
fn render_map(world: &World, trails: &Trails) -> Map {
    let cfg = world.config();
    let (min, max) = world.room_bounds();
    let (min, max) = (Vec2::new(min.x, min.z), Vec2::new(max.x, max.z));
    let size = max - min;
    let scale = (900.0 / size.max_element()).clamp(10.0, 120.0);
    let map_w = (size.x * scale + 2.0 * MARGIN).ceil() as i64;
    let map_h = (size.y * scale + 2.0 * MARGIN).ceil() as i64;

    // Legend text, to size the panel.
    let agent_rows: Vec<(u32, String)> = trails
        .trails
        .iter()
        .map(|(id, _)| (*id, format!("AGENT {id}")))
        .collect();
    let goal_rows = goal_labels(cfg);
    let marker_rows = ["START", "END, TICK = HEADING"];
    let objects_row = "#N = OBJECT ID";
    let grid_row = "GRID 1 M";
    let metres = scale_bar_metres(scale);
    let bar_label = format!("SCALE {metres} M");
    let text_w = agent_rows
        .iter()
        .map(|(_, t)| t.as_str())
        .chain(goal_rows.iter().map(String::as_str))
        .chain(marker_rows)
        .chain([objects_row, grid_row])
        .map(text_px)
        .max()
        .unwrap_or(0);
    let legend_x = map_w;
    let panel_w = (32 + text_w)
        .max(SCALE_BAR_MAX_PX as i64)
        .max(text_px(&bar_label))
        + 20;
    let rows = agent_rows.len() + marker_rows.len() + goal_rows.len() + 2;
    let legend_h = MARGIN as i64 + rows as i64 * ROW_H + 3 * 6 + 40 + MARGIN as i64;
    let width = (map_w + panel_w) as u32;
    let height = map_h.max(legend_h) as u32;
    let mut c = Canvas {
        width,
        height,
        px: vec![255; width as usize * height as usize * 3],
        scale,
        min,
        map_bottom: MARGIN + size.y * scale,
    };

    draw_room(&mut c, world, trails, min, max);

    // The legend: a swatch or marker in the first 32 pixels of each row, then its text.
    let x0 = legend_x + 10;
    let tx = x0 + 32;
    let mut y = MARGIN as i64;
    for (id, text) in &agent_rows {
        let color = AGENT_COLORS[*id as usize % AGENT_COLORS.len()];
        let dark = color.map(|v| (f32::from(v) * 0.6) as u8);
        c.rect(x0, y, 24, TEXT_H, dark, 1.0);
        c.rect(x0 + 3, y + 3, 18, TEXT_H - 6, color, 1.0);
        c.text(tx, y, text, INK);
        y += ROW_H;
    }
    y += 6;
    let mid = |y: i64| Vec2::new(x0 as f32 + 12.0, y as f32 + TEXT_H as f32 / 2.0);
    c.annulus_px(mid(y), 4.5, 7.0, INK);
    c.text(tx, y, marker_rows[0], INK);
    y += ROW_H;
    c.annulus_px(mid(y), 0.0, 7.0, [150, 150, 150]);
    c.annulus_px(mid(y), 5.5, 7.0, INK);
    c.line_px(mid(y), mid(y) - Vec2::new(0.0, 12.0), 2.0, INK);
    c.text(tx, y, marker_rows[1], INK);
    y += ROW_H + 6;
    for (g, text) in cfg.goals.iter().zip(&goal_rows) {
        if matches!(g.kind, GoalKind::Region { .. }) {
            c.annulus_px(mid(y), 0.0, 7.0, [180, 230, 190]);
        }
        c.annulus_px(mid(y), 5.5, 7.0, GOAL_EDGE);
        c.text(tx, y, text, INK);
        y += ROW_H;
    }
    c.rect(x0 + 5, y, 14, TEXT_H, OBJECT_EDGE, 1.0);
    c.rect(x0 + 7, y + 2, 10, TEXT_H - 4, [200, 200, 200], 1.0);
    c.text(tx, y, objects_row, INK);
    y += ROW_H;
    c.rect(x0, y + TEXT_H / 2, 24, 1, [170, 170, 165], 1.0);
    c.text(tx, y, grid_row, INK);
    y += ROW_H + 6;
    c.text(x0, y, &bar_label, INK);
    let bar = ScaleBar {
        x0,
        x1: x0 + (metres * scale).round() as i64,
        y: y + TEXT_H + 6,
        metres,
    };
    c.rect(bar.x0, bar.y, bar.x1 - bar.x0, 4, INK, 1.0);
    c.rect(bar.x0, bar.y - 4, 2, 12, INK, 1.0);
    c.rect(bar.x1 - 2, bar.y - 4, 2, 12, INK, 1.0);
    Map {
        canvas: c,
        legend_x,
        scale_bar: bar,
    }
}

/// Draws the room onto the map: floor and grid, goal regions, objects, the agents' trails
/// and final poses, the walls, then the labels.
fn draw_room(c: &mut Canvas, world: &World, trails: &Trails, min: Vec2, max: Vec2) {
    let cfg = world.config();
    let scale = c.scale;
    // Floor and grid.
    c.fill(min, max, [238, 238, 232], 1.0, |_| true);
    let mut x = min.x.ceil();
    while x < max.x {
        c.line(Vec2::new(x, min.y), Vec2::new(x, max.y), 1.0, GRID);
        x += 1.0;
    }
    let mut z = min.y.ceil();
    while z < max.y {
        c.line(Vec2::new(min.x, z), Vec2::new(max.x, z), 1.0, GRID);
        z += 1.0;
    }
    let mut labels: Vec<(Vec2, String)> = Vec::new();
    for (i, g) in cfg.goals.iter().enumerate() {
        if let GoalKind::Region { center, radius } = g.kind {
            c.disc(center, radius, GOAL_FILL, 0.3);
            c.ring(center, radius, 2.0 / scale, GOAL_EDGE);
            let corner = c.to_px(center + Vec2::splat(radius * std::f32::consts::FRAC_1_SQRT_2));
            labels.push((corner, format!("G{}", i + 1)));
        }
    }
    for o in world.objects() {
        let p = Vec2::new(o.position.x, o.position.z);
        let corner = match o.shape {
            Shape::Box { size } => {
                let h = Vec2::new(size.x, size.z) / 2.0;
                c.fill(p - h, p + h, OBJECT_EDGE, 1.0, |_| true);
                let inset = Vec2::splat(2.0 / scale);
                c.fill(p - h + inset, p + h - inset, o.color, 1.0, |_| true);
                p + h
            }
            Shape::Sphere { radius } => {
                c.disc(p, radius, OBJECT_EDGE, 1.0);
                c.disc(p, radius - 2.0 / scale, o.color, 1.0);
                p + Vec2::splat(radius * std::f32::consts::FRAC_1_SQRT_2)
            }
        };
        let mut name = format!("#{}", o.id);
        for (i, g) in cfg.goals.iter().enumerate() {
            if matches!(g.kind, GoalKind::Object { object, .. } if object == o.id) {
                name += &format!(" G{}", i + 1);
            }
        }
        labels.push((c.to_px(corner), name));
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
                c.line(last, tip, 3.0, INK);
            }
        }
    }
    // Walls on top of the room, labels on top of everything.
    let corners = [
        Vec2::new(min.x, min.y),
        Vec2::new(max.x, min.y),
        Vec2::new(max.x, max.y),
        Vec2::new(min.x, max.y),
    ];
    for i in 0..4 {
        c.line(corners[i], corners[(i + 1) % 4], 4.0, [60, 60, 70]);
    }
    for (at, text) in &labels {
        c.label(at.x as i64 + 3, at.y as i64 - TEXT_H - 3, text);
    }
}

/// Writes the map of [`render_map`] as a PNG: the room from above with every agent's
/// trajectory, labels and a legend. The same world and trails give the same bytes.
///
/// # Errors
/// [`PictureWriteError`].
pub fn write_map(path: &Path, world: &World, trails: &Trails) -> Result<(), PictureWriteError> {
    let c = render_map(world, trails).canvas;
    write_png(
        path,
        c.width,
        c.height,
        png::ColorType::Rgb,
        png::BitDepth::Eight,
        &c.px,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use vrsync_bridge::Config;

    const CAMS: &str = "[[agent.camera]]\nname = \"left\"\nwidth = 8\nheight = 6\nfov_horizontal_deg = 90.0\nfov_vertical_deg = 73.74\n";
    const FLOOR: [u8; 3] = [238, 238, 232];

    /// The default 10 × 10 room (90 px a metre, 20 px margin) with a box (id 7) at
    /// (-3, 3), a goal region at (3, 3), a grasp goal on the box, and agents 0 and 1
    /// facing north at (-1.5, -2.5) and (2.5, -2.5), each having walked 2 m east.
    fn world_and_trails() -> (World, Trails) {
        let mut text = String::from("session = \"map\"\n");
        for id in [0, 1] {
            text += &format!("[[agent]]\nid = {id}\n{CAMS}");
        }
        text += "[world]\n";
        text += "[[world.object]]\nid = 7\nshape = \"box\"\nposition = [-3.0, 0.5, 3.0]\nsize = [1.0, 1.0, 1.0]\ncolor = [40, 90, 220]\n";
        text += "[[world.goal]]\ncenter = [3.0, 3.0]\nradius = 0.5\nreward = 1.0\n";
        text += "[[world.goal]]\nobject = 7\naction = \"grasp\"\nreward = 5.0\n";
        text += "[[world.agent]]\nid = 0\nposition = [-1.5, -2.5]\nheading_deg = 0.0\n";
        text += "[[world.agent]]\nid = 1\nposition = [2.5, -2.5]\nheading_deg = 0.0\n";
        let config = Config::from_toml_str(&text, Path::new("map.toml")).unwrap();
        let world = World::from_config(&config).unwrap();
        let trails = Trails {
            trails: vec![
                (
                    0,
                    vec![
                        Vec2::new(-3.5, -2.5),
                        Vec2::new(-2.5, -2.5),
                        Vec2::new(-1.5, -2.5),
                    ],
                ),
                (1, vec![Vec2::new(0.5, -2.5), Vec2::new(2.5, -2.5)]),
            ],
        };
        (world, trails)
    }

    /// Pixel of a floor point, computed here independently of the canvas: 90 px a metre,
    /// the room's south-west corner (-5, -5) at (20, 920), north up.
    fn px(x: f32, z: f32) -> (i64, i64) {
        (
            (20.0 + (x + 5.0) * 90.0) as i64,
            (920.0 - (z + 5.0) * 90.0) as i64,
        )
    }

    fn at(c: &Canvas, (x, y): (i64, i64)) -> [u8; 3] {
        let i = (y as usize * c.width as usize + x as usize) * 3;
        [c.px[i], c.px[i + 1], c.px[i + 2]]
    }

    #[test]
    fn map_has_a_legend_markers_labels_and_a_scale_bar() {
        let (world, trails) = world_and_trails();
        let map = render_map(&world, &trails);
        let c = &map.canvas;
        assert_eq!(map.legend_x, 940, "the legend is right of the 900 px room");
        assert!(c.width > 940 + 160);

        // Legend: each agent's colour appears in the panel.
        for id in [0usize, 1] {
            let color = AGENT_COLORS[id];
            let found = (0..i64::from(c.height))
                .flat_map(|y| (map.legend_x..i64::from(c.width)).map(move |x| (x, y)))
                .any(|p| at(c, p) == color);
            assert!(found, "no legend pixel in agent {id}'s colour {color:?}");
        }

        // Start: a hollow ring of the trail's dark colour (radius 0.3 m = 27 px).
        // End: a disc filled with the agent's colour.
        for (id, start, end) in [
            (0usize, (-3.5, -2.5), (-1.5, -2.5)),
            (1, (0.5, -2.5), (2.5, -2.5)),
        ] {
            let color = AGENT_COLORS[id];
            let dark = color.map(|v| (f32::from(v) * 0.6) as u8);
            let (sx, sy) = px(start.0, start.1);
            assert_eq!(at(c, (sx, sy - 27)), dark, "agent {id}: start ring, north");
            assert_eq!(at(c, (sx, sy + 26)), dark, "agent {id}: start ring, south");
            assert_eq!(at(c, (sx, sy - 14)), FLOOR, "agent {id}: start is hollow");
            let (ex, ey) = px(end.0, end.1);
            assert_eq!(
                at(c, (ex + 12, ey + 12)),
                color,
                "agent {id}: end is filled"
            );
            assert_eq!(
                at(c, (ex - 12, ey + 12)),
                color,
                "agent {id}: end is filled"
            );
            assert_eq!(
                at(c, (ex, ey + 40)),
                FLOOR,
                "agent {id}: end marker is 0.3 m"
            );
        }

        // Scale bar: 1 m (2 m would be longer than 160 px) = 90 px of ink in the legend.
        let bar = map.scale_bar;
        assert_eq!(bar.metres, 1.0);
        assert!(bar.x0 >= map.legend_x);
        assert_eq!(bar.x1 - bar.x0, 90);
        for x in bar.x0..bar.x1 {
            assert_eq!(at(c, (x, bar.y + 1)), INK, "scale bar at x {x}");
        }
        assert_eq!(at(c, (bar.x0 - 1, bar.y + 1)), PAPER);
        assert_eq!(at(c, (bar.x1, bar.y + 1)), PAPER);
        let ink_in = |x0: i64, x1: i64, y0: i64, y1: i64| {
            (y0..y1).any(|y| (x0..x1).any(|x| at(c, (x, y)) == INK))
        };
        assert!(
            ink_in(bar.x0, bar.x1, bar.y - 6 - TEXT_H, bar.y - 6),
            "scale label"
        );

        // Labels: "G1" north-east of the goal region, "#7 G2" north-east of the box.
        let (gx, gy) = px(3.0 + 0.354, 3.0 + 0.354);
        assert!(
            ink_in(gx + 3, gx + 30, gy - TEXT_H - 3, gy - 3),
            "goal label"
        );
        let (bx, by) = px(-2.5, 3.5);
        assert!(
            ink_in(bx + 3, bx + 60, by - TEXT_H - 3, by - 3),
            "object label"
        );

        // Deterministic.
        assert_eq!(render_map(&world, &trails).canvas.px, c.px);
    }

    #[test]
    fn scale_bar_is_a_round_length_that_fits() {
        assert_eq!(scale_bar_metres(90.0), 1.0);
        assert_eq!(scale_bar_metres(120.0), 1.0);
        assert_eq!(scale_bar_metres(60.0), 2.0);
        assert_eq!(scale_bar_metres(30.0), 5.0);
        assert_eq!(scale_bar_metres(10.0), 10.0);
    }
}
