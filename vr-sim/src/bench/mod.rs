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
use vrsync_alloc_count::allocations;
use vrsync_bridge::{Config, Host, SignalHandling};
use vrsync_floor::{ShmFloorHost, TcpFloorHost, ZenohFloorHost};

mod floor;
mod legacy;
mod report;
mod vrsync;
mod world_loop;

use floor::{bench_floor_numpy, bench_floor_shm, bench_floor_tcp, bench_floor_zenoh};
use report::{plot, print_header, print_ratios, print_row, write_csv};
use vrsync::{bench_python_host, bench_vrsync, make_certificates, python_agent};
use world_loop::bench_python_loop;

/// What to run and where to write.
#[derive(Debug)]
pub struct BenchOptions {
    /// Fewer cycles, 320×240 and 1920×1080 only, agents 1 and 4; 16 and 64 agents at
    /// 84×84 only.
    pub quick: bool,
    /// JSON output.
    pub json: Option<PathBuf>,
    /// CSV output.
    pub csv: Option<PathBuf>,
    /// SVG plot.
    pub plot: Option<PathBuf>,
    /// Python interpreter for the `python` rows (the agent is `python -m
    /// vrsync.bench_agent`), the vector-env rows (`python -m vrsync.bench_vector`) and the
    /// Python host rows (`python -m vrsync.bench_host`), the numpy floor (`python -m
    /// vrsync.bench_numpy`); `None`: no Python rows.
    pub python: Option<PathBuf>,
    /// The sections to run (empty: all).
    pub only: Vec<Section>,
}

/// A section of the benchmark (`--only`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Section {
    /// Every transport and its floor at 1 and 4 agents, per image size.
    Images,
    /// 16 and 64 agents over shm against the floor.
    Many,
    /// The Python vector env, the Python host and the whole loop with rendering (with
    /// `--python`).
    Vector,
    /// The original protocol.
    Original,
}

/// One measured configuration (DESIGN §8 bench JSON keys, plus allocations).
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    /// `shm`, `shm-spin`, `tcp`, `zenoh`, `zenoh-tls` (mutual TLS), `mixed` (agents over
    /// shm, shm, tcp, zenoh), `floor-shm`, `floor-shm-spin`, `floor-tcp`, `floor-zenoh`,
    /// `legacy`, `python`, `python-vec`, `python-vec-stacked` (the same vector env, the
    /// host stacking the agents' images: `[transport.shm] stacked_images`, viewed with no
    /// copy), `python-host` (the host is a Python process,
    /// `vrsync.Host`; the agents are the `shm` rows' Rust bench agents), `python-loop`
    /// (`vr-sim run`'s loop, rendering, serving one `python-vec` process), `floor-numpy`
    /// (numpy's row reads of the `python` agent alone, on shared memory, no SDK).
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
    /// Host allocations per cycle in steady state (`null` for `python-host`: a Python
    /// host's allocations are not counted).
    pub allocs_per_cycle: f64,
    /// Agent allocations per cycle in steady state (mean over agents).
    pub agent_allocs_per_cycle: f64,
    /// Time vr-sim's renderer (one thread per core) needs for the images of one cycle,
    /// every agent's, µs: what a simulator adds to each cycle (measured separately, before
    /// the agents start, not part of the cycle; `null` on floor rows and where not
    /// measured).
    pub render_us: f64,
    /// `legacy` rows: time to PNG-encode one of these images at the fastest level, µs
    /// (measured separately; `null` elsewhere).
    pub png_us: f64,
    /// The Python SDK's own time per agent and cycle, µs (median of the rounds; `null`
    /// elsewhere). `python-vec` (and `python-vec-stacked`) rows: the time per agent-step
    /// spent inside the Python SDK's Rust code (`AgentGroup.step`: sends, stops,
    /// receives, copies or views; blocked waits for the host excluded), as the agent
    /// process reports it. `python-host` rows: the
    /// Python host's time per agent-cycle outside `Host.collect` (loans, one byte written
    /// per image, publishes, `start`, the report's check: everything but the wait for
    /// the agents), as `vrsync.bench_host` reports it (its `host_us_per_agent_cycle`):
    /// wall time, so with more agents than cores it also holds the agents that `start`
    /// woke and that took the cores before it returned.
    pub sdk_us_per_agent_step: f64,
    /// `python-loop` rows: the loop's time per cycle writing sensors and rendering
    /// (mean, median of the rounds; beside `render_us`, the same images rendered with no
    /// agent process running). `null` elsewhere.
    pub loop_render_us: f64,
    /// `python-loop` rows: the rest of frame 1 per cycle (the agents' connections, the
    /// loans, publishing, start; mean, median of the rounds). `null` elsewhere.
    pub loop_publish_us: f64,
    /// `python-loop` rows: the loop's time per cycle waiting for every agent's stop
    /// (`Host::collect`: the Python process's step, its wake-up and the host's; mean,
    /// median of the rounds). `null` elsewhere.
    pub loop_wait_us: f64,
    /// `python-loop` rows: the rest of frame 2 per cycle (applying the commands, the
    /// world's step, the trajectory hash; mean, median of the rounds). `null` elsewhere.
    pub loop_rest_us: f64,
    /// `python-host` rows: the Python host thread's CPU time per agent-cycle in the same
    /// parts of the cycle, µs (median of the rounds; `vrsync.bench_host`'s
    /// `host_cpu_us_per_agent_cycle`): the host's own cost, DESIGN §9's target. `null`
    /// elsewhere.
    pub host_cpu_us_per_agent_cycle: f64,
}

