//! The `legacy` rows: one agent over the original system's protocol (PNG images in
//! protobuf frames over one TCP socket per agent, served by the bridge's legacy
//! transport), against shm at the original's stereo 256×148 and at 3×1920×1080.
//!
//! The client runs on a thread of this process and does what the original clients do
//! each cycle: read every frame, decode the PNG images (as the Python client's Pillow
//! does), touch the first and last byte of every row (as the Rust bench agent does), send
//! one command and the zero-length stop. The images are rendered by vr-sim's renderer in
//! the warm-up cycles (the legacy transport keeps its frame buffer, so the measured cycles
//! encode real pictures, not blank ones), and the PNG encoder runs at the configured
//! fastest level.

use std::io::{Read, Write as _};
use std::net::TcpStream;
use std::thread::JoinHandle;

use prost::Message;
use vrsync_bridge::HostCreateError;
use vrsync_bridge::PngCompression;
use vrsync_bridge::legacy::LegacyHostCreateError;
use vrsync_bridge::legacy::codec::{self, Dialect, field};

use super::*;

/// The config of a legacy case: agent 0 over the legacy transport, cameras named as the
/// original's (`left`, `right`, and `main` for a third).
fn config_text(case: &Case, session: &str, base: u16) -> String {
    let mut s = format!(
        "session = {session:?}\n[sync]\nsync_mode = true\nsimulation_time_per_frame = 0.01\n\
         stop_timeout = 10.0\nconnect_timeout = 30.0\n[transport]\nmax_commands_per_cycle = 8\n\
         [transport.legacy]\nlocal_port = {base}\n[[agent]]\nid = 0\ntransport = \"legacy\"\n"
    );
    for name in ["left", "right", "main"].iter().take(case.cameras as usize) {
        s += &format!(
            "[[agent.camera]]\nname = \"{name}\"\nwidth = {}\nheight = {}\nformat = \"rgb8\"\n",
            case.width, case.height
        );
    }
    s
}

/// The legacy client: version check, then per cycle decode every PNG, touch each row,
/// one AgentTurn, the zero-length stop; ends when the host closes.
fn client(port: u16, dialect: Dialect) -> anyhow::Result<()> {
    let mut s = TcpStream::connect(("127.0.0.1", port)).context("connect to the legacy port")?;
    s.set_nodelay(true)?;
    let mut out = Vec::new();
    codec::push_message(
        &mut out,
        dialect.version_check_field(),
        &codec::VersionCheck {
            version: Some(codec::VERSION.into()),
        },
    );
    s.write_all(&out)?;
    let mut body = Vec::new();
    let mut pixels = Vec::new();
    let mut started = false;
    let mut action = 0i32;
    let mut sink = 0u8;
    loop {
        let mut len = [0u8; 4];
        if s.read_exact(&mut len).is_err() {
            break; // the host closed the session
        }
        let len = usize::try_from(i32::from_le_bytes(len)).context("negative frame length")?;
        body.resize(len, 0);
        s.read_exact(&mut body)?;
        let (f, payload) =
            codec::single_field(&body, Dialect::Burkhardt).map_err(|e| anyhow::anyhow!("{e}"))?;
        match f {
            field::IMAGES => {
                let images = codec::Images::decode(payload)?;
                for png in [images.left, images.right, images.main]
                    .into_iter()
                    .flatten()
                {
                    let mut reader = png::Decoder::new(std::io::Cursor::new(&png)).read_info()?;
                    pixels.resize(reader.output_buffer_size().unwrap_or(0), 0);
                    let info = reader.next_frame(&mut pixels)?;
                    for row in pixels[..info.buffer_size()].chunks_exact(info.line_size.max(1)) {
                        sink ^= row[0] ^ row[row.len() - 1];
                    }
                }
            }
            field::START_SYNC => started = true,
            field::DEBUG if started => {
                started = false;
                action = action.wrapping_add(1);
                out.clear();
                codec::push_message(
                    &mut out,
                    field::AGENT_TURN,
                    &codec::AgentTurn {
                        action_id: Some(action),
                        degree: Some(0.0),
                    },
                );
                out.extend_from_slice(&0i32.to_le_bytes());
                s.write_all(&out)?;
            }
            _ => {}
        }
    }
    std::hint::black_box(sink);
    Ok(())
}

