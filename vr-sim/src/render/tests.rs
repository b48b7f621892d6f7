//! Golden images: small renders of a fixed test world compared with the PNGs committed
//! under `vr-sim/tests/golden/` (within a small tolerance, so that a last-bit change of
//! float rounding on another CPU does not fail them). `VRSYNC_BLESS=1 cargo test -p
//! vrsync-sim` rewrites them; look at them before committing.

use std::path::{Path, PathBuf};

use glam::Vec3;
use vrsync_bridge::Config;
use vrsync_bridge::ImageMut;
use vrsync_bridge::{CAMERA_NAME_LEN, Command, ImageDesc, PixelFormat};

use super::Renderer;
use crate::world::World;

/// Two agents in a 6 × 8 room with a red sphere, a blue box and a green pillar.
fn test_world(format: &str, width: u32, height: u32) -> World {
    let cams = format!(
        "[[agent.camera]]\nname = \"left\"\nwidth = {width}\nheight = {height}\nformat = \"{format}\"\n\
         [[agent.camera]]\nname = \"right\"\nwidth = {width}\nheight = {height}\nformat = \"{format}\"\n\
         [[agent.camera]]\nname = \"main\"\nwidth = {width}\nheight = {height}\nformat = \"{format}\"\nfov_horizontal_deg = 90.0\nfov_vertical_deg = 60.0\n"
    );
    let text = format!(
        "[[agent]]\nid = 0\n{cams}[[agent]]\nid = 1\n{cams}[world]\nroom_width = 6.0\nroom_depth = 8.0\n\
         [[world.object]]\nid = 1\nshape = \"sphere\"\nposition = [0.5, 0.4, 2.0]\nradius = 0.4\ncolor = [220, 30, 30]\n\
         [[world.object]]\nid = 2\nshape = \"box\"\nposition = [-1.5, 0.5, 1.0]\nsize = [1.0, 1.0, 1.0]\ncolor = [40, 90, 220]\n\
         [[world.object]]\nid = 3\nshape = \"box\"\nposition = [2.0, 1.0, -2.0]\nsize = [0.6, 2.0, 0.6]\ncolor = [40, 170, 70]\n\
         [[world.agent]]\nid = 0\nposition = [0.0, -2.0]\n\
         [[world.agent]]\nid = 1\nposition = [1.0, 0.5]\nheading_deg = 200.0\n"
    );
    let config = Config::from_toml_str(&text, Path::new("golden.toml")).unwrap();
    World::from_config(&config).unwrap()
}

