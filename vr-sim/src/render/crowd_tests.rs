//! A crowded scene: 64 agents on their rings in a 10 × 10 room with objects, some of them
//! overlapping (coplanar faces: hits at equal depth), rendered from every agent's four
//! cameras (rgb8, depth32f, gray8, rgba8; several sizes and fields of view). The frames'
//! hash is pinned: any change of the renderer that changes a single byte of a single
//! image fails [`crowd_frames_hash_is_unchanged`].

use std::path::Path;

use glam::Vec3;
use vrsync_bridge::{CAMERA_NAME_LEN, Command, Config, ImageDesc, ImageMut, PixelFormat};

use super::{Entry, Prim, Renderer, RowRays, Tiles, hit_prim};
use crate::geometry::Camera;
use crate::world::World;

/// A camera: name, format, width, height, fov h × v.
type Cam = (&'static str, PixelFormat, u32, u32, f32, f32);

/// The eyes of the speed measurements' crowds: two 32×24 rgb8 cameras, 120° × 90°.
const CROWD_EYES: [Cam; 2] = [
    ("left", PixelFormat::Rgb8, 32, 24, 120.0, 90.0),
    ("right", PixelFormat::Rgb8, 32, 24, 120.0, 90.0),
];

/// Agent 0's cameras (every agent copies them).
const CAMERAS: [Cam; 4] = [
    ("left", PixelFormat::Rgb8, 32, 24, 120.0, 90.0),
    ("right", PixelFormat::Depth32f, 40, 30, 120.0, 90.0),
    ("main", PixelFormat::Gray8, 64, 48, 90.0, 60.0),
    ("wide", PixelFormat::Rgba8, 96, 72, 150.0, 100.0),
];

fn format_name(f: PixelFormat) -> &'static str {
    match f {
        PixelFormat::Rgb8 => "rgb8",
        PixelFormat::Rgba8 => "rgba8",
        PixelFormat::Gray8 => "gray8",
        PixelFormat::Depth32f => "depth32f",
    }
}

/// `agents` agents with [`CAMERAS`] in the default-sized room with seven objects: the
/// default world's five, a box exactly on top of the blue box (same faces: every hit on
/// them is a tie) and a box whose faces partly coincide with the brown one's.
pub(super) fn crowd_world(agents: u32) -> World {
    crowd_world_with(agents, &CAMERAS)
}

/// [`crowd_world`] with other cameras.
fn crowd_world_with(agents: u32, cameras: &[Cam]) -> World {
    let mut text = String::from("[[agent]]\nid = 0\n");
    for &(name, format, w, h, fh, fv) in cameras {
        text += &format!(
            "[[agent.camera]]\nname = \"{name}\"\nwidth = {w}\nheight = {h}\nformat = \"{}\"\n\
             fov_horizontal_deg = {fh:.1}\nfov_vertical_deg = {fv:.1}\n",
            format_name(format)
        );
    }
    text += "[world]\nroom_width = 10.0\nroom_depth = 10.0\n";
    for (id, shape, position, extent, color) in [
        (1, "sphere", [2.5, 0.4, 3.0], "radius = 0.4", [220, 30, 30]),
        (
            2,
            "box",
            [-2.5, 0.5, 2.5],
            "size = [1.0, 1.0, 1.0]",
            [40, 90, 220],
        ),
        (
            3,
            "box",
            [3.0, 0.75, -2.0],
            "size = [0.8, 1.5, 0.8]",
            [40, 170, 70],
        ),
        (
            4,
            "sphere",
            [-3.0, 0.3, -2.5],
            "radius = 0.3",
            [245, 245, 245],
        ),
        (
            5,
            "box",
            [0.0, 0.4, -4.0],
            "size = [2.0, 0.8, 0.8]",
            [140, 95, 55],
        ),
        (
            6,
            "box",
            [-2.5, 0.5, 2.5],
            "size = [1.0, 1.0, 1.0]",
            [250, 120, 0],
        ),
        (
            7,
            "box",
            [1.0, 0.6, -4.0],
            "size = [1.0, 1.2, 0.8]",
            [90, 90, 90],
        ),
    ] {
        text += &format!(
            "[[world.object]]\nid = {id}\nshape = \"{shape}\"\nposition = [{:.2}, {:.2}, {:.2}]\n\
             {extent}\ncolor = [{}, {}, {}]\n",
            position[0], position[1], position[2], color[0], color[1], color[2]
        );
    }
    let config = Config::from_toml_str(&text, Path::new("crowd.toml"))
        .unwrap()
        .with_agent_count(agents)
        .unwrap();
    World::from_config(&config).unwrap()
}