/// Mean time to PNG-encode one `case`-sized RGB image of `pixels` at the fastest level, µs.
fn png_encode_us(case: &Case, pixels: &[u8]) -> anyhow::Result<f64> {
    let n = if case.width >= 1920 { 5 } else { 50 };
    let mut out = Vec::new();
    let t0 = Instant::now();
    for _ in 0..n {
        out.clear();
        let mut enc = png::Encoder::new(&mut out, case.width, case.height);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        enc.set_compression(png::Compression::Fastest);
        let mut w = enc.write_header()?;
        w.write_image_data(pixels)?;
        w.finish()?;
    }
    Ok(t0.elapsed().as_secs_f64() * 1e6 / f64::from(n))
}

/// One round of a legacy case.
pub(super) fn bench_legacy(case: &Case, session: &str, render: bool) -> anyhow::Result<Measured> {
    // Agent ports follow local_port: find a free range by trying (another program may
    // hold one of the ports).
    let mut attempt = 0u32;
    let (mut host, config, base) = loop {
        attempt += 1;
        let base = 30_000 + ((std::process::id() * 131 + attempt * 977) % 30_000) as u16;
        let config =
            Config::from_toml_str(&config_text(case, session, base), Path::new("<bench>"))?;
        debug_assert_eq!(
            config.transport.legacy.png_compression,
            PngCompression::Fastest
        );
        match Host::builder(&config)
            .signal_handling(SignalHandling::Install)
            .create()
        {
            Ok(h) => break (h, config, base),
            Err(HostCreateError::Legacy(LegacyHostCreateError::Bind { .. })) if attempt < 20 => {}
            Err(e) => return Err(e).context("create the legacy bench host"),
        }
    };
    let world = crate::world::World::from_config(&config)?;
    let mut renderer = crate::render::Renderer::new(0)?;
    let dialect = if case.cameras >= 3 {
        Dialect::Burkhardt
    } else {
        Dialect::Vrnew
    };
    let agent: JoinHandle<anyhow::Result<()>> =
        std::thread::spawn(move || client(base + 1, dialect));
    host.wait_for_agents(Duration::from_secs(30))?;
    let mut hist = histogram()?;
    let mut png_us = f64::NAN;
    for cycle in 0..case.warmup + case.cycles {
        let t0 = Instant::now();
        let mut frame = host.loan_frame(0)?;
        if cycle < case.warmup {
            // Real pictures, rendered once into the buffer the transport keeps.
            renderer.render_agent(&world, 0, frame.images_mut());
            if render
                && cycle + 1 == case.warmup
                && let Some(image) = frame.images_mut().next()
            {
                png_us = png_encode_us(case, image.data)?;
            }
        } else {
            for image in frame.images_mut() {
                if let Some(b) = image.data.first_mut() {
                    *b = cycle as u8;
                }
            }
        }
        let t_publish = Instant::now();
        host.publish(frame)?;
        host.start()?;
        let report = host.collect()?;
        let elapsed = if cycle < case.warmup {
            t_publish.elapsed()
        } else {
            t0.elapsed()
        };
        if report.timed_out {
            bail!(
                "legacy {}x{}: cycle {cycle} timed out",
                case.width,
                case.height
            );
        }
        if cycle >= case.warmup {
            hist.record(elapsed.as_nanos() as u64).context("record")?;
        }
    }
    drop(host);
    agent
        .join()
        .map_err(|_| anyhow::anyhow!("the legacy bench client panicked"))??;
    let mut m = Measured::new(hist, f64::NAN, f64::NAN);
    m.png_us = png_us;
    Ok(m)
}
