//! `vr-sim bench`: full sync cycles (host publish → every agent stopped) over shared memory
//! and TCP, against the raw transport floors measured in the same run.
//!
//! Each case runs in [`ROUNDS`] rounds interleaved with its floor, so a change of the
//! machine's state hits both alike. A row's `p50_us` is the median of the rounds' p50s (one
//! disturbed round cannot move it); `p99_us` and `mean_us` come from the merged histogram.
//! `render_us` is measured before the case's agents are spawned, so no agent process
//! competes with the renderer for the cores.

use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use hdrhistogram::Histogram;
use serde::Serialize;
use vrsync_bridge::{Config, Host, SignalHandling};
use vrsync_floor::alloc_count::allocations;
use vrsync_floor::{FloorError, ShmFloorHost, TcpFloorHost, ZenohFloorHost};

mod legacy;

/// What to run and where to write.
#[derive(Debug)]
pub struct BenchOptions {
    /// Fewer cycles, 320×240 and 1920×1080 only, agents 1 and 4.
    pub quick: bool,
    /// JSON output.
    pub json: Option<PathBuf>,
    /// CSV output.
    pub csv: Option<PathBuf>,
    /// SVG plot.
    pub plot: Option<PathBuf>,
    /// Python interpreter for the `python` rows (the agent is `python -m
    /// vrsync.bench_agent`) and the vector-env rows (`python -m vrsync.bench_vector`);
    /// `None`: no Python rows.
    pub python: Option<PathBuf>,
}

/// One measured configuration (DESIGN §8 bench JSON keys, plus allocations).
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    /// `shm`, `shm-spin`, `tcp`, `zenoh`, `zenoh-tls` (mutual TLS), `floor-shm`,
    /// `floor-shm-spin`, `floor-tcp`, `floor-zenoh`, `legacy`, `python`, `python-vec`.
    pub transport: String,
    /// Agents.
    pub agents: u32,
    /// Images per agent and frame.
    pub cameras: u32,
    /// Image width, px.
    pub width: u32,
    /// Image height, px.
    pub height: u32,
    /// Pixel format.
    pub format: String,
    /// Measured cycles (after warm-up).
    pub frames: u64,
    /// Median cycle time, µs.
    pub p50_us: f64,
    /// 99th percentile, µs.
    pub p99_us: f64,
    /// Mean, µs.
    pub mean_us: f64,
    /// Cycles per second at the mean.
    pub frames_per_s: f64,
    /// Host allocations per cycle in steady state.
    pub allocs_per_cycle: f64,
    /// Agent allocations per cycle in steady state (mean over agents).
    pub agent_allocs_per_cycle: f64,
    /// Time vr-sim's renderer needs for one agent's 3 images at this size, µs (measured
    /// separately, not part of the cycle; `null` on floor rows).
    pub render_us: f64,
    /// `legacy` rows: time to PNG-encode one of these images at the fastest level, µs
    /// (measured separately; `null` elsewhere).
    pub png_us: f64,
    /// `python-vec` rows: the time per agent-step spent inside the Python SDK's Rust code
    /// (`AgentGroup.step`: sends, stops, receives, copies; blocked waits for the host
    /// excluded), µs, as the agent process reports it (median of the rounds; `null`
    /// elsewhere).
    pub sdk_us_per_agent_step: f64,
}

const CAMERAS: u32 = 3;
/// The vector-env rows: one camera of this size (rgb8) per agent, at these agent counts.
const VEC_SIZE: u32 = 84;
const VEC_AGENTS: [u32; 2] = [4, 16];
/// Interleaved rounds per case (the row's p50 is the median of the rounds' p50s).
const ROUNDS: u64 = 5;
const BPP: usize = 3;

struct Case {
    transport: &'static str,
    agents: u32,
    /// Images per agent (3; 2 for the original's stereo pair; 1 for the vector-env rows).
    cameras: u32,
    width: u32,
    height: u32,
    warmup: u64,
    cycles: u64,
}

impl Case {
    fn frame_bytes(&self) -> usize {
        self.cameras as usize * self.width as usize * self.height as usize * BPP
    }
}

fn exe(name: &str) -> anyhow::Result<PathBuf> {
    let me = std::env::current_exe().context("locate vr-sim")?;
    let path = me
        .parent()
        .context("vr-sim has no folder")?
        .join(format!("{name}{}", std::env::consts::EXE_SUFFIX));
    if !path.is_file() {
        bail!(
            "cannot find {} (build it with `cargo build --release -p vrsync-agent`)",
            path.display()
        );
    }
    Ok(path)
}

/// Spawned bench agents: their stdout carries `allocs_per_cycle`; killed on drop.
struct Agents(Vec<Child>);

impl Agents {
    fn spawn(args_for: impl Fn(u32) -> Vec<String>, n: u32) -> anyhow::Result<Self> {
        Self::spawn_program(&exe("vr-bench-agent")?, args_for, n)
    }

    fn spawn_program(
        exe: &Path,
        args_for: impl Fn(u32) -> Vec<String>,
        n: u32,
    ) -> anyhow::Result<Self> {
        let mut children = Vec::new();
        for id in 0..n {
            children.push(
                Command::new(exe)
                    .args(args_for(id))
                    .stdout(Stdio::piped())
                    .stderr(Stdio::inherit())
                    .spawn()
                    .with_context(|| format!("start {}", exe.display()))?,
            );
        }
        Ok(Self(children))
    }

    /// Waits for every agent (they leave when the host closes) and averages what they
    /// report (NaN for a figure an agent does not report).
    fn finish(mut self) -> anyhow::Result<Reported> {
        let mut allocs_total = 0.0;
        let mut sdk_total = 0.0;
        let n = self.0.len().max(1) as f64;
        for child in &mut self.0 {
            let mut report = Reported::default();
            if let Some(out) = child.stdout.take() {
                for line in BufReader::new(out).lines().map_while(Result::ok) {
                    report.parse_line(&line);
                }
            }
            let status = child.wait().context("wait for a bench agent")?;
            if !status.success() {
                bail!("a bench agent failed ({status})");
            }
            allocs_total += report.allocs_per_cycle;
            sdk_total += report.sdk_us_per_agent_step;
        }
        self.0.clear();
        Ok(Reported {
            allocs_per_cycle: allocs_total / n,
            sdk_us_per_agent_step: sdk_total / n,
        })
    }
}

