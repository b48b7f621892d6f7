//! Raw command-line arguments (clap), merged over the TOML config in `main.rs`.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand};

use crate::render::Affinity;

/// vr-sim: a headless, deterministic simulator that drives vrsync agents in lock-step.
///
/// Exit codes: 0 success, 1 runtime failure, 2 bad usage or bad config.
/// Logging: set RUST_LOG (e.g. RUST_LOG=debug); default is info.
#[derive(Debug, Parser)]
#[command(name = "vr-sim", version, about, long_about)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// Subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run the embedded default world with example agents spawned as separate processes,
    /// show progress and print a summary. Needs no files.
    Demo(DemoArgs),
    /// Run a world from a config file, with spawned or external agents.
    Run(RunArgs),
    /// Benchmark full sync cycles over shared memory, TCP and zenoh against the raw
    /// transport floors (3 rgb8 images per agent; 1/2/4 agents; 320x240 up to 1920x1080;
    /// over shared memory also 16 and 64 agents at 84x84 and 320x240, with the time to
    /// render each cycle's images and the bridge's share of the cycle),
    /// plus the original protocol, the Python agent and the batched Python vector env
    /// (`python-vec`: one process for 4 and 16 agents of one 84x84 camera, against as many
    /// Rust agent processes and the raw floor; `python-vec-stacked`: the same with the
    /// agents' images stacked by the host and viewed without a copy; `python-loop`: the
    /// same process served by `vr-sim run`'s loop with rendering, 16 and 64 agents,
    /// against the rendering alone).
    /// Build with --release: it spawns `vr-bench-agent` from the same folder.
    Bench(BenchArgs),
    /// Replay a `run --record` file without agents: apply its commands to the world cycle
    /// by cycle as the run did, compare every agent's state after every cycle with the
    /// record and the trajectory hash at the end. Exit 0: the same trajectory; 1: it
    /// diverges (the first cycle, agent and field are named); 2: the record cannot be
    /// replayed (unreadable, malformed, truncated: no end line, or written by a vr-sim
    /// before format version 2).
    ///
    /// With --dump-frames it renders the same trajectory again, with the recorded cameras
    /// or others (--config, --camera-size), e.g. 1920x1080 for figures and videos.
    ///
    /// Limits: the world, its config and the command order come from the record only:
    /// a record is replayed by a vr-sim whose world code gives the same results (the
    /// hash check says when it does not). Images are rendered only for the agents and
    /// cycles whose sensor frame the run wrote, at the start of the cycle, as `run
    /// --dump-frames` does. A record cut short (killed run) is replayed up to where it
    /// ends and then refused (exit 2): it has no hash to check.
    Replay(ReplayArgs),
}

/// `vr-sim replay`.
#[derive(Debug, Args)]
pub struct ReplayArgs {
    /// The `vr-sim run --record` file.
    #[arg(value_name = "RECORD")]
    pub record: PathBuf,
    /// Render with the cameras of this config's `[[agent]]` entries (matched by agent id;
    /// agents it does not list keep their recorded cameras). Only the cameras are used:
    /// the world, timing and agents are the record's, and commands naming a pixel still
    /// resolve against the recorded cameras.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Render every camera at WIDTHxHEIGHT (e.g. 1920x1080). The horizontal field of view
    /// is kept; the vertical one follows the new aspect ratio (square pixels).
    #[arg(long, value_name = "WxH", value_parser = parse_size)]
    pub camera_size: Option<(u32, u32)>,
    /// Write the agents' camera images as PNG files into DIR, named as `run
    /// --dump-frames` names them (`c<cycle>_a<agent>_<camera>.png`): with the recorded
    /// cameras the files are those of the run, byte for byte.
    #[arg(long, value_name = "DIR")]
    pub dump_frames: Option<PathBuf>,
    /// With --dump-frames: write the images of every K-th cycle (0, K, 2K, ...).
    #[arg(long, value_name = "K", default_value_t = 1, requires = "dump_frames",
          value_parser = clap::value_parser!(u64).range(1..))]
    pub every: u64,
    /// Write a top-down PNG map of the replayed trajectories (as `run --map`).
    #[arg(long, value_name = "FILE.png")]
    pub map: Option<PathBuf>,
    /// Render threads, shading the rows of images of 4,096 pixels or more (1: the calling
    /// thread only; 0: one per core).
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub render_threads: usize,
    /// Bind each render thread to its own CPU. auto: when there is one per CPU (the
    /// default thread count). A kernel may otherwise run a woken render thread on the CPU
    /// of the thread that woke it while another CPU idles.
    #[arg(long, value_enum, value_name = "HOW", default_value_t = Affinity::Auto)]
    pub render_affinity: Affinity,
}

