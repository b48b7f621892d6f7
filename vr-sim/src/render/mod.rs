//! The CPU renderer: ray casting of the room (walls, checkered floor, ceiling), its boxes
//! and spheres and the other agents' bodies, flat-shaded, written **straight into the
//! loaned sensor sample**: every pixel is computed and stored in its place in shared
//! memory, with no intermediate image and no copy.
//!
//! Each camera ray is `forward + u·right + v·up`, so the ray parameter of a hit is its depth
//! along the optical axis (what `depth32f` images hold, in metres; the far wall is always
//! hit because the room is closed). Objects and bodies are culled per image by the screen
//! rectangle of their bounding box and sorted by the nearest depth of that box; each tile
//! of the image (8 × 8 pixels or more) lists, in that order, the ones whose rectangle
//! overlaps it. A pixel tests only its tile's list, the ones whose rectangle covers it,
//! and stops at the first that is farther than its nearest hit so far: with many agents
//! in view, a ray costs about what it costs with one. The result is exactly what testing
//! every rectangle covering the pixel in collection order gives (the nearest hit; on equal
//! depth, the first object in the world's order, objects before bodies).
//!
//! An agent's two eyes, when they look the same way with the same image size and field of
//! view, share that set-up: the list is made once, for boxes stretched by the distance
//! between the eyes, and both images are traced from it (see `Group`).
//!
//! With a rayon pool of more than one thread, the images of a batch of agents
//! ([`Renderer::render_agents`]) are shaded in parallel, one image (or eye pair) per task,
//! when they have at least [`MIN_POOL_PIXELS`] pixels together; within an image, rows are
//! shaded in parallel when it has that many alone. Smaller work costs less than waking the pool
//! (with many agent processes on few cores, far less), so it stays on the calling thread.
//! Every pixel is a pure function of the world, so the images do not depend on the number
//! of threads or on how the images are batched. With a pool thread for every CPU, each is
//! bound to its own CPU (see [`affinity`]).

use std::sync::{Mutex, PoisonError};

use glam::Vec3;
use rayon::prelude::*;
use vrsync_bridge::{ImageDesc, PixelFormat};
use vrsync_bridge::{ImageMut, ImagesMut};

pub use affinity::Affinity;

use crate::geometry::{Camera, NEAR_M, enter_box, hit_cylinder, hit_sphere, recip};
use crate::world::{Body, CameraSpec, World};
use crate::world_config::Shape;

use lanes::*;
use rects::*;
use shade::*;

/// Colours of the agents' bodies, by agent id (modulo the length). None is red, so that
/// only the red object looks red.
pub const AGENT_COLORS: [[u8; 3]; 6] = [
    [235, 200, 40],
    [40, 185, 225],
    [160, 95, 210],
    [60, 175, 95],
    [240, 140, 200],
    [120, 120, 230],
];

/// Unit vector towards the light (from above, a little from the south-west).
const LIGHT: Vec3 = Vec3::new(0.298, 0.795, -0.497);

/// Why the renderer could not be created.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RendererCreateError {
    /// The thread pool could not be built.
    #[error("cannot start {threads} render threads: {error}")]
    Pool {
        /// Threads asked for.
        threads: usize,
        /// The pool error (in the message, so not also a `source()`).
        error: rayon::ThreadPoolBuildError,
    },
}

#[derive(Debug, Clone, Copy)]
enum PrimKind {
    Sphere {
        center: Vec3,
        radius: f32,
    },
    Box {
        min: Vec3,
        max: Vec3,
    },
    Body {
        base: Vec3,
        radius: f32,
        height: f32,
    },
}

/// An object or body that may show up in the image, with its screen rectangle.
#[derive(Debug, Clone, Copy)]
struct Prim {
    kind: PrimKind,
    color: Vec3,
    x0: u32,
    x1: u32,
    y0: u32,
    y1: u32,
    /// No hit on it is nearer than this (ray parameter = depth along the optical axis).
    near: f32,
    /// Its place in collection order (objects, then bodies, in the world's order; its
    /// index in the image's list): on equal depth the lower one is seen.
    index: u32,
}

/// Per-tile lists of primitives: tile `i` (row-major, [`Tiles::width`] ×
/// [`Tiles::height`] pixels) holds `items[start[i]..start[i + 1]]`, sorted by nearest
/// depth (then collection order).
#[derive(Debug, Default, Clone)]
struct Tiles {
    /// A multiple of [`LANES`], so that a packet never straddles two tiles.
    width: u32,
    height: u32,
    cols: u32,
    start: Vec<u32>,
    items: Vec<Entry>,
    /// Scratch: the primitives' nearest depths and indices, sorted.
    order: Vec<(f32, u32)>,
}