const CAMERAS: u32 = 3;
/// The vector-env and Python host rows: one camera of this size (rgb8) per agent, at these
/// agent counts.
const VEC_SIZE: u32 = 84;
const VEC_AGENTS: [u32; 2] = [4, 16];
/// The whole-loop rows (`python-loop`, one 84x84 rgb8 camera per agent): these agent
/// counts.
const LOOP_AGENTS: [u32; 2] = [16, 64];
/// The many-agent rows (3 rgb8 images per agent, against the raw floor at the same
/// fan-out): these agent counts at these image sizes.
const MANY_AGENTS: [u32; 2] = [16, 64];
const MANY_SIZES: [(u32, u32); 2] = [(84, 84), (320, 240)];
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
            "cannot find {} (build it with `cargo build --release -p vrsync-agent-bin`)",
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
    /// The Python host's CPU time per agent-cycle of each round that reports it, µs.
    round_host_cpu_us: Vec<f64>,
    /// Each round's render time alone (rows that measure it every round), µs.
    round_render_us: Vec<f64>,
    /// `python-loop`: each round's mean time per cycle rendering in the loop, µs.
    round_loop_render_us: Vec<f64>,
    /// `python-loop`: each round's mean time per cycle in the rest of frame 1, µs.
    round_loop_publish_us: Vec<f64>,
    /// `python-loop`: each round's mean wait per cycle for the agents, µs.
    round_loop_wait_us: Vec<f64>,
    /// `python-loop`: each round's mean time per cycle in the rest of frame 2, µs.
    round_loop_rest_us: Vec<f64>,
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
            round_host_cpu_us: Vec::new(),
            round_render_us: Vec::new(),
            round_loop_render_us: Vec::new(),
            round_loop_publish_us: Vec::new(),
            round_loop_wait_us: Vec::new(),
            round_loop_rest_us: Vec::new(),
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
        self.round_host_cpu_us.extend(other.round_host_cpu_us);
        self.round_render_us.extend(other.round_render_us);
        self.round_loop_render_us.extend(other.round_loop_render_us);
        self.round_loop_publish_us
            .extend(other.round_loop_publish_us);
        self.round_loop_wait_us.extend(other.round_loop_wait_us);
        self.round_loop_rest_us.extend(other.round_loop_rest_us);
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
        // Measured every round (`python-loop`): the median; else the one measurement.
        render_us: if m.round_render_us.is_empty() {
            m.render_us
        } else {
            median(&m.round_render_us)
        },
        png_us: m.png_us,
        sdk_us_per_agent_step: median(&m.round_sdk_us),
        loop_render_us: median(&m.round_loop_render_us),
        loop_publish_us: median(&m.round_loop_publish_us),
        loop_wait_us: median(&m.round_loop_wait_us),
        loop_rest_us: median(&m.round_loop_rest_us),
        host_cpu_us_per_agent_cycle: median(&m.round_host_cpu_us),
    }
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
    println!(
        "vr-sim bench{}: 3 rgb8 images per agent (vector-env rows: one 84x84); cycle = host \
         publish -> every agent stopped",
        if opts.quick { " --quick" } else { "" }
    );
    print_header();
    let mut bench = Bench {
        quick: opts.quick,
        dir: dir.path(),
        python: python.as_deref(),
        sessions: 0,
    };
    let mut rows = Vec::new();
    let runs = |s: Section| opts.only.is_empty() || opts.only.contains(&s);
    if runs(Section::Images) {
        bench.image_sets(&mut rows)?;
    }
    if runs(Section::Many) {
        bench.many_agents(&mut rows)?;
    }
    if runs(Section::Vector) {
        bench.vector_env(&mut rows)?;
    }
    if runs(Section::Original) {
        bench.original_protocol(&mut rows)?;
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

/// What every part of a bench run shares.
struct Bench<'a> {
    quick: bool,
    /// The private temp dir of the configs and the zenoh-tls certificates.
    dir: &'a Path,
    /// The interpreter for the Python rows, if they run.
    python: Option<&'a Path>,
    /// Sessions named so far (each measurement gets its own).
    sessions: u32,
}