/// [`crowd_world`] after a few cycles in which some agents turned, tilted their eyes or
/// walked towards the centre (bodies close to other cameras, partly behind their near
/// planes).
pub(super) fn crowd_world_moved(agents: u32) -> World {
    crowd_world_moved_with(agents, &CAMERAS)
}

/// [`crowd_world_moved`] with other cameras.
fn crowd_world_moved_with(agents: u32, cameras: &[Cam]) -> World {
    let mut w = crowd_world_with(agents, cameras);
    for id in 0..agents {
        let command = match id % 4 {
            0 => Command::Turn {
                angle_deg: 17.0 * id as f32,
            },
            1 => Command::EyeMovement {
                pan_left_deg: -25.0,
                pan_right_deg: 10.0,
                tilt_deg: if id % 8 == 1 { -35.0 } else { 20.0 },
            },
            2 => Command::MoveTo {
                target: Vec3::new(0.2, 0.0, 0.1),
            },
            _ => continue,
        };
        w.apply(id, 1, command).unwrap();
    }
    for _ in 0..12 {
        w.step();
    }
    w
}

pub(super) fn desc(
    camera: u32,
    name: &str,
    format: PixelFormat,
    width: u32,
    height: u32,
) -> ImageDesc {
    let mut n = [0u8; CAMERA_NAME_LEN];
    n[..name.len()].copy_from_slice(name.as_bytes());
    let stride = width * format.bytes_per_pixel() as u32;
    ImageDesc {
        name: n,
        camera,
        format: format as u32,
        width_px: width,
        height_px: height,
        stride_bytes: stride,
        reserved: 0,
        offset: 0,
        len: u64::from(stride * height),
    }
}