/// What a bench agent prints at its end: `allocs_per_cycle X` (the Rust agent),
/// `sdk_us_per_agent_step X` (`vrsync.bench_vector`).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Reported {
    allocs_per_cycle: f64,
    sdk_us_per_agent_step: f64,
}

impl Default for Reported {
    fn default() -> Self {
        Self {
            allocs_per_cycle: f64::NAN,
            sdk_us_per_agent_step: f64::NAN,
        }
    }
}

impl Reported {
    /// Takes the figure of one output line, if it carries one.
    fn parse_line(&mut self, line: &str) {
        let value = |rest: &str| rest.trim().parse::<f64>().unwrap_or(f64::NAN);
        if let Some(v) = line.strip_prefix("allocs_per_cycle ") {
            self.allocs_per_cycle = value(v);
        } else if let Some(v) = line.strip_prefix("sdk_us_per_agent_step ") {
            self.sdk_us_per_agent_step = value(v);
        }
    }
}

impl Drop for Agents {
    fn drop(&mut self) {
        for c in &mut self.0 {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

fn histogram() -> anyhow::Result<Histogram<u64>> {
    Histogram::new_with_bounds(100, 600_000_000_000, 3).context("histogram")
}

/// One measurement of one case: its histogram and allocation figures.
struct Measured {
    hist: Histogram<u64>,
    /// p50 of each round, µs.
    round_p50s_us: Vec<f64>,
    /// The agent's SDK time per agent-step of each round that reports it, µs.
    round_sdk_us: Vec<f64>,
    allocs: f64,
    agent_allocs: f64,
    render_us: f64,
    png_us: f64,
}

impl Measured {
    fn new(hist: Histogram<u64>, allocs: f64, agent_allocs: f64) -> Self {
        Self {
            round_p50s_us: vec![hist.value_at_quantile(0.5) as f64 / 1000.0],
            round_sdk_us: Vec::new(),
            hist,
            allocs,
            agent_allocs,
            render_us: f64::NAN,
            png_us: f64::NAN,
        }
    }

    /// Adds another round of the same case (allocation figures: the worst round).
    fn merge(&mut self, other: Measured) -> anyhow::Result<()> {
        self.hist.add(&other.hist).context("merge histograms")?;
        self.round_p50s_us.extend(other.round_p50s_us);
        self.round_sdk_us.extend(other.round_sdk_us);
        self.allocs = self.allocs.max(other.allocs);
        self.agent_allocs = self.agent_allocs.max(other.agent_allocs);
        if self.render_us.is_nan() {
            self.render_us = other.render_us;
        }
        if self.png_us.is_nan() {
            self.png_us = other.png_us;
        }
        Ok(())
    }
}

/// The median of `values` (the mean of the middle two for an even count; NaN if empty).
fn median(values: &[f64]) -> f64 {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    match v.len() {
        0 => f64::NAN,
        n if n % 2 == 1 => v[n / 2],
        n => (v[n / 2 - 1] + v[n / 2]) / 2.0,
    }
}

fn row(case: &Case, m: &Measured) -> Row {
    let hist = &m.hist;
    let mean_us = hist.mean() / 1000.0;
    Row {
        transport: case.transport.to_string(),
        agents: case.agents,
        cameras: case.cameras,
        width: case.width,
        height: case.height,
        format: "rgb8".into(),
        frames: hist.len(),
        p50_us: median(&m.round_p50s_us),
        p99_us: hist.value_at_quantile(0.99) as f64 / 1000.0,
        mean_us,
        frames_per_s: if mean_us > 0.0 { 1e6 / mean_us } else { 0.0 },
        allocs_per_cycle: m.allocs,
        agent_allocs_per_cycle: m.agent_allocs,
        render_us: m.render_us,
        png_us: m.png_us,
        sdk_us_per_agent_step: median(&m.round_sdk_us),
    }
}

/// Renders agent 0's frame `n` times into a loaned (never published) sample: what the
/// simulator would add to each cycle per agent.
fn measure_render(config: &Config, host: &mut Host, n: u32) -> anyhow::Result<f64> {
    let world = crate::world::World::from_config(config)?;
    let mut renderer = crate::render::Renderer::new(0)?;
    let mut total = Duration::ZERO;
    for _ in 0..n {
        let mut frame = host.loan_frame(0)?;
        let t0 = Instant::now();
        renderer.render_agent(&world, 0, frame.images_mut());
        total += t0.elapsed();
    }
    Ok(total.as_secs_f64() * 1e6 / f64::from(n.max(1)))
}

/// A CA and one certificate (naming 127.0.0.1, for server and client use) for the
/// `zenoh-tls` rows, in `dir`: `ca.pem`, `bench.pem`, `bench.key`.
fn make_certificates(dir: &Path) -> anyhow::Result<()> {
    use rcgen::{
        BasicConstraints, CertificateParams, CertifiedIssuer, DnType, ExtendedKeyUsagePurpose,
        IsCa, KeyPair,
    };
    let mut p = CertificateParams::new(Vec::<String>::new())?;
    p.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
    p.distinguished_name
        .push(DnType::CommonName, "vrsync bench CA");
    let ca = CertifiedIssuer::self_signed(p, KeyPair::generate()?)?;
    let mut p = CertificateParams::new(vec!["127.0.0.1".to_string()])?;
    p.distinguished_name
        .push(DnType::CommonName, "vrsync bench");
    p.extended_key_usages = vec![
        ExtendedKeyUsagePurpose::ServerAuth,
        ExtendedKeyUsagePurpose::ClientAuth,
    ];
    let key = KeyPair::generate()?;
    let cert = p.signed_by(&key, &ca)?;
    for (name, text) in [
        ("ca.pem", ca.pem()),
        ("bench.pem", cert.pem()),
        ("bench.key", key.serialize_pem()),
    ] {
        std::fs::write(dir.join(name), text).with_context(|| format!("write {name}"))?;
    }
    Ok(())
}

/// The config of `case`; `certs`: the folder of [`make_certificates`] (`zenoh-tls`).
fn config_text(case: &Case, session: &str, certs: &Path) -> String {
    let (kind, wait) = match case.transport {
        "tcp" => ("tcp", "block"),
        "zenoh" | "zenoh-tls" => ("zenoh", "block"),
        "shm-spin" => ("shm", "spin"),
        _ => ("shm", "block"),
    };
    let mut s = format!(
        "session = {session:?}\n[sync]\nsync_mode = true\nsimulation_time_per_frame = 0.01\n\
         stop_timeout = 10.0\nconnect_timeout = 30.0\nwait = {wait:?}\n[transport]\nkind = {kind:?}\n\
         tcp_listen = \"127.0.0.1:0\"\nmax_commands_per_cycle = 8\n"
    );
    if kind == "zenoh" {
        // Loopback, a port free a moment ago (zenoh's stable API cannot report the port
        // of a port-0 listener), scouting off (the default).
        let endpoint = loopback_endpoint().unwrap_or_default();
        if case.transport == "zenoh-tls" {
            // Mutual TLS: host and agents share the config, hence the certificate.
            let file = |name: &str| certs.join(name).display().to_string();
            s += &format!(
                "[transport.zenoh]\nlisten = [{:?}]\ntls_ca = {:?}\ntls_cert = {:?}\n\
                 tls_key = {:?}\nmtls = true\n",
                endpoint.replacen("tcp/", "tls/", 1),
                file("ca.pem"),
                file("bench.pem"),
                file("bench.key")
            );
        } else {
            s += &format!("[transport.zenoh]\nlisten = [{endpoint:?}]\n");
        }
    }
    for id in 0..case.agents {
        s += &format!("[[agent]]\nid = {id}\n");
        for c in 0..case.cameras {
            s += &format!(
                "[[agent.camera]]\nname = \"c{c}\"\nwidth = {}\nheight = {}\nformat = \"rgb8\"\n",
                case.width, case.height
            );
        }
    }
    s
}

/// The interpreter for the `python` rows, if it can import `vrsync` (else the rows are
/// left out, saying why).
fn python_agent(python: Option<&Path>) -> Option<PathBuf> {
    let python = python?;
    let ok = Command::new(python)
        .args(["-c", "import vrsync.bench_agent, vrsync.bench_vector"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if ok {
        Some(python.to_path_buf())
    } else {
        println!(
            "python rows left out: {} cannot import vrsync (pip install ./agent-sdk/python, \
             or give --python)",
            python.display()
        );
        None
    }
}

/// A full vrsync cycle through the host API.
fn bench_vrsync(
    case: &Case,
    session: &str,
    dir: &Path,
    render: bool,
    python: Option<&Path>,
) -> anyhow::Result<Measured> {
    let text = config_text(case, session, dir);
    let mut config = Config::from_toml_str(&text, Path::new("<bench>"))?;
    let mut host = Host::builder(&config)
        .signal_handling(SignalHandling::Install)
        .create()
        .context("create the bench host")?;
    if let Some(addr) = host.tcp_local_addr() {
        config.transport.tcp_listen = addr;
    }
    let path = dir.join(format!("{session}.toml"));
    std::fs::write(&path, config.to_toml_string()).context("write the bench config")?;
    // Before the agents exist: nothing else competes for the cores (spinning agents would).
    let render_us = if render && case.agents == 1 {
        measure_render(&config, &mut host, 5)?
    } else {
        f64::NAN
    };
    let warmup = case.warmup;
    let config_arg = path.display().to_string();
    let agents = match python {
        // The Python agent does the Rust agent's work (first and last byte of every row,
        // one command, stop) through the Python SDK.
        // One Python process drives every agent through the batched vector env, doing
        // the same work per agent.
        Some(python) if case.transport == "python-vec" => Agents::spawn_program(
            python,
            |_| {
                vec![
                    "-m".into(),
                    "vrsync.bench_vector".into(),
                    "--config".into(),
                    config_arg.clone(),
                    "--warmup".into(),
                    warmup.to_string(),
                ]
            },
            1,
        )?,
        Some(python) if case.transport == "python" => Agents::spawn_program(
            python,
            |id| {
                vec![
                    "-m".into(),
                    "vrsync.bench_agent".into(),
                    "--config".into(),
                    config_arg.clone(),
                    "--id".into(),
                    id.to_string(),
                ]
            },
            case.agents,
        )?,
        _ => Agents::spawn(
            |id| {
                vec![
                    "--mode".into(),
                    "sdk".into(),
                    "--config".into(),
                    config_arg.clone(),
                    "--id".into(),
                    id.to_string(),
                    "--warmup".into(),
                    warmup.to_string(),
                ]
            },
            case.agents,
        )?,
    };
    // The agents' start-up (a Python interpreter importing numpy, 16 processes on 2
    // cores) happens here, before cycle 0; the warm-up cycles follow.
    host.wait_for_agents(Duration::from_secs(60))?;
    let ids: Vec<u32> = host.agent_ids().collect();
    let mut hist = histogram()?;
    let mut allocs_start = 0;
    for cycle in 0..case.warmup + case.cycles {
        if cycle == case.warmup {
            allocs_start = allocations();
        }
        let t0 = Instant::now();
        for &id in &ids {
            let mut frame = host.loan_frame(id)?;
            // The host's part of "rendering": mark each image (the frame is already in
            // shared memory; nothing is copied).
            for image in frame.images_mut() {
                if let Some(b) = image.data.first_mut() {
                    *b = cycle as u8;
                }
            }
            host.publish(frame)?;
        }
        host.start()?;
        let report = host.collect()?;
        let elapsed = t0.elapsed();
        if report.timed_out {
            bail!(
                "{} agents={} {}x{}: cycle {cycle} timed out",
                case.transport,
                case.agents,
                case.width,
                case.height
            );
        }
        if cycle >= case.warmup {
            hist.record(elapsed.as_nanos() as u64).context("record")?;
        }
    }
    let host_allocs = (allocations() - allocs_start) as f64 / case.cycles as f64;
    drop(host);
    let reported = agents.finish()?;
    let _ = std::fs::remove_file(&path);
    let mut m = Measured::new(hist, host_allocs, reported.allocs_per_cycle);
    m.render_us = render_us;
    if !reported.sdk_us_per_agent_step.is_nan() {
        m.round_sdk_us.push(reported.sdk_us_per_agent_step);
    }
    Ok(m)
}

/// The raw iceoryx2 round trip.
fn bench_floor_shm(case: &Case, session: &str, spin: bool) -> anyhow::Result<Measured> {
    let bytes = case.frame_bytes();
    // The same waiting strategy as vrsync with the default config (see
    // `SyncConfig::effective_spin_before_block`).
    let cores = std::thread::available_parallelism().map_or(1, usize::from);
    let spin_before_block = if case.agents as usize + 1 > cores {
        Duration::ZERO
    } else {
        Duration::from_micros(vrsync_bridge::DEFAULT_SPIN_BEFORE_BLOCK_US)
    };
    let mut host = ShmFloorHost::create(session, case.agents, bytes, spin, spin_before_block)?;
    let total = case.warmup + case.cycles;
    let row_bytes = case.width as usize * BPP;
    let agents = Agents::spawn(
        |id| {
            let mut a = vec![
                "--mode".into(),
                "floor-shm".into(),
                "--session".into(),
                session.to_string(),
                "--id".into(),
                id.to_string(),
                "--cycles".into(),
                total.to_string(),
                "--row-bytes".into(),
                row_bytes.to_string(),
                "--warmup".into(),
                case.warmup.to_string(),
                "--spin-before-block-us".into(),
                spin_before_block.as_micros().to_string(),
            ];
            if spin {
                a.push("--spin".into());
            }
            a
        },
        case.agents,
    )?;
    host.wait_connected(Duration::from_secs(30))?;
    let (hist, host_allocs) =
        measure_floor(case, |cycle| host.cycle(cycle, Duration::from_secs(10)))?;
    let agent_allocs = agents.finish()?.allocs_per_cycle;
    drop(host);
    Ok(Measured::new(hist, host_allocs, agent_allocs))
}

/// The one measurement loop of every floor: runs `cycle` for the warm-up and measured
/// cycles of `case` and returns the histogram of the measured cycles' round trips (ns) and
/// the host's allocations per measured cycle.
fn measure_floor(
    case: &Case,
    mut cycle: impl FnMut(u64) -> Result<(), FloorError>,
) -> anyhow::Result<(Histogram<u64>, f64)> {
    let total = case.warmup + case.cycles;
    let mut hist = histogram()?;
    let mut allocs_start = 0;
    for c in 0..total {
        if c == case.warmup {
            allocs_start = allocations();
        }
        let t0 = Instant::now();
        cycle(c)?;
        if c >= case.warmup {
            hist.record(t0.elapsed().as_nanos() as u64)
                .context("record")?;
        }
    }
    let host_allocs = (allocations() - allocs_start) as f64 / case.cycles as f64;
    Ok((hist, host_allocs))
}

/// `tcp/127.0.0.1:<a port free a moment ago>`.
fn loopback_endpoint() -> anyhow::Result<String> {
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .context("find a free loopback port")?
        .port();
    Ok(format!("tcp/127.0.0.1:{port}"))
}

/// The raw zenoh round trip (put → subscriber → 8-byte reply, same fan-out).
fn bench_floor_zenoh(case: &Case, session: &str) -> anyhow::Result<Measured> {
    let bytes = case.frame_bytes();
    let endpoint = loopback_endpoint()?;
    let mut host = ZenohFloorHost::create(session, &endpoint, case.agents, bytes)?;
    let total = case.warmup + case.cycles;
    let row_bytes = case.width as usize * BPP;
    let agents = Agents::spawn(
        |id| {
            vec![
                "--mode".into(),
                "floor-zenoh".into(),
                "--session".into(),
                session.to_string(),
                "--endpoint".into(),
                endpoint.clone(),
                "--id".into(),
                id.to_string(),
                "--cycles".into(),
                total.to_string(),
                "--row-bytes".into(),
                row_bytes.to_string(),
                "--warmup".into(),
                case.warmup.to_string(),
            ]
        },
        case.agents,
    )?;
    host.wait_connected(Duration::from_secs(30))?;
    let (hist, host_allocs) =
        measure_floor(case, |cycle| host.cycle(cycle, Duration::from_secs(10)))?;
    drop(host);
    let agent_allocs = agents.finish()?.allocs_per_cycle;
    Ok(Measured::new(hist, host_allocs, agent_allocs))
}

/// The raw TCP round trip.
fn bench_floor_tcp(case: &Case) -> anyhow::Result<Measured> {
    let bytes = case.frame_bytes();
    let mut host = TcpFloorHost::create(bytes)?;
    let addr = host.addr()?;
    let total = case.warmup + case.cycles;
    let row_bytes = case.width as usize * BPP;
    let agents = Agents::spawn(
        |_| {
            vec![
                "--mode".into(),
                "floor-tcp".into(),
                "--addr".into(),
                addr.to_string(),
                "--frame-bytes".into(),
                bytes.to_string(),
                "--cycles".into(),
                total.to_string(),
                "--row-bytes".into(),
                row_bytes.to_string(),
                "--warmup".into(),
                case.warmup.to_string(),
            ]
        },
        case.agents,
    )?;
    host.accept(case.agents, Duration::from_secs(30))?;
    let (hist, host_allocs) = measure_floor(case, |cycle| host.cycle(cycle))?;
    let agent_allocs = agents.finish()?.allocs_per_cycle;
    Ok(Measured::new(hist, host_allocs, agent_allocs))
}

/// Runs the whole benchmark and writes the outputs.
///
/// # Errors
/// Any failed measurement or output.
pub fn run(opts: &BenchOptions) -> anyhow::Result<Vec<Row>> {
    if let Some(p) = &opts.plot
        && p.extension().is_none_or(|e| e != "svg")
    {
        bail!(
            "--plot writes SVG: give a file name ending in .svg (got {})",
            p.display()
        );
    }
    let sets: &[(u32, u32)] = if opts.quick {
        &[(320, 240), (1920, 1080)]
    } else {
        &[(320, 240), (640, 480), (1280, 720), (1920, 1080)]
    };
    let agent_counts: &[u32] = if opts.quick { &[1, 4] } else { &[1, 2, 4] };
    let python = python_agent(opts.python.as_deref());
    // The bench agents' configs: in a private temp dir (random name, mode 0700), not at a
    // predictable /tmp path; removed at the end.
    let dir = {
        use std::os::unix::fs::PermissionsExt;
        tempfile::Builder::new()
            .prefix("vrsync-bench-")
            .permissions(std::fs::Permissions::from_mode(0o700))
            .tempdir()
            .context("cannot create a temp dir for the bench configs")?
    };
    make_certificates(dir.path()).context("make the zenoh-tls rows' certificates")?;
    let mut rows = Vec::new();
    let mut n = 0u32;
    let session = |n: &mut u32| {
        *n += 1;
        format!("bench-{}-{n}", std::process::id())
    };
    let shm_cycles = if opts.quick { 400 } else { 3000 };
    println!(
        "vr-sim bench{}: 3 rgb8 images per agent (vector-env rows: one 84x84); cycle = host \
         publish -> every agent stopped",
        if opts.quick { " --quick" } else { "" }
    );
    print_header();
    for &(w, h) in sets {
        let bytes = CAMERAS as u64 * u64::from(w) * u64::from(h) * BPP as u64;
        // TCP moves every byte: size the run by volume (~1.5 GB quick, ~6 GB full).
        let volume: u64 = if opts.quick {
            1_500_000_000
        } else {
            6_000_000_000
        };
        for &agents in agent_counts {
            let tcp_cycles = (volume / (bytes * u64::from(agents))).clamp(30, shm_cycles);
            let mk = |transport: &'static str, cycles: u64| Case {
                transport,
                agents,
                cameras: CAMERAS,
                width: w,
                height: h,
                warmup: (cycles / ROUNDS / 10).max(10),
                cycles: (cycles / ROUNDS).max(10),
            };
            let mut cases = vec![mk("shm", shm_cycles), mk("floor-shm", shm_cycles)];
            // Spinning needs a free core per waiting process: 1 agent + the host on 2 cores.
            if agents == 1 {
                cases.push(mk("shm-spin", shm_cycles));
                cases.push(mk("floor-shm-spin", shm_cycles));
            }
            cases.push(mk("tcp", tcp_cycles));
            cases.push(mk("floor-tcp", tcp_cycles));
            cases.push(mk("zenoh", tcp_cycles));
            cases.push(mk("zenoh-tls", tcp_cycles));
            cases.push(mk("floor-zenoh", tcp_cycles));
            // The Python agent (1 agent, the smallest and the largest image set).
            if python.is_some() && agents == 1 && (w == 320 || w == 1920) {
                cases.push(mk("python", shm_cycles));
            }
            // Rounds interleave the cases, so a change of the machine's state (other load,
            // CPU idle states) hits vrsync and its floor alike; each round measures a third
            // of the cycles and the histograms are merged.
            measure_interleaved(&cases, &mut rows, |case, round| match case.transport {
                "floor-shm" => bench_floor_shm(case, &session(&mut n), false),
                "floor-shm-spin" => bench_floor_shm(case, &session(&mut n), true),
                "floor-tcp" => bench_floor_tcp(case),
                "floor-zenoh" => bench_floor_zenoh(case, &session(&mut n)),
                _ => bench_vrsync(
                    case,
                    &session(&mut n),
                    dir.path(),
                    round == 0,
                    python.as_deref(),
                ),
            })?;
        }
    }
    // The batched Python vector env (one process for every agent) against the same
    // fan-out of Rust bench agents and of the raw iceoryx2 floor: one 84x84 rgb8 camera
    // per agent (an RL observation), 4 and 16 agents.
    if python.is_some() {
        let vec_cycles = if opts.quick { 600 } else { 3000 };
        for agents in VEC_AGENTS {
            let mk = |transport: &'static str| Case {
                transport,
                agents,
                cameras: 1,
                width: VEC_SIZE,
                height: VEC_SIZE,
                // Enough for the Python process to reach its steady state (first-touch
                // page faults, numpy's caches) before the host measures.
                warmup: (vec_cycles / ROUNDS / 10).max(20),
                cycles: (vec_cycles / ROUNDS).max(10),
            };
            let cases = [mk("python-vec"), mk("shm"), mk("floor-shm")];
            measure_interleaved(&cases, &mut rows, |case, _round| match case.transport {
                "floor-shm" => bench_floor_shm(case, &session(&mut n), false),
                _ => bench_vrsync(case, &session(&mut n), dir.path(), false, python.as_deref()),
            })?;
        }
    }
    // The original protocol (1 agent): PNG over TCP, one socket per agent, at the
    // original's stereo 256x148 (with an shm row of the same images) and at 3x1920x1080
    // (against the shm row above).
    for (w, h, cameras, cycles) in [
        (256, 148, 2, if opts.quick { 250 } else { 1000 }),
        (1920, 1080, 3, if opts.quick { 25 } else { 60 }),
    ] {
        let mk = |transport: &'static str, cycles: u64| Case {
            transport,
            agents: 1,
            cameras,
            width: w,
            height: h,
            warmup: (cycles / ROUNDS / 10).max(5),
            cycles: (cycles / ROUNDS).max(5),
        };
        let mut cases = vec![mk("legacy", cycles)];
        if w == 256 {
            cases.push(mk("shm", shm_cycles));
        }
        measure_interleaved(&cases, &mut rows, |case, round| match case.transport {
            "legacy" => legacy::bench_legacy(case, &session(&mut n), round == 0),
            _ => bench_vrsync(case, &session(&mut n), dir.path(), round == 0, None),
        })?;
    }
    print_ratios(&rows);
    if let Some(p) = &opts.json {
        let text = serde_json::to_string_pretty(&rows).context("serialise")?;
        std::fs::write(p, text + "\n").with_context(|| format!("write {}", p.display()))?;
    }
    if let Some(p) = &opts.csv {
        write_csv(p, &rows)?;
    }
    if let Some(p) = &opts.plot {
        plot(p, &rows)?;
    }
    Ok(rows)
}

fn print_header() {
    println!(
        "{:<15} {:>6} {:>12} {:>10} {:>10} {:>10} {:>10} {:>10} {:>10} {:>10} {:>10}",
        "transport",
        "agents",
        "image",
        "MB/agent",
        "p50 µs",
        "p99 µs",
        "mean µs",
        "allocs/c",
        "agent a/c",
        "render µs",
        "sdk µs/step"
    );
}

/// Measures every case in [`ROUNDS`] interleaved rounds (`measure(case, round)`), so a
/// change of the machine's state (other load, CPU idle states) hits vrsync and its floor
/// alike, merges each case's rounds, and prints and appends its row.
fn measure_interleaved(
    cases: &[Case],
    rows: &mut Vec<Row>,
    mut measure: impl FnMut(&Case, u64) -> anyhow::Result<Measured>,
) -> anyhow::Result<()> {
    let mut measured: Vec<Option<Measured>> = cases.iter().map(|_| None).collect();
    for round in 0..ROUNDS {
        for (case, acc) in cases.iter().zip(measured.iter_mut()) {
            let m = measure(case, round)?;
            match acc {
                Some(a) => a.merge(m)?,
                None => *acc = Some(m),
            }
        }
    }
    for (case, m) in cases.iter().zip(measured) {
        let Some(m) = m else { continue };
        let r = row(case, &m);
        print_row(&r);
        rows.push(r);
    }
    Ok(())
}

fn print_row(r: &Row) {
    let mb = f64::from(r.cameras) * f64::from(r.width) * f64::from(r.height) * BPP as f64 / 1e6;
    println!(
        "{:<15} {:>6} {:>12} {:>10.3} {:>10.1} {:>10.1} {:>10.1} {:>10.2} {:>10.2} {:>10} {:>10}",
        r.transport,
        r.agents,
        format!("{}x{}x{}", r.cameras, r.width, r.height),
        mb,
        r.p50_us,
        r.p99_us,
        r.mean_us,
        r.allocs_per_cycle,
        r.agent_allocs_per_cycle,
        if r.render_us.is_nan() {
            "-".to_string()
        } else {
            format!("{:.0}", r.render_us)
        },
        if r.sdk_us_per_agent_step.is_nan() {
            "-".to_string()
        } else {
            format!("{:.2}", r.sdk_us_per_agent_step)
        }
    );
    let _ = std::io::stdout().flush();
}

fn size_name(w: u32) -> &'static str {
    if w == 256 {
        return "2x256x148";
    }
    if w == 1920 {
        "3x1920x1080"
    } else {
        "3x320x240"
    }
}

fn find<'a>(rows: &'a [Row], t: &str, agents: u32, w: u32) -> Option<&'a Row> {
    rows.iter()
        .find(|r| r.transport == t && r.agents == agents && r.width == w)
}