impl Bench<'_> {
    fn session(&mut self) -> String {
        self.sessions += 1;
        format!("bench-{}-{}", std::process::id(), self.sessions)
    }

    /// Cycles of an shm case.
    fn shm_cycles(&self) -> u64 {
        if self.quick { 400 } else { 3000 }
    }

    /// Every transport and its floor at 3 images per agent, per image size and agent
    /// count.
    fn image_sets(&mut self, rows: &mut Vec<Row>) -> anyhow::Result<()> {
        let sets: &[(u32, u32)] = if self.quick {
            &[(320, 240), (1920, 1080)]
        } else {
            &[(320, 240), (640, 480), (1280, 720), (1920, 1080)]
        };
        let agent_counts: &[u32] = if self.quick { &[1, 4] } else { &[1, 2, 4] };
        let shm_cycles = self.shm_cycles();
        for &(w, h) in sets {
            let bytes = CAMERAS as u64 * u64::from(w) * u64::from(h) * BPP as u64;
            // TCP moves every byte: size the run by volume (~1.5 GB quick, ~6 GB full).
            let volume: u64 = if self.quick {
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
                // Spinning needs a free core per waiting process: 1 agent + the host on 2
                // cores.
                if agents == 1 {
                    cases.push(mk("shm-spin", shm_cycles));
                    cases.push(mk("floor-shm-spin", shm_cycles));
                }
                for t in ["tcp", "floor-tcp", "zenoh", "zenoh-tls", "floor-zenoh"] {
                    cases.push(mk(t, tcp_cycles));
                }
                // One host mixing transports (2 shm, 1 tcp, 1 zenoh agents): its one wait
                // over every transport against the single-transport rows.
                if agents == 4 {
                    cases.push(mk("mixed", tcp_cycles));
                }
                // The Python agent (1 agent, the smallest and the largest image set), and
                // numpy's share of it: its row reads alone, on shared memory, no SDK.
                if self.python.is_some() && agents == 1 && (w == 320 || w == 1920) {
                    cases.push(mk("python", shm_cycles));
                    cases.push(mk("floor-numpy", shm_cycles));
                }
                measure_interleaved(&cases, rows, |case, round| match case.transport {
                    "floor-shm" => bench_floor_shm(case, &self.session(), false),
                    "floor-shm-spin" => bench_floor_shm(case, &self.session(), true),
                    "floor-tcp" => bench_floor_tcp(case),
                    "floor-zenoh" => bench_floor_zenoh(case, &self.session()),
                    "floor-numpy" => match self.python {
                        Some(python) => bench_floor_numpy(case, &self.session(), self.dir, python),
                        None => bail!("floor-numpy needs --python"),
                    },
                    _ => {
                        let session = self.session();
                        bench_vrsync(case, &session, self.dir, round == 0, self.python)
                    }
                })?;
            }
        }
        Ok(())
    }

    /// Many agents on one host: 16 and 64 Rust bench agents of 3 images each (84x84, and
    /// 320x240 unless quick) over shm against the raw iceoryx2 floor at the same fan-out;
    /// the shm row also carries the time vr-sim needs to render that cycle's images, so
    /// the table shows the bridge's share of a simulated cycle.
    fn many_agents(&mut self, rows: &mut Vec<Row>) -> anyhow::Result<()> {
        let sizes = if self.quick {
            &MANY_SIZES[..1]
        } else {
            &MANY_SIZES[..]
        };
        // 200 measured cycles per round even when quick: with 64 agent processes on two
        // cores a cycle's time depends on the order the scheduler runs them in, and the
        // p50 of 50 cycles moved by a third between runs.
        let cycles = if self.quick { 1000 } else { 1500 };
        for &(w, h) in sizes {
            for agents in MANY_AGENTS {
                let mk = |transport: &'static str| Case {
                    transport,
                    agents,
                    cameras: CAMERAS,
                    width: w,
                    height: h,
                    warmup: (cycles / ROUNDS / 10).max(10),
                    cycles: (cycles / ROUNDS).max(10),
                };
                let cases = [mk("shm"), mk("floor-shm")];
                measure_interleaved(&cases, rows, |case, round| match case.transport {
                    "floor-shm" => bench_floor_shm(case, &self.session(), false),
                    _ => {
                        let session = self.session();
                        bench_vrsync(case, &session, self.dir, round == 0, None)
                    }
                })?;
            }
        }
        Ok(())
    }

    /// The batched Python vector env (one process for every agent) against the same
    /// fan-out of Rust bench agents and of the raw iceoryx2 floor: one 84x84 rgb8 camera
    /// per agent (an RL observation), 4 and 16 agents. In the same rounds the Python host
    /// (`python-host`: `vrsync.Host` in a Python process) serves the `shm` row's Rust
    /// bench agents: the Python host against the Rust host. Then the whole loop
    /// (`python-loop`, 16 and 64 agents): `vr-sim run`'s loop rendering the images for
    /// the vector env, against the rendering alone.
    fn vector_env(&mut self, rows: &mut Vec<Row>) -> anyhow::Result<()> {
        let Some(python) = self.python else {
            return Ok(());
        };
        for agents in VEC_AGENTS {
            let cases = vector_env_cases(agents, self.quick);
            measure_interleaved(&cases, rows, |case, _round| match case.transport {
                "floor-shm" => bench_floor_shm(case, &self.session(), false),
                "python-host" => bench_python_host(case, &self.session(), self.dir, python),
                _ => {
                    let session = self.session();
                    bench_vrsync(case, &session, self.dir, false, Some(python))
                }
            })?;
        }
        // The whole loop with rendering: `vr-sim run`'s loop serving the vector env,
        // against the same renderer alone in the same round.
        for agents in LOOP_AGENTS {
            let case = loop_case(agents, self.quick);
            measure_interleaved(&[case], rows, |case, _round| {
                let session = self.session();
                bench_python_loop(case, &session, self.dir, python)
            })?;
        }
        Ok(())
    }

    /// The original protocol (1 agent): PNG over TCP, one socket per agent, at the
    /// original's stereo 256x148 (with an shm row of the same images) and at 3x1920x1080
    /// (against the shm row of [`Bench::image_sets`]).
    fn original_protocol(&mut self, rows: &mut Vec<Row>) -> anyhow::Result<()> {
        let shm_cycles = self.shm_cycles();
        for (w, h, cameras, cycles) in [
            (256, 148, 2, if self.quick { 250 } else { 1000 }),
            (1920, 1080, 3, if self.quick { 25 } else { 60 }),
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
            measure_interleaved(&cases, rows, |case, round| match case.transport {
                "legacy" => legacy::bench_legacy(case, &self.session(), round == 0),
                _ => {
                    let session = self.session();
                    bench_vrsync(case, &session, self.dir, round == 0, None)
                }
            })?;
        }
        Ok(())
    }
}

