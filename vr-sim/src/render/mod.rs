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
        let mut jobs: Vec<(&Body, ImageMut<'a>)> = Vec::new();
        for (id, images) in agents {
            if let Some(body) = world.bodies().iter().find(|b| b.id == id) {
                jobs.extend(images.map(|image| (body, image)));
            }
        }
        self.render_images(world, jobs);
    }

    /// Renders images of bodies' cameras in place, like [`Renderer::render_agents`] (in
    /// parallel when they have at least [`MIN_POOL_PIXELS`] pixels together). Two
    /// neighbouring images of one body through cameras that differ only in their position
    /// (an agent's two eyes looking the same way) share their set-up ([`Group`]).
    pub fn render_images(&mut self, world: &World, jobs: Vec<(&Body, ImageMut<'_>)>) {
        let pixels: u64 = jobs
            .iter()
            .map(|(_, i)| u64::from(i.desc.width_px) * u64::from(i.desc.height_px))
            .sum();
        let parallel = jobs.len() > 1 && pixels >= u64::from(MIN_POOL_PIXELS);
        let groups = group_images(world, jobs);
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
/// origin (by less than [`MAX_GROUP_OFFSET_M`]) in pairs, the others alone.
fn group_images<'b, 'i>(world: &World, jobs: Vec<(&'b Body, ImageMut<'i>)>) -> Vec<Group<'b, 'i>> {
    let mut groups: Vec<Group<'b, 'i>> = Vec::with_capacity(jobs.len());
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

/// The side planes of a camera's view and its near plane: a cheap first test of whether
/// a primitive can show up in the image at all.
#[derive(Debug, Clone, Copy)]
struct Frustum {
    origin: Vec3,
    forward: Vec3,
    /// Unit normals, pointing out of the view, of the planes through the image's left,
    /// right, top and bottom edges (every pixel's ray is strictly inside).
    sides: [Vec3; 4],
}

impl Frustum {
    fn new(cam: &Camera) -> Self {
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
    fn misses_ball(&self, center: Vec3, radius: f32) -> bool {
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
const RECT_MARGIN_PX: f32 = 0.25;

/// A pixel rectangle `(x0, x1, y0, y1)`, inclusive.
type Rect = (u32, u32, u32, u32);

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
fn clipped_rect(cam: &Camera, min: Vec3, max: Vec3) -> Option<(Rect, f32)> {
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
fn rect_of(cam: &Camera, near: f32, (u0, u1, v0, v1): (f32, f32, f32, f32)) -> Option<(Rect, f32)> {
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
struct BoxLanes {
    min: [[f32; LANES]; 3],
    max: [[f32; LANES]; 3],
}

impl BoxLanes {
    fn set(&mut self, k: usize, min: Vec3, max: Vec3) {
        for axis in 0..3 {
            (self.min[axis][k], self.max[axis][k]) = (min[axis], max[axis]);
        }
    }
}

/// For each of the first `n` boxes of `boxes`, what [`clipped_rect`] gives for it (`None`
/// past `n`): the corners' projections and bounds of every box at once (the same
/// operations in the same order on every lane), [`clipped_rect`] itself for a box that
/// reaches behind half the near distance.
fn clipped_rects_lanes(cam: &Camera, boxes: &BoxLanes, n: usize) -> [Option<(Rect, f32)>; LANES] {
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

/// Images with fewer pixels are shaded on the calling thread.
const MIN_POOL_PIXELS: u32 = 4096;

/// Shades every row of one image into `data`.
fn draw(
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
type RowShader = fn(&View<'_>, u32, PixelFormat, &mut [u8]);

/// [`shade_row`] compiled for the widest vector instructions this CPU has: AVX2 (8 lanes
/// per instruction instead of SSE2's 4) where the CPU has it. The pixels are the same:
/// the lane loops do the same IEEE operations in the same order either way (Rust never
/// fuses a multiply and an add on its own).
fn row_shader() -> RowShader {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        return shade_row_avx2;
    }
    shade_row
}

/// [`shade_row`] with AVX2. Only [`row_shader`] hands it out, after checking the CPU.
#[cfg(target_arch = "x86_64")]
fn shade_row_avx2(view: &View<'_>, y: u32, format: PixelFormat, row: &mut [u8]) {
    #[target_feature(enable = "avx2")]
    fn with_avx2(view: &View<'_>, y: u32, format: PixelFormat, row: &mut [u8]) {
        shade_row_inline(view, y, format, row);
    }
    // SAFETY: `row_shader` returns this function only when the CPU has AVX2.
    unsafe { with_avx2(view, y, format, row) }
}

fn shade_row(view: &View<'_>, y: u32, format: PixelFormat, row: &mut [u8]) {
    shade_row_inline(view, y, format, row);
}

#[inline(always)]
fn shade_row_inline(view: &View<'_>, y: u32, format: PixelFormat, row: &mut [u8]) {
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

/// Pixels traced together (a packet): neighbours in a row, all in one tile, each
/// primitive tested for all of them at once in straight-line lane loops that the compiler
/// turns into SIMD instructions. Tiles are a multiple of this wide.
const LANES: usize = 8;

/// A packet's rays, one per lane (structure of arrays).
#[derive(Debug, Default)]
struct Rays {
    dx: [f32; LANES],
    dy: [f32; LANES],
    dz: [f32; LANES],
}

/// The rays of one image row: pixel `x`'s is `row_dir + (u0 + x · du) · right`
/// (computed this way, in this order, by every pixel).
#[derive(Debug, Clone, Copy)]
struct RowRays {
    row_dir: Vec3,
    u0: f32,
    du: f32,
}

impl RowRays {
    #[inline(always)]
    fn of(cam: &Camera, y: u32) -> Self {
        let du = 2.0 * cam.tan_half_h / cam.width_px as f32;
        Self {
            row_dir: cam.forward + cam.v_of(y as f32 + 0.5) * cam.up,
            u0: -cam.tan_half_h + 0.5 * du,
            du,
        }
    }

    /// Pixel `x`'s ray (the row shader computes the same, component by component, per lane).
    #[cfg(test)]
    fn dir(&self, right: Vec3, x: u32) -> Vec3 {
        self.row_dir + (self.u0 + x as i32 as f32 * self.du) * right
    }
}

/// Where every lane's ray leaves the room `min..max` (from `o` inside it), the same bits
/// as [`exit_box`](crate::geometry::exit_box) gives, and the [`RoomFace`] it sees there
/// (the floor's even squares for the whole floor: [`floor_face`] tells the square): the
/// same operations in the same order on every lane, the branches turned into selects.
#[inline(always)]
fn room_exit_lanes(o: Vec3, rays: &Rays, min: Vec3, max: Vec3) -> ([f32; LANES], [u32; LANES]) {
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
fn floor_face(o: Vec3, d: Vec3, t: f32) -> usize {
    let q = o + t * d;
    RoomFace::Floor as usize + ((floor_i32(q.x).wrapping_add(floor_i32(q.z)) & 1) as usize)
}

/// The shaded colours (at most 255) of the lanes whose nearest hit is a body.
#[derive(Debug, Default)]
struct BodyColors {
    /// Whether the lane's nearest hit is a body (else its colour is meaningless).
    hit: [bool; LANES],
    /// Red, green and blue, by lane.
    rgb: [[f32; LANES]; 3],
}

/// [`shade`] of [`normal_at`] for every lane whose nearest hit (`nearest`, an index into
/// `prims`, at depth `t`) is a body, at once: the same operations in the same order on
/// every lane (so the same bits), the branches turned into selects.
#[inline(always)]
fn body_colors_lanes(
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
fn hit_cylinder_lanes(o: Vec3, rays: &Rays, base: Vec3, radius: f32, height: f32) -> [f32; LANES] {
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
fn shade_row_as<const COLOR: bool>(
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

pub mod affinity;
#[cfg(test)]
mod crowd_tests;
#[cfg(test)]
mod rect_tests;
#[cfg(test)]
mod reference;
#[cfg(test)]
mod tests;