/// A primitive in a tile's list: what a pixel checks before it loads the primitive.
#[derive(Debug, Clone, Copy, Default)]
struct Entry {
    /// [`Prim::near`].
    near: f32,
    /// The primitive's index in the image's list (collection order).
    index: u32,
    x0: u16,
    x1: u16,
    y0: u16,
    y1: u16,
}

impl Entry {
    fn of(p: &Prim) -> Self {
        // Rectangles are clamped to the image, whose sides are at most 8192 pixels.
        Self {
            near: p.near,
            index: p.index,
            x0: p.x0 as u16,
            x1: p.x1 as u16,
            y0: p.y0 as u16,
            y1: p.y1 as u16,
        }
    }
}

/// Tiles are 8 pixels square, or larger so that an image has at most this many.
const MAX_TILES: u32 = 1024;

/// Everything shading one image needs; shared read-only by the row tasks.
#[derive(Debug)]
struct View<'a> {
    cam: Camera,
    room_min: Vec3,
    room_max: Vec3,
    /// The shaded colour (at most 255) of every [`RoomFace`], by its index.
    room_colors: [Vec3; ROOM_FACES],
    prims: &'a [Prim],
    tiles: &'a Tiles,
}

/// What a ray that hits nothing in the room sees where it leaves the room: the floor's
/// two colours (by checker parity), the ceiling and the four walls. [`room_exit_lanes`]
/// gives the index; [`View::room_colors`] the colour.
#[derive(Debug, Clone, Copy)]
#[repr(u32)]
enum RoomFace {
    /// The floor squares of even parity; odd ones are `Floor + 1`.
    Floor = 0,
    Ceiling = 2,
    /// The wall at the room's largest x (seen facing +x).
    MaxX = 3,
    MinX = 4,
    MaxZ = 5,
    MinZ = 6,
}

/// How many colours the room shows ([`RoomFace`]).
const ROOM_FACES: usize = 7;

/// The renderer: a thread pool (or none) and scratch space reused every cycle.
#[derive(Debug)]
pub struct Renderer {
    pool: Option<rayon::ThreadPool>,
    /// The calling thread's scratch.
    scratch: Scratch,
    /// Each pool thread's scratch, by [`rayon::current_thread_index`] (a lock is only
    /// ever taken by its own thread, so it never waits).
    workers: Vec<Mutex<Scratch>>,
    /// The row shader for this CPU ([`row_shader`]).
    shader: RowShader,
    /// Whether the pool has a thread for every CPU the process may use.
    every_cpu: bool,
}

/// What one image's set-up fills in, kept between images so that it does not allocate.
#[derive(Debug, Default)]
struct Scratch {
    prims: Vec<Prim>,
    tiles: Tiles,
}

fn rgb(c: [u8; 3]) -> Vec3 {
    Vec3::new(f32::from(c[0]), f32::from(c[1]), f32::from(c[2]))
}

fn shade(color: Vec3, normal: Vec3) -> Vec3 {
    color * (0.7 + 0.3 * normal.dot(LIGHT))
}

impl Renderer {
    /// A renderer using `threads` threads for rows (1: render on the calling thread;
    /// 0: one per core), each bound to its own CPU when they are one per CPU
    /// ([`Affinity::Auto`]).
    ///
    /// # Errors
    /// [`RendererCreateError`] if the pool cannot be started.
    pub fn new(threads: usize) -> Result<Self, RendererCreateError> {
        Self::with_affinity(threads, Affinity::Auto)
    }

    /// A renderer like [`Renderer::new`], its pool's threads bound to CPUs as `affinity`
    /// says. A thread that cannot be bound (the CPU was taken from the process meanwhile)
    /// runs unbound, with a warning.
    ///
    /// # Errors
    /// [`RendererCreateError`] if the pool cannot be started.
    pub fn with_affinity(threads: usize, affinity: Affinity) -> Result<Self, RendererCreateError> {
        // The CPUs this process may use (its affinity mask, its cgroup's quota).
        let cpus = std::thread::available_parallelism().map_or(1, usize::from);
        let threads = match threads {
            0 => cpus,
            n => n,
        };
        let pool = if threads == 1 {
            None
        } else {
            let cpus = affinity.cpus_for(threads);
            Some(
                rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .thread_name(|i| format!("vr-sim-render-{i}"))
                    .start_handler(move |i| {
                        if let Some(cpus) = &cpus {
                            let cpu = cpus[i % cpus.len()];
                            if let Err(error) = affinity::bind_current_thread(cpu) {
                                tracing::warn!(thread = i, cpu, %error, "render thread left unbound");
                            }
                        }
                    })
                    .build()
                    .map_err(|error| RendererCreateError::Pool { threads, error })?,
            )
        };
        let workers = pool
            .as_ref()
            .map_or(0, rayon::ThreadPool::current_num_threads);
        Ok(Self {
            pool,
            scratch: Scratch::default(),
            workers: (0..workers).map(|_| Mutex::default()).collect(),
            shader: row_shader(),
            every_cpu: workers >= cpus,
        })
    }