/// Every agent's images of [`CAMERAS`], agent by agent, camera by camera, rendered by
/// `render`.
pub(super) fn crowd_frames(
    w: &World,
    render: impl FnMut(&World, u32, ImageMut<'_>),
) -> Vec<Vec<u8>> {
    frames_of(w, &CAMERAS, render)
}

/// Every agent's images of `cameras` (the world's), rendered by `render`.
fn frames_of(
    w: &World,
    cameras: &[Cam],
    mut render: impl FnMut(&World, u32, ImageMut<'_>),
) -> Vec<Vec<u8>> {
    let mut frames = Vec::new();
    for body in w.bodies() {
        for (camera, &(name, format, width, height, _, _)) in cameras.iter().enumerate() {
            let d = desc(camera as u32, name, format, width, height);
            let mut buf = vec![0xAB; d.len as usize];
            render(
                w,
                body.id,
                ImageMut {
                    desc: d,
                    data: &mut buf,
                },
            );
            frames.push(buf);
        }
    }
    frames
}

/// Every agent's images of [`CAMERAS`], rendered in one [`Renderer::render_images`] batch
/// (in parallel when the renderer has a pool).
fn crowd_frames_batched(w: &World, r: &mut Renderer) -> Vec<Vec<u8>> {
    frames_batched(w, &CAMERAS, r)
}

/// Every agent's images of `cameras` (the world's), rendered in one
/// [`Renderer::render_images`] batch.
fn frames_batched(w: &World, cameras: &[Cam], r: &mut Renderer) -> Vec<Vec<u8>> {
    let descs: Vec<_> =
        w.bodies()
            .iter()
            .flat_map(|body| {
                cameras.iter().enumerate().map(
                    move |(camera, &(name, format, width, height, _, _))| {
                        (body, desc(camera as u32, name, format, width, height))
                    },
                )
            })
            .collect();
    let mut frames: Vec<Vec<u8>> = descs
        .iter()
        .map(|(_, d)| vec![0xAB; d.len as usize])
        .collect();
    let jobs = descs
        .iter()
        .zip(&mut frames)
        .map(|(&(body, desc), buf)| (body, ImageMut { desc, data: buf }))
        .collect();
    r.render_images(w, jobs);
    frames
}

fn hash(frames: &[Vec<u8>]) -> String {
    let mut h = blake3::Hasher::new();
    for f in frames {
        h.update(f);
    }
    h.finalize().to_hex().to_string()
}

/// The hash of every image of [`crowd_world`] (64 agents) and [`crowd_world_moved`] (64
/// and 5 agents), rendered by the renderer of commit "render: a pinned hash of a crowded
/// scene" (the brute-force loop of [`super::reference`]), on 1 and on 2 threads, image by
/// image and in one batch (on 2 threads: images in parallel), with the row shader for
/// this CPU (AVX2 where it has it) and with the baseline one.
///
/// A bit-exact check: it assumes IEEE f32 arithmetic without fused multiply-adds and the
/// platform's `sin`/`cos`/`tan` of x86_64 Linux (glibc), as CI has. If it fails elsewhere
/// and only there, [`fast_renderer_equals_the_brute_force_loop`] (the same comparison on
/// the machine itself) is the check that counts.
#[test]
fn crowd_frames_hash_is_unchanged() {
    let worlds = [crowd_world(64), crowd_world_moved(64), crowd_world_moved(5)];
    for (threads, baseline) in [(1, false), (2, false), (1, true), (2, true)] {
        let mut r = Renderer::new(threads).unwrap();
        if baseline {
            r.use_baseline_isa();
        }
        let (mut all, mut batched) = (Vec::new(), Vec::new());
        for w in &worlds {
            all.extend(crowd_frames(w, |w, id, image| {
                let body = w.bodies().iter().find(|b| b.id == id).unwrap();
                r.render_image(w, body, image);
            }));
            batched.extend(crowd_frames_batched(w, &mut r));
        }
        assert_eq!(all.len(), (64 + 64 + 5) * CAMERAS.len());
        for (how, frames) in [("one by one", &all), ("in one batch", &batched)] {
            assert_eq!(
                hash(frames),
                "35e8de9aabc1e72acc5a6e362cf7022d6f6d72f5f69f63b0443ef75c7c9aac23",
                "{threads} thread(s), {how}, baseline instructions only: {baseline}: the \
                 crowd's frames changed"
            );
        }
    }
}

/// An agent's two eyes looking the same way are rendered with one set-up (the primitives
/// listed once, for both): every byte is still what the brute-force loop gives, for the
/// crowd as it starts (every agent's eyes pair up) and after moving (some agents turned
/// their eyes apart: those render each eye alone), small and large images (bodies close
/// to the eyes, partly behind their near planes), on 1 and 2 threads.
#[test]
fn eyes_sharing_their_set_up_give_the_brute_force_bytes() {
    let small: [Cam; 2] = [
        ("left", PixelFormat::Rgb8, 32, 24, 120.0, 90.0),
        ("right", PixelFormat::Rgb8, 32, 24, 120.0, 90.0),
    ];
    let large: [Cam; 2] = [
        ("left", PixelFormat::Depth32f, 160, 120, 100.0, 75.0),
        ("right", PixelFormat::Depth32f, 160, 120, 100.0, 75.0),
    ];
    let worlds = [
        (crowd_world_with(64, &small), &small, 64),
        (crowd_world_moved_with(64, &small), &small, 48),
        (crowd_world_with(16, &large), &large, 16),
        (crowd_world_moved_with(16, &large), &large, 12),
    ];
    for (k, (w, cams, pairs)) in worlds.iter().enumerate() {
        let want = frames_of(w, &cams[..], |w, id, image| {
            let body = w.bodies().iter().find(|b| b.id == id).unwrap();
            super::reference::render_image(w, body, image);
        });
        // How many images were grouped: the test must exercise the shared set-up.
        let mut bufs: Vec<Vec<u8>> = want.iter().map(|f| vec![0; f.len()]).collect();
        let jobs: Vec<_> = bufs
            .iter_mut()
            .enumerate()
            .map(|(i, buf)| {
                let (body, c) = (&w.bodies()[i / 2], &cams[i % 2]);
                let desc = desc((i % 2) as u32, c.0, c.1, c.2, c.3);
                (
                    body,
                    ImageMut {
                        desc,
                        data: buf.as_mut_slice(),
                    },
                )
            })
            .collect();
        let capacity = jobs.len();
        let groups = super::group_images(w, jobs, capacity);
        let paired = groups.iter().filter(|g| g.second.is_some()).count();
        assert_eq!(paired, *pairs, "world {k}: eye pairs sharing a set-up");
        for threads in [1, 2] {
            let mut r = Renderer::new(threads).unwrap();
            let got = frames_batched(w, &cams[..], &mut r);
            for (i, (g, e)) in got.iter().zip(&want).enumerate() {
                let differ = g.iter().zip(e).filter(|(a, b)| a != b).count();
                assert!(
                    differ == 0,
                    "world {k}, image {i} ({threads} thread(s)): {differ} bytes differ from \
                     the brute-force loop"
                );
            }
        }
    }
}

/// The fast renderer (per-tile lists, depth order, early exit) gives exactly the bytes of
/// the brute-force loop it replaced ([`super::reference`]), for every image of the crowd
/// as it starts and after moving, with 64 and 5 agents, on 1 and 2 threads; and with
/// larger images (larger tiles) from 8 agents of which some walked close to others.
#[test]
fn fast_renderer_equals_the_brute_force_loop() {
    let large: [Cam; 3] = [
        ("left", PixelFormat::Rgb8, 320, 240, 120.0, 90.0),
        ("main", PixelFormat::Depth32f, 200, 150, 100.0, 80.0),
        ("right", PixelFormat::Gray8, 275, 131, 170.0, 60.0),
    ];
    let mut moved_large = crowd_world_with(8, &large);
    for id in 0..8 {
        let target = Vec3::new(0.1 * id as f32, 0.0, -0.2);
        w_apply(&mut moved_large, id, Command::MoveTo { target });
    }
    for _ in 0..40 {
        moved_large.step();
    }
    let worlds = [
        (crowd_world(64), &CAMERAS[..]),
        (crowd_world_moved(64), &CAMERAS[..]),
        (crowd_world_moved(5), &CAMERAS[..]),
        (crowd_world_with(8, &large), &large[..]),
        (moved_large, &large[..]),
    ];
    let want: Vec<Vec<Vec<u8>>> = worlds
        .iter()
        .map(|(w, cams)| {
            frames_of(w, cams, |w, id, image| {
                let body = w.bodies().iter().find(|b| b.id == id).unwrap();
                super::reference::render_image(w, body, image);
            })
        })
        .collect();
    for threads in [1, 2] {
        let mut r = Renderer::new(threads).unwrap();
        for (k, ((w, cams), want)) in worlds.iter().zip(&want).enumerate() {
            let got = frames_of(w, cams, |w, id, image| {
                let body = w.bodies().iter().find(|b| b.id == id).unwrap();
                r.render_image(w, body, image);
            });
            for (i, (g, e)) in got.iter().zip(want).enumerate() {
                let differ = g.iter().zip(e).filter(|(a, b)| a != b).count();
                assert!(
                    differ == 0,
                    "world {k}, agent {}, camera {}, {threads} thread(s): {differ} of {} \
                     bytes differ from the brute-force render",
                    i / cams.len(),
                    i % cams.len(),
                    e.len()
                );
            }
        }
    }
}

fn w_apply(w: &mut World, id: u32, command: Command) {
    w.apply(id, 1, command).unwrap();
}

/// Where the time goes, for the numbers in the report (not an assertion): per image, the
/// primitives kept after culling; per ray, the primitives whose row range covers the ray
/// (the ones the ray's column is compared with) and those whose rectangle covers it (the
/// intersection tests); and the render time per ray, at 1 to 64 agents with two 32×24
/// cameras each. `cargo test --release -p vrsync-sim crowd_render_speed -- --ignored
/// --nocapture`.
#[test]
#[ignore = "measurement, run by hand in release mode"]
fn crowd_render_speed() {
    let cams = CROWD_EYES;
    for agents in [1, 4, 8, 16, 32, 64] {
        let w = crowd_world_with(agents, &cams);
        let mut r = super::Scratch::default();
        let (mut prims, mut visited, mut tests, mut rays) = (0usize, 0usize, 0usize, 0usize);
        for body in w.bodies() {
            for spec in body.cameras() {
                let cam = w.camera(body, spec);
                r.collect_prims(&w, body, &cam, Vec3::ZERO);
                r.bin_prims(&cam);
                prims += r.prims.len();
                let (room_min, room_max) = w.room_bounds();
                for y in 0..cam.height_px {
                    for x in 0..cam.width_px {
                        rays += 1;
                        let d = cam.ray_through(x as f32 + 0.5, y as f32 + 0.5);
                        let inv = crate::geometry::recip(d);
                        let mut t =
                            crate::geometry::exit_box(cam.origin, inv, room_min, room_max).0;
                        let tiles = &r.tiles;
                        let tile = (y / tiles.height * tiles.cols + x / tiles.width) as usize;
                        for e in
                            &tiles.items[tiles.start[tile] as usize..tiles.start[tile + 1] as usize]
                        {
                            let p = &r.prims[e.index as usize];
                            visited += 1;
                            if p.near > t {
                                break;
                            }
                            if (p.x0..=p.x1).contains(&x) && (p.y0..=p.y1).contains(&y) {
                                tests += 1;
                                if let Some(th) = super::hit_prim(p, cam.origin, d, inv) {
                                    t = t.min(th);
                                }
                            }
                        }
                    }
                }
            }
        }
        let images = w.bodies().len() * cams.len();
        let setup = {
            let t = std::time::Instant::now();
            for _ in 0..20 {
                for body in w.bodies() {
                    for spec in body.cameras() {
                        let cam = w.camera(body, spec);
                        r.collect_prims(&w, body, &cam, Vec3::ZERO);
                        r.bin_prims(&cam);
                    }
                }
            }
            t.elapsed().as_secs_f64() / (20 * images) as f64
        };
        for threads in [1, 2] {
            let mut r = Renderer::new(threads).unwrap();
            let mut best = f64::MAX;
            let cycles = (2000 / agents).max(20);
            let mut bufs: Vec<Vec<u8>> = (0..images).map(|_| vec![0u8; 32 * 24 * 3]).collect();
            for _ in 0..3 {
                let t = std::time::Instant::now();
                for _ in 0..cycles {
                    // In batches of agents, as `vr-sim run` renders.
                    let mut jobs: Vec<_> = bufs
                        .iter_mut()
                        .enumerate()
                        .map(|(i, buf)| {
                            let (body, camera) = (&w.bodies()[i / 2], i % 2);
                            let d = desc(camera as u32, cams[camera].0, PixelFormat::Rgb8, 32, 24);
                            (
                                body,
                                ImageMut {
                                    desc: d,
                                    data: buf.as_mut_slice(),
                                },
                            )
                        })
                        .collect();
                    while !jobs.is_empty() {
                        let rest =
                            jobs.split_off(jobs.len().min(r.agents_per_batch().saturating_mul(2)));
                        r.render_images(&w, jobs);
                        jobs = rest;
                    }
                }
                best = best.min(t.elapsed().as_secs_f64() / f64::from(cycles));
            }
            println!(
                "{agents:>2} agents, {threads} thread(s): {:.1} prims/image ({:.1} µs to collect \
                 and list them), {:.2} visited/ray, {:.2} tested/ray; {:.0} µs/cycle, \
                 {:.1} ns/ray",
                prims as f64 / images as f64,
                setup * 1e6,
                visited as f64 / rays as f64,
                tests as f64 / rays as f64,
                best * 1e6,
                best * 1e9 / rays as f64
            );
        }
    }
}

/// The set-up, what tracing costs with the tile lists the renderer builds, and a floor
/// under every culling scheme: tracing with lists that hold, for each packet (8 × 1
/// pixels), exactly the primitives its pixels see (so each packet tests only what it must
/// to get every pixel's exact depth, and nothing has to be listed). Every figure for the
/// crowd of [`crowd_render_speed`] (two 32 × 24 rgb8 eyes per agent), on one thread.
/// The floor's images are checked to be the renderer's, byte for byte. Run it with
/// `cargo test --release -p vrsync-sim --bin vr-sim crowd_per_ray_floor -- --ignored
/// --nocapture`.
#[test]
#[ignore = "prints timings; run on demand in release mode"]
fn crowd_per_ray_floor() {
    use super::{Scratch, draw, row_shader, view_of};
    let cams = CROWD_EYES;
    let shader = row_shader();
    for agents in [1, 4, 16, 64] {
        let w = crowd_world_with(agents, &cams);
        let room = w.room_bounds();
        // Per image: camera, primitives, the renderer's tiles, the floor's tiles.
        let mut images = Vec::new();
        let mut scratch = Scratch::default();
        let (mut listed, mut tested, mut hit, mut seen, mut seeing) = (0usize, 0, 0, 0, 0);
        for body in w.bodies() {
            for (i, spec) in body.cameras().iter().enumerate() {
                let cam = w.camera(body, spec);
                scratch.collect_prims(&w, body, &cam, Vec3::ZERO);
                scratch.bin_prims(&cam);
                let prims = scratch.prims.clone();
                let packets = cam.width_px.div_ceil(8);
                let (mut lists, hit_lists) = seen_and_hit_per_packet(&cam, &prims, room);
                let floor = floor_tiles(&mut lists, &prims, packets);
                let (walked, tests) = walked_and_tested(&cam, &scratch.tiles, &prims, room);
                listed += walked;
                tested += tests;
                seen += floor.items.len();
                hit += hit_lists.iter().map(Vec::len).sum::<usize>();
                seeing += lists.iter().filter(|l| !l.is_empty()).count();
                let d = desc(i as u32, cams[i].0, PixelFormat::Rgb8, 32, 24);
                images.push((cam, prims, scratch.tiles.clone(), floor, d));
            }
        }
        let pixels = (images.len() * 32 * 24) as f64;
        let mut bufs = vec![vec![0u8; 32 * 24 * 3]; images.len()];
        let mut floor_bufs = bufs.clone();
        let trace = |bufs: &mut [Vec<u8>], floor: bool| {
            for ((cam, prims, tiles, floor_tiles, d), buf) in images.iter().zip(bufs.iter_mut()) {
                let tiles = if floor { floor_tiles } else { tiles };
                let view = view_of(&w, *cam, prims, tiles);
                draw(&view, d, PixelFormat::Rgb8, buf, None, shader);
            }
        };
        trace(&mut bufs, false);
        trace(&mut floor_bufs, true);
        assert!(
            bufs == floor_bufs,
            "the floor's images differ from the renderer's"
        );
        let rounds = (4000 / agents).max(40);
        let best = |f: &mut dyn FnMut()| {
            (0..5)
                .map(|_| {
                    let t = std::time::Instant::now();
                    for _ in 0..rounds {
                        f();
                    }
                    t.elapsed().as_secs_f64() * 1e9 / (f64::from(rounds) * pixels)
                })
                .fold(f64::MAX, f64::min)
        };
        let setup = best(&mut || {
            for body in w.bodies() {
                for spec in body.cameras() {
                    let cam = w.camera(body, spec);
                    scratch.collect_prims(&w, body, &cam, Vec3::ZERO);
                    scratch.bin_prims(&cam);
                }
            }
        });
        let traced = best(&mut || trace(&mut bufs, false));
        let floor = best(&mut || trace(&mut floor_bufs, true));
        println!(
            "{agents:>2} agents: set-up {setup:.2} ns/ray (per image, eyes not shared), trace \
             {traced:.2} ns/ray (per packet: {:.2} list entries at most, {:.2} tested, {:.2} \
             hit by some ray), floor {floor:.2} ns/ray ({:.2} seen primitives per packet, \
             {:.0}% of packets see one)",
            listed as f64 / pixels * 8.0,
            tested as f64 / pixels * 8.0,
            hit as f64 / pixels * 8.0,
            seen as f64 / pixels * 8.0,
            seeing as f64 / pixels * 800.0,
        );
    }
}

/// Per packet (8 × 1 pixels) of `cam`, the primitives its pixels see: each pixel's nearest
/// primitive, as the renderer decides it (among those whose rectangle holds the pixel, the
/// nearest hit nearer than the room, on equal depth the first); and every primitive some
/// pixel's ray hits, seen or hidden.
fn seen_and_hit_per_packet(
    cam: &Camera,
    prims: &[Prim],
    (room_min, room_max): (Vec3, Vec3),
) -> (Vec<Vec<u32>>, Vec<Vec<u32>>) {
    let packets = cam.width_px.div_ceil(8);
    let mut lists: Vec<Vec<u32>> = vec![Vec::new(); (packets * cam.height_px) as usize];
    // Per packet, every primitive some pixel's ray hits (seen or hidden).
    let mut hit_lists = lists.clone();
    for y in 0..cam.height_px {
        let rr = RowRays::of(cam, y);
        for x in 0..cam.width_px {
            let d = rr.dir(cam.right, x);
            let inv = crate::geometry::recip(d);
            let mut t = crate::geometry::exit_box(cam.origin, inv, room_min, room_max).0;
            let mut nearest = None;
            let hit_list = &mut hit_lists[(y * packets + x / 8) as usize];
            for p in prims {
                if (p.x0..=p.x1).contains(&x)
                    && (p.y0..=p.y1).contains(&y)
                    && let Some(th) = hit_prim(p, cam.origin, d, inv)
                {
                    if !hit_list.contains(&p.index) {
                        hit_list.push(p.index);
                    }
                    if th < t {
                        (t, nearest) = (th, Some(p.index));
                    }
                }
            }
            let list = &mut lists[(y * packets + x / 8) as usize];
            if let Some(k) = nearest
                && !list.contains(&k)
            {
                list.push(k);
            }
        }
    }
    (lists, hit_lists)
}

/// The floor's tiles: one per packet, listing exactly the primitives it sees (`lists`,
/// sorted here by nearest depth, then index).
fn floor_tiles(lists: &mut [Vec<u32>], prims: &[Prim], packets: u32) -> Tiles {
    let mut floor = Tiles {
        width: 8,
        height: 1,
        cols: packets,
        ..Tiles::default()
    };
    floor.start.push(0);
    for list in lists.iter_mut() {
        list.sort_by(|&a, &b| {
            let (a, b) = (&prims[a as usize], &prims[b as usize]);
            a.near.total_cmp(&b.near).then(a.index.cmp(&b.index))
        });
        floor
            .items
            .extend(list.iter().map(|&k| Entry::of(&prims[k as usize])));
        floor.start.push(floor.items.len() as u32);
    }
    floor
}

/// The list entries the packets of `cam` walk over the renderer's `tiles` (at most; a
/// packet stops at the first beyond its hits), and those they test: walking each list as
/// the renderer does.
fn walked_and_tested(
    cam: &Camera,
    tiles: &Tiles,
    prims: &[Prim],
    (room_min, room_max): (Vec3, Vec3),
) -> (usize, usize) {
    let t = tiles;
    let (mut listed, mut tested) = (0, 0);
    for y in 0..cam.height_px {
        let rr = RowRays::of(cam, y);
        for x0 in (0..cam.width_px).step_by(8) {
            let tile = (y / t.height * t.cols + x0 / t.width) as usize;
            let list = &t.items[t.start[tile] as usize..t.start[tile + 1] as usize];
            listed += list.len();
            let rays: Vec<(u32, glam::Vec3)> = (x0..(x0 + 8).min(cam.width_px))
                .map(|x| (x, rr.dir(cam.right, x)))
                .collect();
            let mut depth: Vec<f32> = rays
                .iter()
                .map(|&(_, d)| {
                    let inv = crate::geometry::recip(d);
                    crate::geometry::exit_box(cam.origin, inv, room_min, room_max).0
                })
                .collect();
            for e in list {
                if e.near > depth.iter().fold(f32::MIN, |m, &v| m.max(v)) {
                    break;
                }
                let (y, first, last) = (y as u16, x0 as u16, rays[rays.len() - 1].0 as u16);
                if y < e.y0 || y > e.y1 || last < e.x0 || first > e.x1 {
                    continue;
                }
                tested += 1;
                let p = &prims[e.index as usize];
                for (&(x, d), t) in rays.iter().zip(&mut depth) {
                    if (p.x0..=p.x1).contains(&x)
                        && let Some(th) = hit_prim(p, cam.origin, d, crate::geometry::recip(d))
                        && th < *t
                    {
                        *t = th;
                    }
                }
            }
        }
    }
    (listed, tested)
}