fn print_ratios(rows: &[Row]) {
    println!("\nratios (targets in parentheses):");
    let ratio = |a: Option<&Row>, b: Option<&Row>| match (a, b) {
        (Some(a), Some(b)) if b.p50_us > 0.0 => Some(a.p50_us / b.p50_us),
        _ => None,
    };
    let line = |what: &str, v: Option<f64>, target: &str| {
        if let Some(v) = v {
            println!("  {what:<52} {v:>8.2}  ({target})");
        }
    };
    for agents in [1, 4] {
        line(
            &format!("shm / floor-shm, {agents} agent(s), 3x1920x1080"),
            ratio(
                find(rows, "shm", agents, 1920),
                find(rows, "floor-shm", agents, 1920),
            ),
            "<= 2",
        );
    }
    // Zero copy (DESIGN §9): the bridge's growth from 3x320x240 to 3x1920x1080 against
    // the floor's growth (the bench agent reads every row, so both grow with the rows).
    let shm_growth = ratio(find(rows, "shm", 1, 1920), find(rows, "shm", 1, 320));
    let floor_growth = ratio(
        find(rows, "floor-shm", 1, 1920),
        find(rows, "floor-shm", 1, 320),
    );
    line(
        "shm 3x1920x1080 / shm 3x320x240, 1 agent",
        shm_growth,
        "report",
    );
    line(
        "floor-shm 3x1920x1080 / floor-shm 3x320x240, 1 agent",
        floor_growth,
        "report",
    );
    line(
        "zero copy: shm growth / floor-shm growth, 1 agent",
        shm_growth.zip(floor_growth).map(|(s, f)| s / f),
        "<= 1.2",
    );
    for agents in [1, 4] {
        line(
            &format!("tcp / shm, {agents} agent(s), 3x1920x1080"),
            ratio(
                find(rows, "tcp", agents, 1920),
                find(rows, "shm", agents, 1920),
            ),
            if agents == 1 { ">= 200" } else { "report" },
        );
    }
    for agents in [1, 4] {
        for w in [320, 1920] {
            line(
                &format!("zenoh / floor-zenoh, {agents} agent(s), {}", size_name(w)),
                ratio(
                    find(rows, "zenoh", agents, w),
                    find(rows, "floor-zenoh", agents, w),
                ),
                "<= 1.3",
            );
            line(
                &format!("zenoh / tcp, {agents} agent(s), {}", size_name(w)),
                ratio(find(rows, "zenoh", agents, w), find(rows, "tcp", agents, w)),
                "report",
            );
            line(
                &format!("zenoh-tls / zenoh, {agents} agent(s), {}", size_name(w)),
                ratio(
                    find(rows, "zenoh-tls", agents, w),
                    find(rows, "zenoh", agents, w),
                ),
                "report",
            );
        }
    }
    for w in [320, 1920] {
        line(
            &format!("python / shm (Rust agent), 1 agent, {}", size_name(w)),
            ratio(find(rows, "python", 1, w), find(rows, "shm", 1, w)),
            "<= 2",
        );
    }
    let growth = |t: &str| ratio(find(rows, t, 1, 1920), find(rows, t, 1, 320));
    if let (Some(py), Some(rust)) = (growth("python"), growth("shm")) {
        line(
            "python 1080p/320x240 growth / Rust agent's growth",
            Some(py / rust),
            "<= 1.2",
        );
    }
    line(
        "shm 4 agents / shm 1 agent, 3x1920x1080",
        ratio(find(rows, "shm", 4, 1920), find(rows, "shm", 1, 1920)),
        "report; compare floors",
    );
    line(
        "floor-shm 4 agents / floor-shm 1 agent, 3x1920x1080",
        ratio(
            find(rows, "floor-shm", 4, 1920),
            find(rows, "floor-shm", 1, 1920),
        ),
        "report",
    );
    line(
        "shm-spin / floor-shm-spin, 1 agent, 3x1920x1080",
        ratio(
            find(rows, "shm-spin", 1, 1920),
            find(rows, "floor-shm-spin", 1, 1920),
        ),
        "<= 2",
    );
    for w in [256, 1920] {
        line(
            &format!("legacy / shm, 1 agent, {}", size_name(w)),
            ratio(find(rows, "legacy", 1, w), find(rows, "shm", 1, w)),
            "report",
        );
        if let Some(r) = find(rows, "legacy", 1, w) {
            line(
                &format!(
                    "PNG encode per image (fastest), {}x{} µs",
                    r.width, r.height
                ),
                Some(r.png_us),
                "report",
            );
        }
    }
    // The batched Python vector env: one process, one wake-up per cycle, against N Rust
    // agent processes (DESIGN §9).
    for agents in VEC_AGENTS {
        let target = |at16: &'static str| if agents == 16 { at16 } else { "report" };
        line(
            &format!("python-vec / shm (Rust agents), {agents} agents, 1x84x84"),
            ratio(
                find(rows, "python-vec", agents, VEC_SIZE),
                find(rows, "shm", agents, VEC_SIZE),
            ),
            target("<= 1.0"),
        );
        line(
            &format!("python-vec SDK µs per agent-step, {agents} agents"),
            find(rows, "python-vec", agents, VEC_SIZE).map(|r| r.sdk_us_per_agent_step),
            target("<= 5"),
        );
        line(
            &format!("shm / floor-shm, {agents} agents, 1x84x84"),
            ratio(
                find(rows, "shm", agents, VEC_SIZE),
                find(rows, "floor-shm", agents, VEC_SIZE),
            ),
            "report",
        );
    }
    let max_allocs = rows
        .iter()
        .filter(|r| r.transport.starts_with("shm"))
        .map(|r| r.allocs_per_cycle.max(r.agent_allocs_per_cycle))
        .fold(0.0, f64::max);
    println!(
        "  {:<52} {max_allocs:>8.2}  (0)",
        "max allocations per cycle on the shm path"
    );
}