/// The cases of [`Bench::vector_env`] at `agents` agents, one 84x84 rgb8 camera each, in
/// the order of each round: the vector env (its images copied into the stacked arrays,
/// then `python-vec-stacked`: the host stacks them, `[transport.shm] stacked_images`, and
/// the env views them with no copy), the Python host, the Rust host (`shm`, the
/// reference of all) and the raw floor.
fn vector_env_cases(agents: u32, quick: bool) -> Vec<Case> {
    [
        "python-vec",
        "python-vec-stacked",
        "python-host",
        "shm",
        "floor-shm",
    ]
    .into_iter()
    .map(|transport| vec_case(transport, agents, quick))
    .collect()
}

/// A case of the vector-env section (`python-loop` too): `agents` agents of one 84x84
/// rgb8 camera each.
fn vec_case(transport: &'static str, agents: u32, quick: bool) -> Case {
    let cycles = if quick { 600 } else { 3000 };
    Case {
        transport,
        agents,
        cameras: 1,
        width: VEC_SIZE,
        height: VEC_SIZE,
        // Enough for the Python process to reach its steady state (first-touch page
        // faults, numpy's caches) before the host measures.
        warmup: (cycles / ROUNDS / 10).max(20),
        cycles: (cycles / ROUNDS).max(10),
    }
}

/// A `python-loop` case: as [`vec_case`], with more cycles in a quick run (400 measured
/// per round): a 16-agent cycle takes well under a millisecond, so 120 of them (a quick
/// vector case's round) last under a tenth of a second, short enough for a burst of
/// another process's work to move the round's p50.
fn loop_case(agents: u32, quick: bool) -> Case {
    let mut case = vec_case("python-loop", agents, quick);
    if quick {
        case.warmup = 40;
        case.cycles = 400;
    }
    case
}

/// The one measurement loop of every row (vrsync and floors): runs `cycle` for the warm-up and measured
/// cycles of `case` and returns the histogram of the measured cycles' round trips (ns) and
/// the host's allocations per measured cycle.
fn measure_loop(
    case: &Case,
    mut cycle: impl FnMut(u64) -> anyhow::Result<()>,
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

#[cfg(test)]
mod tests;