/// `WIDTHxHEIGHT`, both at least 1.
fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let bad = || format!("{s:?} is not WIDTHxHEIGHT (e.g. 1920x1080)");
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(bad)?;
    let (w, h): (u32, u32) = (w.parse().map_err(|_| bad())?, h.parse().map_err(|_| bad())?);
    if w == 0 || h == 0 || w > 16_384 || h > 16_384 {
        return Err(format!("{s}: width and height must be within 1..=16384"));
    }
    Ok((w, h))
}

/// `vr-sim bench`.
#[derive(Debug, Args)]
pub struct BenchArgs {
    /// Fewer cycles, 320x240 and 1920x1080 only, 1 and 4 agents; 16 and 64 agents at
    /// 84x84 only (about two minutes on 2 cores).
    #[arg(long)]
    pub quick: bool,
    /// Write the rows as a JSON array.
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    /// Write the rows as CSV.
    #[arg(long, value_name = "FILE")]
    pub csv: Option<PathBuf>,
    /// Plot p50 cycle time vs image bytes (log-log, SVG; floors dashed).
    #[arg(long, value_name = "FILE.svg")]
    pub plot: Option<PathBuf>,
    /// Python interpreter for the `python` rows (`python -m vrsync.bench_agent`, the
    /// Python SDK doing the Rust bench agent's work; beside them `floor-numpy`, `python -m
    /// vrsync.bench_numpy`: the same row reads by numpy alone on shared memory, no SDK),
    /// the vector-env rows (`python -m vrsync.bench_vector`: one process steps every
    /// agent through one `AgentGroup`; the row also reports the SDK's time per
    /// agent-step; `python-loop`: that process served by `vr-sim run`'s loop, rendering)
    /// and the `python-host` rows
    /// (`python -m vrsync.bench_host`: `vrsync.Host` serving the Rust bench agents; the
    /// row reports the host's own time per agent-cycle); rows are left out, saying why,
    /// when it cannot import vrsync (`pip install ./agent-sdk/python`).
    #[arg(
        long,
        value_name = "PYTHON",
        env = "VRSYNC_PYTHON",
        default_value = "python3"
    )]
    pub python: PathBuf,
    /// Leave out the Python rows (`python`, `floor-numpy`, and the vector-env section:
    /// `python-vec` and `python-vec-stacked` with their `shm` and `floor-shm` rows at
    /// 1x84x84, `python-host`, `python-loop`).
    #[arg(long)]
    pub no_python: bool,
    /// Run only these sections (repeatable; default all): `images` (every transport at 1
    /// and 4 agents), `many` (16 and 64 agents over shm), `vector` (the vector env, the
    /// Python host, the whole loop with rendering), `original` (the original protocol).
    #[arg(long, value_name = "SECTION")]
    pub only: Vec<crate::bench::Section>,
}

/// `vr-sim demo`.
#[derive(Debug, Args)]
pub struct DemoArgs {
    /// Number of cycles.
    #[arg(long, value_name = "N", default_value_t = 300)]
    pub frames: u64,
    /// Number of agents (each a `vr-agent --policy wander` process).
    #[arg(long, value_name = "N", default_value_t = 2)]
    pub agents: u32,
    /// Folder for the demo's outputs: effective config, summary, recording, map.png and
    /// a few camera frames in frames/.
    #[arg(long, value_name = "DIR", default_value = "vrsync-demo")]
    pub out: PathBuf,
    /// Policy of the example agents: wander (walk, turn away after collisions), seek (find
    /// the red object with the eyes and walk to it), idle, circle.
    #[arg(long, value_name = "NAME", default_value = "wander",
          value_parser = ["wander", "seek", "idle", "circle"])]
    pub policy: String,
    /// Render threads: the images of every agent at once (of up to 8 agents per thread
    /// when there are fewer threads than CPUs), and the rows of large images (1: the host
    /// thread only; 0: one per core).
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub render_threads: usize,
    /// Bind each render thread to its own CPU. auto: when there is one per CPU (the
    /// default thread count). A kernel may otherwise run a woken render thread on the CPU
    /// of the thread that woke it while another CPU idles.
    #[arg(long, value_enum, value_name = "HOW", default_value_t = Affinity::Auto)]
    pub render_affinity: Affinity,
}