fn write_csv(path: &Path, rows: &[Row]) -> anyhow::Result<()> {
    let mut s = String::from(
        "transport,agents,cameras,width,height,format,frames,p50_us,p99_us,mean_us,frames_per_s,allocs_per_cycle,agent_allocs_per_cycle,render_us,sdk_us_per_agent_step\n",
    );
    for r in rows {
        s += &format!(
            "{},{},{},{},{},{},{},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.1},{:.3}\n",
            r.transport,
            r.agents,
            r.cameras,
            r.width,
            r.height,
            r.format,
            r.frames,
            r.p50_us,
            r.p99_us,
            r.mean_us,
            r.frames_per_s,
            r.allocs_per_cycle,
            r.agent_allocs_per_cycle,
            r.render_us,
            r.sdk_us_per_agent_step
        );
    }
    std::fs::write(path, s).with_context(|| format!("write {}", path.display()))
}

fn plot(path: &Path, rows: &[Row]) -> anyhow::Result<()> {
    use plotters::prelude::*;

    let bytes =
        |r: &Row| f64::from(r.cameras) * f64::from(r.width) * f64::from(r.height) * BPP as f64;
    let (xmin, xmax) = rows
        .iter()
        .map(bytes)
        .fold((f64::MAX, 0.0f64), |(lo, hi), b| (lo.min(b), hi.max(b)));
    let (ymin, ymax) = rows
        .iter()
        .map(|r| r.p50_us)
        .fold((f64::MAX, 0.0f64), |(lo, hi), v| (lo.min(v), hi.max(v)));
    let root = SVGBackend::new(path, (900, 600)).into_drawing_area();
    root.fill(&WHITE)
        .map_err(|e| anyhow::anyhow!("plot: {e}"))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "vrsync cycle time p50 vs image bytes per agent (log-log)",
            ("sans-serif", 20),
        )
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(
            (xmin * 0.8..xmax * 1.25).log_scale(),
            (ymin.max(0.1) * 0.7..ymax * 1.5).log_scale(),
        )
        .map_err(|e| anyhow::anyhow!("plot: {e}"))?;
    chart
        .configure_mesh()
        .x_desc("image bytes per agent and cycle (rgb8)")
        .y_desc("p50 cycle time (µs)")
        .draw()
        .map_err(|e| anyhow::anyhow!("plot: {e}"))?;
    let mut series: Vec<(String, u32)> = Vec::new();
    for r in rows {
        let key = (r.transport.clone(), r.agents);
        if !series.contains(&key) {
            series.push(key);
        }
    }
    for (i, (transport, agents)) in series.iter().enumerate() {
        let mut points: Vec<(f64, f64)> = rows
            .iter()
            .filter(|r| &r.transport == transport && r.agents == *agents)
            .map(|r| (bytes(r), r.p50_us))
            .collect();
        points.sort_by(|a, b| a.0.total_cmp(&b.0));
        let color = Palette99::pick(i).to_rgba();
        let floor = transport.starts_with("floor");
        let label = format!("{transport} ×{agents}");
        let style = ShapeStyle::from(&color).stroke_width(2);
        let drawn = if floor {
            chart.draw_series(DashedLineSeries::new(points.clone(), 6, 4, style))
        } else {
            chart.draw_series(LineSeries::new(points.clone(), style))
        }
        .map_err(|e| anyhow::anyhow!("plot: {e}"))?;
        drawn
            .label(label)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color));
        chart
            .draw_series(points.iter().map(|&p| Circle::new(p, 3, color.filled())))
            .map_err(|e| anyhow::anyhow!("plot: {e}"))?;
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperLeft)
        .draw()
        .map_err(|e| anyhow::anyhow!("plot: {e}"))?;
    root.present().map_err(|e| anyhow::anyhow!("plot: {e}"))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_of_round_p50s_ignores_one_disturbed_round() {
        assert_eq!(median(&[5.0, 4.0, 400.0, 4.5, 5.5]), 5.0);
        assert_eq!(median(&[2.0, 1.0]), 1.5);
        assert!(median(&[]).is_nan());
    }

    #[test]
    fn a_row_reports_the_median_of_the_rounds_p50s() {
        let hist = |us: u64, n: u64| {
            let mut h = histogram().unwrap();
            h.record_n(us * 1000, n).unwrap();
            h
        };
        let case = Case {
            transport: "shm",
            agents: 1,
            cameras: CAMERAS,
            width: 320,
            height: 240,
            warmup: 1,
            cycles: 10,
        };
        // One slow round with many samples would own the merged histogram's p50.
        let mut m = Measured::new(hist(10, 10), 0.0, 0.0);
        m.merge(Measured::new(hist(900, 100), 0.0, 0.0)).unwrap();
        m.merge(Measured::new(hist(11, 10), 0.0, 0.0)).unwrap();
        let r = row(&case, &m);
        assert!((r.p50_us - 11.0).abs() < 0.1, "{}", r.p50_us);
        assert_eq!(r.frames, 120);
    }

    #[test]
    fn agent_reports_are_parsed_and_missing_figures_stay_nan() {
        let mut r = Reported::default();
        for line in ["checksum 123", "sdk_us_per_agent_step 3.250"] {
            r.parse_line(line);
        }
        assert_eq!(r.sdk_us_per_agent_step, 3.25);
        assert!(r.allocs_per_cycle.is_nan());
        let mut r = Reported::default();
        r.parse_line("allocs_per_cycle 1.00");
        r.parse_line("sdk_us_per_agent_step nan");
        assert_eq!(r.allocs_per_cycle, 1.0);
        assert!(r.sdk_us_per_agent_step.is_nan());
    }

    #[test]
    fn a_vector_env_row_carries_the_median_sdk_time_and_json_null_elsewhere() {
        let mut h = histogram().unwrap();
        h.record(100_000).unwrap();
        let case = Case {
            transport: "python-vec",
            agents: 16,
            cameras: 1,
            width: VEC_SIZE,
            height: VEC_SIZE,
            warmup: 1,
            cycles: 1,
        };
        let mut m = Measured::new(h.clone(), 0.0, f64::NAN);
        m.round_sdk_us = vec![4.0];
        for sdk in [40.0, 3.0] {
            let mut other = Measured::new(h.clone(), 0.0, f64::NAN);
            other.round_sdk_us = vec![sdk];
            m.merge(other).unwrap();
        }
        let r = row(&case, &m);
        assert_eq!(r.sdk_us_per_agent_step, 4.0);
        assert_eq!(r.cameras, 1);
        let json = serde_json::to_value(&r).unwrap();
        assert_eq!(json["sdk_us_per_agent_step"], 4.0);
        let shm = row(
            &Case {
                transport: "shm",
                ..case
            },
            &Measured::new(h, 0.0, 0.0),
        );
        let json = serde_json::to_value(&shm).unwrap();
        assert!(json["sdk_us_per_agent_step"].is_null());
        // DESIGN §8: the contract's keys are all there.
        for key in [
            "transport",
            "agents",
            "cameras",
            "width",
            "height",
            "format",
            "frames",
            "p50_us",
            "p99_us",
            "mean_us",
            "frames_per_s",
        ] {
            assert!(json.get(key).is_some(), "{key}");
        }
    }

    #[test]
    fn a_vector_env_case_configures_one_camera_per_agent() {
        let case = Case {
            transport: "python-vec",
            agents: 16,
            cameras: 1,
            width: VEC_SIZE,
            height: VEC_SIZE,
            warmup: 1,
            cycles: 1,
        };
        let text = config_text(&case, "bench-test-vec", Path::new("/nonexistent"));
        let config = Config::from_toml_str(&text, Path::new("<test>")).unwrap();
        assert_eq!(config.agents.len(), 16);
        assert!(config.agents.iter().all(|a| a.cameras.len() == 1));
        assert_eq!(case.frame_bytes(), 84 * 84 * 3);
    }
}