fn desc(camera: u32, name: &str, format: PixelFormat, width: u32, height: u32) -> ImageDesc {
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

/// Renders camera `camera` of agent 0 into a fresh buffer.
fn render(r: &mut Renderer, w: &World, camera: u32, format: PixelFormat) -> (ImageDesc, Vec<u8>) {
    let spec = &w.bodies()[0].cameras()[camera as usize];
    let d = desc(
        camera,
        &spec.name.clone(),
        format,
        spec.width_px,
        spec.height_px,
    );
    let mut buf = vec![0xAB; d.len as usize];
    r.render_image(
        w,
        &w.bodies()[0],
        ImageMut {
            desc: d,
            data: &mut buf,
        },
    );
    (d, buf)
}

fn golden_path(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/golden")
        .join(name)
}

fn read_png(path: &Path) -> (png::OutputInfo, Vec<u8>) {
    let file = std::fs::File::open(path).unwrap_or_else(|e| {
        panic!(
            "{}: {e} (run with VRSYNC_BLESS=1 to create it)",
            path.display()
        )
    });
    let mut reader = png::Decoder::new(std::io::BufReader::new(file))
        .read_info()
        .unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    buf.truncate(info.buffer_size());
    (info, buf)
}

/// Compares a render with its golden PNG: at most 1 % of the samples may differ, none
/// by more than `tolerance` unless it is one of those few (edges).
fn check_golden(name: &str, d: &ImageDesc, data: &[u8], tolerance: u16) {
    let path = golden_path(name);
    let format = d.pixel_format().unwrap();
    let dir = std::env::temp_dir().join(format!("vrsync-golden-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let image = ImageMut {
        desc: *d,
        data: &mut data.to_vec(),
    };
    let fresh = crate::picture::dump_image(&dir, 0, 0, &image).unwrap();
    if std::env::var_os("VRSYNC_BLESS").is_some() {
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::copy(&fresh, &path).unwrap();
        return;
    }
    let (want_info, want) = read_png(&path);
    let (got_info, got) = read_png(&fresh);
    assert_eq!(
        (got_info.width, got_info.height),
        (want_info.width, want_info.height),
        "{name}"
    );
    assert_eq!(got.len(), want.len(), "{name}");
    let wide = format == PixelFormat::Depth32f;
    let samples: Vec<(u16, u16)> = if wide {
        got.chunks_exact(2)
            .zip(want.chunks_exact(2))
            .map(|(a, b)| {
                (
                    u16::from_be_bytes([a[0], a[1]]),
                    u16::from_be_bytes([b[0], b[1]]),
                )
            })
            .collect()
    } else {
        got.iter()
            .zip(&want)
            .map(|(&a, &b)| (u16::from(a), u16::from(b)))
            .collect()
    };
    let off = samples
        .iter()
        .filter(|(a, b)| a.abs_diff(*b) > tolerance)
        .count();
    assert!(
        off * 100 <= samples.len(),
        "{name}: {off} of {} samples differ by more than {tolerance} from {} (new render: {})",
        samples.len(),
        path.display(),
        fresh.display()
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn golden_stereo_pair_and_main_camera() {
    let w = test_world("rgb8", 96, 56);
    let mut r = Renderer::new(1).unwrap();
    for (camera, name) in [
        (0, "start_left.png"),
        (1, "start_right.png"),
        (2, "start_main.png"),
    ] {
        let (d, data) = render(&mut r, &w, camera, PixelFormat::Rgb8);
        check_golden(name, &d, &data, 2);
    }
}

#[test]
fn golden_poses_with_eye_movements() {
    let mut w = test_world("rgb8", 96, 56);
    let mut r = Renderer::new(1).unwrap();
    // Walk towards the sphere, look down and to the left.
    w.apply(
        0,
        1,
        Command::MoveTo {
            target: Vec3::new(0.3, 0.0, 0.6),
        },
    )
    .unwrap();
    w.apply(
        0,
        2,
        Command::EyeMovement {
            pan_left_deg: -20.0,
            pan_right_deg: -20.0,
            tilt_deg: -30.0,
        },
    )
    .unwrap();
    for _ in 0..10 {
        w.step();
    }
    let (d, data) = render(&mut r, &w, 0, PixelFormat::Rgb8);
    check_golden("near_left_tilted.png", &d, &data, 2);
    // Turn around: the other agent (yellow) and the green pillar.
    w.apply(0, 3, Command::Turn { angle_deg: 150.0 }).unwrap();
    w.apply(
        0,
        4,
        Command::EyeMovement {
            pan_left_deg: 0.0,
            pan_right_deg: 0.0,
            tilt_deg: 0.0,
        },
    )
    .unwrap();
    for _ in 0..10 {
        w.step();
    }
    let (d, data) = render(&mut r, &w, 0, PixelFormat::Rgb8);
    check_golden("turned_left.png", &d, &data, 2);
}

#[test]
fn golden_gray_rgba_and_depth() {
    let mut r = Renderer::new(1).unwrap();
    let w = test_world("gray8", 96, 56);
    let (d, data) = render(&mut r, &w, 0, PixelFormat::Gray8);
    check_golden("start_left_gray.png", &d, &data, 2);
    let w = test_world("depth32f", 96, 56);
    let (d, data) = render(&mut r, &w, 0, PixelFormat::Depth32f);
    check_golden("start_left_depth.png", &d, &data, 5); // millimetres
    let w = test_world("rgba8", 96, 56);
    let (_, rgba) = render(&mut r, &w, 0, PixelFormat::Rgba8);
    let w = test_world("rgb8", 96, 56);
    let (_, rgb) = render(&mut r, &w, 0, PixelFormat::Rgb8);
    for (a, b) in rgba.chunks_exact(4).zip(rgb.chunks_exact(3)) {
        assert_eq!((&a[..3], a[3]), (b, 255));
    }
}

/// Render speed, for the numbers in the report (not an assertion: never assert a
/// duration). `cargo test --release -p vrsync-sim render_speed -- --ignored
/// --nocapture`.
#[test]
#[ignore = "measurement, run by hand in release mode"]
fn render_speed() {
    for (w, h) in [(256, 148), (640, 480), (1920, 1080)] {
        let world = test_world("rgb8", w, h);
        let body = &world.bodies()[0];
        for threads in [1, 2] {
            let mut r = Renderer::new(threads).unwrap();
            let mut bufs = [
                vec![0u8; (w * h * 3) as usize],
                vec![0u8; (w * h * 3) as usize],
            ];
            let cycles = (40_000_000 / (w * h)).clamp(5, 400);
            let mut best = f64::MAX;
            for _ in 0..3 {
                let t = std::time::Instant::now();
                for _ in 0..cycles {
                    for (camera, buf) in bufs.iter_mut().enumerate() {
                        let d = desc(
                            camera as u32,
                            if camera == 0 { "left" } else { "right" },
                            PixelFormat::Rgb8,
                            w,
                            h,
                        );
                        r.render_image(&world, body, ImageMut { desc: d, data: buf });
                    }
                }
                best = best.min(t.elapsed().as_secs_f64() * 1e6 / f64::from(cycles));
            }
            println!(
                "2 x {w}x{h} rgb8, {threads} thread(s): {best:.0} µs per cycle ({:.1} ns per pixel)",
                best * 1e3 / f64::from(2 * w * h)
            );
        }
    }
}

#[test]
fn depth_is_the_distance_along_the_optical_axis() {
    // Agent 0 at z = -2 looks north at the wall at z = 4 over the sphere: the centre
    // pixel row above the horizon sees the wall 6 m away on the axis.
    let w = test_world("depth32f", 97, 57);
    let mut r = Renderer::new(1).unwrap();
    let (d, data) = render(&mut r, &w, 2, PixelFormat::Depth32f); // main: head centre
    let px = |x: u32, y: u32| {
        let i = (y * d.stride_bytes + x * 4) as usize;
        f32::from_ne_bytes([data[i], data[i + 1], data[i + 2], data[i + 3]])
    };
    assert!((px(48, 28) - 6.0).abs() < 1e-3, "{}", px(48, 28));
    // Every pixel of the north wall, left to right, is 6 m deep (a plane facing us).
    for x in [30, 40, 56, 66] {
        let v = px(x, 20);
        assert!((v - 6.0).abs() < 1e-3, "x {x}: {v}");
    }
    // The floor just below the horizon is farther than near the bottom.
    assert!(px(48, 56) < px(48, 40));
}

#[test]
fn the_red_sphere_is_red_where_it_should_be_and_threads_change_nothing() {
    let w = test_world("rgb8", 128, 74);
    let mut one = Renderer::new(1).unwrap();
    let mut two = Renderer::new(2).unwrap();
    let (d, a) = render(&mut one, &w, 0, PixelFormat::Rgb8);
    let (_, b) = render(&mut two, &w, 0, PixelFormat::Rgb8);
    assert_eq!(a, b, "rendering must not depend on the thread count");
    // The sphere at (0.5, 0.4, 2) seen from the left eye at (-0.03, 1.6, -2): slightly
    // right of the centre column, below the centre row.
    let cam = w.camera(&w.bodies()[0], &w.bodies()[0].cameras()[0]);
    let p = Vec3::new(0.5, 0.4, 2.0) - cam.origin;
    let (u, v) = (
        p.dot(cam.right) / p.dot(cam.forward),
        p.dot(cam.up) / p.dot(cam.forward),
    );
    let x = ((u / cam.tan_half_h + 1.0) * 0.5 * 128.0) as u32;
    let y = ((1.0 - v / cam.tan_half_v) * 0.5 * 74.0) as u32;
    let i = (y * d.stride_bytes + x * 3) as usize;
    let (r, g, bl) = (a[i], a[i + 1], a[i + 2]);
    assert!(
        r > 120 && g < 40 && bl < 40,
        "pixel ({x}, {y}) = {r} {g} {bl}"
    );
    assert!(x > 64 && y > 37);
}