/// `vr-sim run`.
#[derive(Debug, Args)]
#[command(group(clap::ArgGroup::new("rerun_sink").args(["rerun", "rrd"]).multiple(true)))]
pub struct RunArgs {
    /// Config file (see config/default.toml for every key).
    #[arg(long, value_name = "FILE")]
    pub config: PathBuf,
    /// Stop after N cycles (default: run until Ctrl-C).
    #[arg(long, value_name = "N")]
    pub frames: Option<u64>,
    /// Start N `vr-agent` processes (ids 0..N, found next to this executable) and reap
    /// them at the end. Resizes the config's agent list to N. Without it, vr-sim waits for
    /// external agents and says which it waits for.
    #[arg(long, value_name = "N")]
    pub spawn_agents: Option<u32>,
    /// Extra argument for every spawned agent (repeatable), e.g. --agent-arg=--jitter-ms
    /// --agent-arg=20.
    #[arg(long, value_name = "ARG", allow_hyphen_values = true)]
    pub agent_arg: Vec<String>,
    /// Override the config's session name.
    #[arg(long, value_name = "NAME")]
    pub session: Option<String>,
    /// Write one JSON line per agent per cycle (cycle, sim time, pose, commands, statuses).
    #[arg(long, value_name = "FILE")]
    pub record: Option<PathBuf>,
    /// Write the run summary as JSON.
    #[arg(long, value_name = "FILE")]
    pub summary_json: Option<PathBuf>,
    /// Write what happens, one JSON object per line, flushed as it happens (for tests and
    /// tooling, instead of log text). Each line has "event" and "wall_s" (seconds since
    /// start); events: listening (session, transport, address: the bound TCP address, so
    /// tcp_listen port 0 works), waiting_for_agents (agents), agent_connected (agent,
    /// cycle), all_agents_connected (agents), agent_left, agent_rejoined (agent, cycle),
    /// agent_evicted (agent, cycle, reason), peer_refused (kind, agent, peer, reason: a
    /// connection refused before it was admitted), command_rejected (agent, cycle, kind, reason;
    /// first per agent and kind), cycle (cycle, timed_out_agents, late_batches; only cycle
    /// 0, every 1000th and those where something happened), finished (frames,
    /// interrupted, trajectory_hash, summary) or error (message).
    #[arg(long, value_name = "FILE")]
    pub events: Option<PathBuf>,
    /// Write a top-down PNG map of the room at the end: every agent's trajectory with start
    /// and end markers, labelled goals and objects, a legend and a scale bar in metres.
    #[arg(long, value_name = "FILE.png")]
    pub map: Option<PathBuf>,
    /// Write the agents' camera images as PNG files into DIR
    /// (`c<cycle>_a<agent>_<camera>.png`; depth as 16-bit millimetres).
    #[arg(long, value_name = "DIR")]
    pub dump_frames: Option<PathBuf>,
    /// With --dump-frames: write the images of every K-th cycle (0, K, 2K, ...).
    #[arg(long, value_name = "K", default_value_t = 1, requires = "dump_frames",
          value_parser = clap::value_parser!(u64).range(1..))]
    pub every: u64,
    /// Render threads: the images of every agent at once (of up to 8 agents per thread
    /// when there are fewer threads than CPUs; rendered, then published in agent order),
    /// and the rows of large images (1: the host thread only; 0: one per core). The
    /// images do not depend on it.
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub render_threads: usize,
    /// Bind each render thread to its own CPU. auto: when there is one per CPU (the
    /// default thread count). A kernel may otherwise run a woken render thread on the CPU
    /// of the thread that woke it while another CPU idles.
    #[arg(long, value_enum, value_name = "HOW", default_value_t = Affinity::Auto)]
    pub render_affinity: Affinity,
    /// Show the run live in a Rerun viewer: the one listening on port 9876, else a new
    /// `rerun` process from PATH (`pip install rerun-sdk==0.36.3` installs it). Logged:
    /// every agent's camera images, its body, eyes (camera frustums) and trajectory in the
    /// 3D room (walls, objects, goals), its commands and action statuses, collisions and
    /// rewards; the host's wait per cycle and stop timeouts; timelines `cycle` and
    /// `sim_time` (README: "Live view and recording in Rerun"). Needs a vr-sim built with
    /// the `rerun` cargo feature (else exit 2).
    #[arg(long)]
    pub rerun: bool,
    /// Save the same Rerun log as a recording (`rerun FILE.rrd` opens it; the Python
    /// `rerun-sdk` reads it). With --rerun: both. Needs the `rerun` feature (else exit 2).
    #[arg(long, value_name = "FILE.rrd")]
    pub rrd: Option<PathBuf>,
    /// With --rerun/--rrd: log the camera images of every N-th cycle only (0, N, 2N, ...),
    /// for long runs; poses, text and scalars are logged every cycle.
    #[arg(long, value_name = "N", default_value_t = 1, requires = "rerun_sink",
          value_parser = clap::value_parser!(u64).range(1..))]
    pub rerun_every: u64,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
}