    /// Threads shading rows.
    pub fn threads(&self) -> usize {
        self.pool
            .as_ref()
            .map_or(1, rayon::ThreadPool::current_num_threads)
    }

    /// How many agents' frames to render in one [`Renderer::render_agents`] call
    /// (`usize::MAX`: all of them). With threads left over for the agents (fewer render
    /// threads than CPUs), enough images to keep every render thread busy at once, few
    /// enough that the first frames are published (and their agents start) while the
    /// rest are rendered. With a render thread on every CPU, all at once: an agent
    /// started early would only take a CPU from the render threads (measured at 64
    /// agents on 2 CPUs: in batches of 16, a cycle took 4% longer, the rendering 14%).
    pub fn agents_per_batch(&self) -> usize {
        match self.threads() {
            1 => 1,
            _ if self.every_cpu => usize::MAX,
            n => 8 * n,
        }
    }

    /// Shades with the baseline instruction set even where the CPU has more (to test
    /// that both give the same bytes).
    #[cfg(test)]
    pub(crate) fn use_baseline_isa(&mut self) {
        self.shader = shade_row;
    }

    /// Renders every image of agent `id`'s loaned frame in place.
    pub fn render_agent(&mut self, world: &World, id: u32, images: ImagesMut<'_>) {
        self.render_agents(world, [(id, images)]);
    }

    /// Renders every image of several agents' loaned frames in place: one task per image
    /// (or eye pair) on the pool when the images have at least [`MIN_POOL_PIXELS`] pixels
    /// together, else one after the other on the calling thread (the pixels are the same
    /// either way). An id that is not in the world is skipped.
    pub fn render_agents<'a>(
        &mut self,
        world: &World,
        agents: impl IntoIterator<Item = (u32, ImagesMut<'a>)>,
    ) {
        let agents = agents.into_iter();
        // One list per call, sized for one image per agent (the common case), built
        // straight from the frames: a cycle's only allocation here.
        let capacity = agents.size_hint().0;
        let jobs = agents.flat_map(|(id, images)| {
            let body = world.bodies().iter().find(|b| b.id == id);
            images.filter_map(move |image| body.map(|body| (body, image)))
        });
        self.render_groups(world, group_images(world, jobs, capacity));
    }

