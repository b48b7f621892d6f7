//! `vr-bench-agent`: the minimal agent `vr-sim bench` spawns. Each cycle it touches every
//! image (reads the first and last byte of every row), sends one command and stops. With
//! `--mode floor-shm|floor-tcp` it is the agent side of the raw transport floors instead.
//! At the end it prints `allocs_per_cycle <n>` measured after the warm-up cycles.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::{Context, bail};
use clap::{Parser, ValueEnum};
use vrsync_agent::{AgentBuilder, Command, SignalHandling, StopError, WaitStartError};
use vrsync_alloc_count::{CountingAlloc, allocations};
use vrsync_floor::{
    ShmFloorAgentOptions, shm_floor_agent, tcp_floor_agent, touch_rows, zenoh_floor_agent,
};
use vrsync_transport::Config;

#[global_allocator]
static ALLOC: CountingAlloc = CountingAlloc;

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum Mode {
    /// The vrsync agent SDK over the config's transport.
    Sdk,
    /// Raw iceoryx2 round trip.
    FloorShm,
    /// Raw TCP round trip.
    FloorTcp,
    /// Raw zenoh round trip.
    FloorZenoh,
}

/// Benchmark agent for `vr-sim bench` (not meant to be started by hand).
#[derive(Debug, Parser)]
#[command(name = "vr-bench-agent", version, about)]
struct Args {
    #[arg(long, value_enum, default_value = "sdk")]
    mode: Mode,
    /// Config file (sdk mode).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Agent id.
    #[arg(long, default_value_t = 0)]
    id: u32,
    /// Cycles to run (floors), warm-up included.
    #[arg(long, default_value_t = 0)]
    cycles: u64,
    /// Cycles not counted for allocations.
    #[arg(long, default_value_t = 0)]
    warmup: u64,
    /// Floor session (floor-shm, floor-zenoh).
    #[arg(long, default_value = "")]
    session: String,
    /// Host address (floor-tcp).
    #[arg(long)]
    addr: Option<SocketAddr>,
    /// The host's zenoh endpoint (floor-zenoh).
    #[arg(long, default_value = "")]
    endpoint: String,
    /// Bytes per frame (floors).
    #[arg(long, default_value_t = 0)]
    frame_bytes: usize,
    /// Bytes per image row (floors).
    #[arg(long, default_value_t = 0)]
    row_bytes: usize,
    /// Busy-poll (floor-shm).
    #[arg(long)]
    spin: bool,
    /// Poll this long before sleeping (floor-shm), µs.
    #[arg(long, default_value_t = 0)]
    spin_before_block_us: u64,
}

fn main() -> ExitCode {
    let args = match Args::try_parse() {
        Ok(a) => a,
        Err(e) => {
            let _ = e.print();
            return ExitCode::from(2);
        }
    };
    match run(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("vr-bench-agent {}: error: {e:#}", args.id);
            ExitCode::from(1)
        }
    }
}

fn run(args: &Args) -> anyhow::Result<()> {
    let timeout = Duration::from_secs(60);
    match args.mode {
        Mode::FloorShm => {
            let r = shm_floor_agent(
                &args.session,
                args.id,
                &ShmFloorAgentOptions {
                    cycles: args.cycles,
                    warmup: args.warmup,
                    row_len: args.row_bytes,
                    spin: args.spin,
                    spin_before_block: Duration::from_micros(args.spin_before_block_us),
                    timeout,
                },
            )?;
            println!("allocs_per_cycle {}", r.allocs_per_cycle);
            Ok(())
        }
        Mode::FloorTcp => {
            let addr = args.addr.context("--addr is required for floor-tcp")?;
            let r = tcp_floor_agent(
                addr,
                args.frame_bytes,
                args.cycles,
                args.warmup,
                args.row_bytes,
                timeout,
            )?;
            println!("allocs_per_cycle {}", r.allocs_per_cycle);
            Ok(())
        }
        Mode::FloorZenoh => {
            let r = zenoh_floor_agent(
                &args.session,
                &args.endpoint,
                args.id,
                args.cycles,
                args.warmup,
                args.row_bytes,
                timeout,
            )?;
            println!("allocs_per_cycle {}", r.allocs_per_cycle);
            Ok(())
        }
        Mode::Sdk => sdk(args, timeout),
    }
}

fn sdk(args: &Args, timeout: Duration) -> anyhow::Result<()> {
    let path = args
        .config
        .as_ref()
        .context("--config is required in sdk mode")?;
    let config = Config::load(path)?;
    let mut agent = AgentBuilder::new(&config, args.id)
        .signal_handling(SignalHandling::Install)
        .connect()?;
    let mut cycles = 0u64;
    let mut allocs_at_warmup = None;
    let mut sum = 0u64;
    loop {
        if cycles == args.warmup {
            allocs_at_warmup = Some((allocations(), cycles));
        }
        let frame = match agent.wait_start(Some(timeout)) {
            Ok(f) => f,
            Err(WaitStartError::HostClosed) => break,
            Err(e) => bail!("wait_start: {e}"),
        };
        for image in frame.images() {
            sum = sum.wrapping_add(touch_rows(image.data(), image.stride()));
        }
        drop(frame);
        agent.send(Command::Turn { angle_deg: 1.0 })?;
        match agent.stop() {
            Ok(()) => {}
            Err(StopError::HostClosed) => break,
            Err(e) => bail!("stop: {e}"),
        }
        cycles += 1;
    }
    std::hint::black_box(sum);
    let per_cycle = match allocs_at_warmup {
        Some((a, c)) if cycles > c => (allocations() - a) as f64 / (cycles - c) as f64,
        _ => 0.0,
    };
    println!("allocs_per_cycle {per_cycle}");
    Ok(())
}