    /// Renders images of bodies' cameras in place, like [`Renderer::render_agents`] (in
    /// parallel when they have at least [`MIN_POOL_PIXELS`] pixels together). Two
    /// neighbouring images of one body through cameras that differ only in their position
    /// (an agent's two eyes looking the same way) share their set-up ([`Group`]).
    #[cfg(test)]
    pub(crate) fn render_images(&mut self, world: &World, jobs: Vec<(&Body, ImageMut<'_>)>) {
        let capacity = jobs.len();
        self.render_groups(world, group_images(world, jobs, capacity));
    }

    /// Renders `groups`, in parallel when they have more than one image and at least
    /// [`MIN_POOL_PIXELS`] pixels together.
    fn render_groups(&mut self, world: &World, groups: Vec<Group<'_, '_>>) {
        let images = |g: &Group<'_, '_>| 1 + usize::from(g.second.is_some());
        let pixels_of = |(_, i): &(Camera, ImageMut<'_>)| {
            u64::from(i.desc.width_px) * u64::from(i.desc.height_px)
        };
        let pixels: u64 = groups
            .iter()
            .map(|g| pixels_of(&g.first) + g.second.as_ref().map_or(0, pixels_of))
            .sum();
        let count: usize = groups.iter().map(images).sum();
        let parallel = count > 1 && pixels >= u64::from(MIN_POOL_PIXELS);
        match &self.pool {
            Some(pool) if parallel => {
                let (workers, shader) = (&self.workers, self.shader);
                pool.install(|| {
                    groups.into_par_iter().for_each(|group| {
                        // Always a pool thread here; the index is in range.
                        let i = rayon::current_thread_index().unwrap_or(0) % workers.len();
                        let mut scratch = workers[i].lock().unwrap_or_else(PoisonError::into_inner);
                        scratch.render_group(world, group, Some(pool), shader);
                    });
                });
            }
            pool => {
                for group in groups {
                    self.scratch
                        .render_group(world, group, pool.as_ref(), self.shader);
                }
            }
        }
    }

    /// Renders one image of `body`'s cameras in place (the camera is chosen by the image's
    /// camera index; its name selects the viewpoint: `left`, `right`, else the head).
    pub fn render_image(&mut self, world: &World, body: &Body, image: ImageMut<'_>) {
        let group = Group {
            body,
            first: (camera_of(world, body, &image.desc), image),
            second: None,
        };
        self.scratch
            .render_group(world, group, self.pool.as_ref(), self.shader);
    }
}

/// One image, or two of one body whose cameras differ only in their origin, rendered
/// with one set-up: the primitives are collected and listed for the first camera with
/// their boxes stretched by the offset between the two origins, so that each rectangle
/// and nearest depth also bounds what the second camera sees (the second camera sees a
/// box where the first sees it moved back by the offset). Each image is still traced
/// from its own origin, so its pixels are what rendering it alone gives.
struct Group<'b, 'i> {
    body: &'b Body,
    first: (Camera, ImageMut<'i>),
    second: Option<(Camera, ImageMut<'i>)>,
}

/// Two cameras farther apart than this are not grouped (their rectangles would grow).
const MAX_GROUP_OFFSET_M: f32 = 0.5;

/// `jobs` as [`Group`]s: neighbours of one body with cameras that differ only in their
/// origin (by less than [`MAX_GROUP_OFFSET_M`]) in pairs, the others alone; the list is
/// allocated for `capacity` groups.
fn group_images<'b, 'i>(
    world: &World,
    jobs: impl IntoIterator<Item = (&'b Body, ImageMut<'i>)>,
    capacity: usize,
) -> Vec<Group<'b, 'i>> {
    let mut groups: Vec<Group<'b, 'i>> = Vec::with_capacity(capacity);
    for (body, image) in jobs {
        let cam = camera_of(world, body, &image.desc);
        if let Some(last) = groups.last_mut()
            && last.second.is_none()
            && std::ptr::eq(last.body, body)
            && same_view_but_origin(&last.first.0, &cam)
            && (cam.origin - last.first.0.origin).length() < MAX_GROUP_OFFSET_M
        {
            last.second = Some((cam, image));
            continue;
        }
        groups.push(Group {
            body,
            first: (cam, image),
            second: None,
        });
    }
    groups
}

/// Whether two cameras look the same way with the same image (all but the origin equal).
fn same_view_but_origin(a: &Camera, b: &Camera) -> bool {
    Camera {
        origin: b.origin,
        ..*a
    } == *b
}

impl Scratch {
    /// Renders a [`Group`]'s images (see [`Renderer::render_image`]), each one's rows on
    /// `pool` if it is large enough.
    fn render_group(
        &mut self,
        world: &World,
        group: Group<'_, '_>,
        pool: Option<&rayon::ThreadPool>,
        shader: RowShader,
    ) {
        let Group {
            body,
            first: (cam, image),
            second,
        } = group;
        if cam.width_px == 0 || cam.height_px == 0 {
            return;
        }
        let offset = second
            .as_ref()
            .map_or(Vec3::ZERO, |(c, _)| c.origin - cam.origin);
        self.collect_prims(world, body, &cam, offset);
        self.bin_prims(&cam);
        for (cam, image) in std::iter::once((cam, image)).chain(second) {
            let view = view_of(world, cam, &self.prims, &self.tiles);
            let format = image.desc.pixel_format().unwrap_or_default();
            draw(&view, &image.desc, format, image.data, pool, shader);
        }
    }

    /// The objects and bodies (not `me`'s) whose [`clipped_rect`] overlaps the image, in
    /// collection order: seen through `cam`, and through `cam` moved by `offset` (each
    /// box is stretched to also hold itself moved back by `offset`, each bounding ball
    /// grown by its length; with a zero offset both are unchanged).
    fn collect_prims(&mut self, world: &World, me: &Body, cam: &Camera, offset: Vec3) {
        self.prims.clear();
        let prims = &mut self.prims;
        let frustum = Frustum::new(cam);
        // `ball` (centre, radius) holds the primitive: when no pixel's ray can reach it,
        // the primitive is left out (it would never be hit, so leaving it out changes no
        // pixel, nor the order of the others), an object before its rectangle is computed.
        let grow = offset.length();
        let stretch = |min: Vec3, max: Vec3| (min.min(min - offset), max.max(max - offset));
        let mut push = |kind: PrimKind, color: [u8; 3], rect: Option<(Rect, f32)>| {
            if let Some(((x0, x1, y0, y1), near)) = rect {
                let index = prims.len() as u32;
                prims.push(Prim {
                    kind,
                    color: rgb(color),
                    x0,
                    x1,
                    y0,
                    y1,
                    near,
                    index,
                });
            }
        };
        for o in world.objects() {
            let (min, max) = o.bounds();
            let (kind, ball) = match o.shape {
                Shape::Sphere { radius } => (
                    PrimKind::Sphere {
                        center: o.position,
                        radius,
                    },
                    (o.position, radius),
                ),
                Shape::Box { .. } => (
                    PrimKind::Box { min, max },
                    (0.5 * (min + max), 0.5 * (max - min).length()),
                ),
            };
            if !frustum.misses_ball(ball.0, ball.1 + grow) {
                let (min, max) = stretch(min, max);
                push(kind, o.color, clipped_rect(cam, min, max));
            }
        }
        // The bodies, [`LANES`] at a time: their rectangles at once
        // ([`clipped_rects_lanes`]), kept for those whose ball is in view.
        let cfg = world.config();
        let (r, h) = (cfg.agent_radius, cfg.body_height);
        let body_ball = Vec3::new(0.0, 0.5 * h, 0.0);
        let body_ball_radius = (r * r + 0.25 * h * h).sqrt();
        let mut boxes = BoxLanes::default();
        let mut lanes: [Option<&Body>; LANES] = [None; LANES];
        for chunk in world.bodies().chunks(LANES) {
            let mut n = 0;
            for b in chunk.iter().filter(|b| b.id != me.id) {
                let (min, max) = stretch(
                    b.position - Vec3::new(r, 0.0, r),
                    b.position + Vec3::new(r, h, r),
                );
                boxes.set(n, min, max);
                lanes[n] = Some(b);
                n += 1;
            }
            let rects = clipped_rects_lanes(cam, &boxes, n);
            for (b, rect) in lanes[..n].iter().flatten().zip(rects) {
                if frustum.misses_ball(b.position + body_ball, body_ball_radius + grow) {
                    continue;
                }
                let kind = PrimKind::Body {
                    base: b.position,
                    radius: r,
                    height: h,
                };
                push(kind, AGENT_COLORS[b.id as usize % AGENT_COLORS.len()], rect);
            }
        }
    }

    /// Lists the primitives per tile, each list by nearest depth (then collection order).
    fn bin_prims(&mut self, cam: &Camera) {
        let prims = &self.prims;
        let t = &mut self.tiles;
        t.order.clear();
        t.order.extend(prims.iter().map(|p| (p.near, p.index)));
        t.order
            .sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        (t.width, t.height) = (8, 8);
        const _: () = assert!(8 % LANES == 0, "a packet must not straddle two tiles");
        while cam.width_px.div_ceil(t.width) * cam.height_px.div_ceil(t.height) > MAX_TILES {
            t.width *= 2;
            t.height *= 2;
        }
        t.cols = cam.width_px.div_ceil(t.width);
        let n = (t.cols * cam.height_px.div_ceil(t.height)) as usize;
        t.start.clear();
        t.start.resize(n + 1, 0);
        let (w, h) = (t.width, t.height);
        let tile_range = |p: &Prim| (p.x0 / w..=p.x1 / w, p.y0 / h..=p.y1 / h);
        // Count per tile (shifted by one), prefix-sum into starts, then fill.
        for p in prims {
            let (xs, ys) = tile_range(p);
            for ty in ys {
                for tx in xs.clone() {
                    t.start[(ty * t.cols + tx) as usize + 1] += 1;
                }
            }
        }
        for i in 0..n {
            t.start[i + 1] += t.start[i];
        }
        t.items.clear();
        t.items.resize(t.start[n] as usize, Entry::default());
        // `start[i]` is the fill cursor of tile i; afterwards it is tile i + 1's start,
        // so shift back.
        for &(_, k) in &t.order {
            let p = &prims[k as usize];
            let entry = Entry::of(p);
            let (xs, ys) = tile_range(p);
            for ty in ys {
                for tx in xs.clone() {
                    let i = (ty * t.cols + tx) as usize;
                    t.items[t.start[i] as usize] = entry;
                    t.start[i] += 1;
                }
            }
        }
        for i in (1..=n).rev() {
            t.start[i] = t.start[i - 1];
        }
        t.start[0] = 0;
    }
}

/// The camera of `body` that renders `desc` (by the image's camera index; its name selects
/// the viewpoint: `left`, `right`, else the head).
fn camera_of(world: &World, body: &Body, desc: &ImageDesc) -> Camera {
    match body.cameras().get(desc.camera as usize) {
        Some(s) if s.width_px == desc.width_px && s.height_px == desc.height_px => {
            world.camera(body, s)
        }
        // A frame whose table does not match the config: render the described size.
        _ => world.camera(
            body,
            &CameraSpec {
                name: desc.name().to_string(),
                width_px: desc.width_px,
                height_px: desc.height_px,
                fov_h_deg: 120.0,
                fov_v_deg: 90.0,
            },
        ),
    }
}

/// What shading an image of `world` through `cam` needs.
fn view_of<'a>(world: &World, cam: Camera, prims: &'a [Prim], tiles: &'a Tiles) -> View<'a> {
    let cfg = world.config();
    let (room_min, room_max) = world.room_bounds();
    let (floor, walls, ceiling) = (
        cfg.floor_colors.map(rgb),
        cfg.wall_colors.map(rgb),
        rgb(cfg.ceiling_color),
    );
    let room_colors = [
        shade(floor[0], Vec3::Y),
        shade(floor[1], Vec3::Y),
        ceiling,
        shade(walls[1], Vec3::NEG_X),
        shade(walls[3], Vec3::X),
        shade(walls[0], Vec3::NEG_Z),
        shade(walls[2], Vec3::Z),
    ]
    .map(|c| c.min(Vec3::splat(255.0)));
    View {
        cam,
        room_min,
        room_max,
        room_colors,
        prims,
        tiles,
    }
}

/// `x.floor()` without a libm call (baseline x86_64 has no rounding instruction), for
/// `|x| < 2^31`; beyond, a value of at least 2^31 in magnitude (still outside the image);
/// NaN stays NaN.
#[inline(always)]
fn floor_f32(x: f32) -> f32 {
    if x.is_nan() { x } else { floor_i32(x) as f32 }
}

/// `x.floor() as i32` without a libm call (saturating beyond `i32`'s range, 0 for NaN;
/// never panics).
#[inline(always)]
fn floor_i32(x: f32) -> i32 {
    let i = x as i32;
    if (i as f32) > x { i.wrapping_sub(1) } else { i }
}

/// Where a ray hits a primitive (`t` at unit depth), if in front of the near plane.
#[inline(always)]
fn hit_prim(p: &Prim, o: Vec3, d: Vec3, inv: Vec3) -> Option<f32> {
    match p.kind {
        PrimKind::Sphere { center, radius } => hit_sphere(o, d, center, radius, NEAR_M),
        PrimKind::Box { min, max } => enter_box(o, inv, min, max, NEAR_M).map(|h| h.0),
        PrimKind::Body {
            base,
            radius,
            height,
        } => hit_cylinder(o, d, base, radius, height, NEAR_M).map(|h| h.0),
    }
}

/// The surface normal of the nearest hit, at `t` (computed once per pixel, for the
/// winner only).
fn normal_at(p: &Prim, o: Vec3, d: Vec3, inv: Vec3, t: f32) -> Vec3 {
    let q = o + t * d;
    match p.kind {
        PrimKind::Sphere { center, radius } => (q - center) / radius,
        PrimKind::Box { min, max } => match enter_box(o, inv, min, max, NEAR_M) {
            Some((_, axis, positive)) => {
                let mut n = Vec3::ZERO;
                n[axis] = if positive { 1.0 } else { -1.0 };
                n
            }
            None => Vec3::Y,
        },
        PrimKind::Body {
            base,
            radius,
            height,
        } => {
            if q.y >= base.y + height - 1e-4 {
                Vec3::Y
            } else {
                Vec3::new(q.x - base.x, 0.0, q.z - base.z) / radius
            }
        }
    }
}

pub mod affinity;
#[cfg(test)]
mod crowd_tests;
mod lanes;
#[cfg(test)]
mod rect_tests;
mod rects;
#[cfg(test)]
mod reference;
mod shade;
#[cfg(test)]
mod tests;
