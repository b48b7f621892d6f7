//! `vr-agent`: the example agent. Connects to a vrsync host and runs a policy.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::Context;
use clap::Parser;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tracing::{info, warn};
use vrsync_agent::{Agent, AgentBuilder, SignalHandling, StopError, WaitStartError};
use vrsync_agent_bin::policy::{Policy, PolicyKind};
use vrsync_transport::Config;

/// Example vrsync agent: waits for each cycle's start, reads its sensor frame from shared
/// memory, sends motor commands chosen by a policy, and stops.
///
/// Exit codes: 0 when the host closed the session (or --frames were done), 1 on a runtime
/// failure (host died, no start within the timeout, protocol mismatch), 2 on bad usage or
/// a bad config.
#[derive(Debug, Parser)]
#[command(name = "vr-agent", version, about, long_about)]
struct Args {
    /// Config file (the same the host uses: session and transport are read from it).
    #[arg(long, value_name = "FILE")]
    config: PathBuf,
    /// Agent id (0..=250).
    #[arg(long, value_name = "N")]
    id: u32,
    /// What the agent does.
    ///
    /// `wander` and `seek` run one action at a time: they send the next command when a frame
    /// reports the running action `Finished` or `Aborted` (or a collision), or after 30
    /// cycles without such a status (20 for a search turn of `seek`). A host that reports no
    /// action statuses therefore gets one command per agent every 30 cycles. `circle` sends
    /// a command every cycle, `idle` none.
    #[arg(long, value_enum, default_value = "wander")]
    policy: PolicyKind,
    /// Sleep a random 0..=MAX ms each cycle before stopping (simulated compute time, for
    /// determinism tests). Drawn from a generator separate from the policy's.
    #[arg(long, value_name = "MAX", default_value_t = 0)]
    jitter_ms: u64,
    /// Seed of the policy (default: the config's `seed`).
    #[arg(long, value_name = "S")]
    seed: Option<u64>,
    /// Leave after this many cycles (default: run until the host closes the session).
    #[arg(long, value_name = "N")]
    frames: Option<u64>,
    /// Give up when no start arrives for this many seconds. Default: no limit when the
    /// host may wait for a busy agent (sync mode with some agent's `wait_for_stop =
    /// "alive"`, the default: another agent may compute for longer than any fixed limit;
    /// a dead host is still noticed), else stop_timeout + connect_timeout of the config.
    #[arg(long, value_name = "SECONDS")]
    start_timeout: Option<f64>,
    /// Write one line per cycle to FILE: `cycle sim_time_ns skipped action_ids` (action ids
    /// of the commands sent in that cycle, comma-separated). `{id}` in FILE is replaced by
    /// the agent id, so spawned agents can share one --agent-arg.
    #[arg(long, value_name = "FILE")]
    log_cycles: Option<PathBuf>,
    /// Write one line per action status and collision the frames bring (each once, also
    /// those of skipped frames) to FILE: `CYCLE status ACTION_ID STATE SEQ` or `CYCLE
    /// collision ACTION_ID COLLIDER_ID SEQ` (STATE: 0 in execution, 1 finished, 2 aborted,
    /// 3 walking, 4 rotating, 5 walking and rotating). `{id}` as in --log-cycles.
    #[arg(long, value_name = "FILE")]
    log_events: Option<PathBuf>,
    /// Testing aid: before the policy's commands, send four invalid ones every cycle (NaN
    /// distance, distance out of range, unknown object id, unknown command kind), all with
    /// action id 4294967295; the host must reject them and leave the world untouched.
    #[arg(long, hide = true)]
    bad_commands: bool,
    /// Testing aid: in this cycle, compute for 1.5 × the config's stop_timeout before
    /// stopping. With `wait_for_stop = "timeout"` the host times out and the stop arrives
    /// late, with half a timeout left to answer the next cycle in time; with `"alive"` the
    /// host waits and reports the agent slow.
    #[arg(long, value_name = "CYCLE", hide = true)]
    late_stop_at: Option<u64>,
    /// Testing aid: with --late-stop-at, be late for N cycles instead of one (compute for
    /// N + 0.5 stop timeouts), so with `wait_for_stop = "timeout"` the frames of N - 1
    /// cycles are skipped.
    #[arg(long, value_name = "N", hide = true, default_value_t = 1)]
    late_stop_cycles: u32,
    /// Testing aid: after stopping each of these cycles (comma-separated), stop this
    /// process (SIGSTOP to itself) until something continues it (SIGCONT): frozen at a
    /// known cycle, as a debugger or an overloaded machine freezes it.
    #[arg(long, value_name = "CYCLE", value_delimiter = ',', hide = true)]
    sigstop_after: Vec<u64>,
}

fn main() -> ExitCode {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| {
                tracing_subscriber::EnvFilter::new(vrsync_agent::log::default_log_filter("info"))
            }),
        )
        .with_writer(std::io::stderr)
        .with_ansi(vrsync_agent::log::ansi_on_stderr())
        .init();
    let args = match Args::try_parse() {
        Ok(a) => a,
        Err(e) => {
            let _ = e.print();
            return if e.use_stderr() {
                ExitCode::from(2)
            } else {
                ExitCode::SUCCESS
            };
        }
    };
    match run(&args) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("vr-agent {}: error: {e:#}", args.id);
            ExitCode::from(1)
        }
    }
}

/// `--log-events`: the statuses and collisions `frame` brings, one line each.
fn log_events(
    out: &mut impl std::io::Write,
    cycle: u64,
    frame: &vrsync_agent::Frame,
) -> anyhow::Result<()> {
    for s in frame.statuses() {
        writeln!(out, "{cycle} status {} {} {}", s.action_id, s.state, s.seq)
            .context("write --log-events")?;
    }
    for c in frame.collisions() {
        writeln!(
            out,
            "{cycle} collision {} {} {}",
            c.action_id, c.collider_id, c.seq
        )
        .context("write --log-events")?;
    }
    out.flush().context("write --log-events")
}

/// `--bad-commands`: one command the host must reject of each sort (a NaN argument, a
/// distance out of range, an object that does not exist, an unknown kind).
fn send_bad_commands(agent: &mut Agent) -> anyhow::Result<()> {
    use vrsync_transport::{Command, MotorCommand};
    let bad_id = u32::MAX;
    let mut nan = Command::Move {
        heading_deg: 0.0,
        distance: 1.0,
    }
    .encode(bad_id);
    nan.args[1] = f32::NAN;
    let far = Command::Move {
        heading_deg: 0.0,
        distance: 1.0e9,
    }
    .encode(bad_id);
    let ghost = Command::GraspId { object_id: 999_999 }.encode(bad_id);
    let unknown = MotorCommand {
        kind: 99,
        action_id: bad_id,
        ..MotorCommand::default()
    };
    for c in [nan, far, ghost, unknown] {
        agent.send_wire(c).context("queue command")?;
    }
    Ok(())
}

fn run(args: &Args) -> anyhow::Result<ExitCode> {
    let config = match Config::load(&args.config) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("vr-agent {}: error: {e}", args.id);
            return Ok(ExitCode::from(2));
        }
    };
    let start_timeout = match args.start_timeout {
        Some(s) if s.is_finite() && s > 0.0 => Some(Duration::from_secs_f64(s)),
        Some(s) => {
            eprintln!(
                "vr-agent {}: error: --start-timeout must be > 0, got {s}",
                args.id
            );
            return Ok(ExitCode::from(2));
        }
        None if config.waits_for_live_agents() => None,
        None => Some(config.sync.stop_timeout + config.sync.connect_timeout),
    };
    let connected = AgentBuilder::new(&config, args.id)
        .signal_handling(SignalHandling::Install)
        .connect();
    let mut agent = match connected {
        Ok(a) => a,
        Err(e) => {
            return Err(anyhow::Error::new(e).context(format!(
                "cannot connect agent {} to session {:?}",
                args.id, config.session
            )));
        }
    };
    info!(id = args.id, session = %config.session, policy = ?args.policy, "connected");
    let seed = args.seed.unwrap_or(config.seed);
    let mut policy = Policy::new(args.policy, seed, args.id);
    let mut jitter = ChaCha8Rng::seed_from_u64(seed.wrapping_add(0x5EED) ^ u64::from(args.id));
    let create = |p: &PathBuf| -> anyhow::Result<_> {
        let p = PathBuf::from(p.to_string_lossy().replace("{id}", &args.id.to_string()));
        Ok(std::io::BufWriter::new(
            std::fs::File::create(&p).with_context(|| format!("cannot create {}", p.display()))?,
        ))
    };
    let mut log = args.log_cycles.as_ref().map(create).transpose()?;
    let mut event_log = args.log_events.as_ref().map(create).transpose()?;
    let mut sent = Vec::with_capacity(4);
    let mut cycles = 0u64;
    let outcome = loop {
        if args.frames.is_some_and(|n| cycles >= n) {
            break Ok(());
        }
        let frame = match agent.wait_start(start_timeout) {
            Ok(f) => f,
            Err(WaitStartError::HostClosed) => break Ok(()),
            Err(WaitStartError::Terminated) => {
                info!(id = args.id, "termination requested");
                break Ok(());
            }
            Err(e) => break Err(e),
        };
        let cycle = frame.cycle();
        let sim_time_ns = frame.header().sim_time_ns;
        if cycles == 0 {
            info!(id = args.id, cycle, "first frame received");
        }
        let decision = policy.decide(&frame);
        if let Some(out) = &mut event_log {
            log_events(out, cycle, &frame)?;
        }
        drop(frame);
        sent.clear();
        if args.bad_commands {
            send_bad_commands(&mut agent)?;
        }
        for command in decision.iter() {
            let action = agent.send(command).context("queue command")?;
            policy.started(action);
            sent.push(action);
        }
        if let Some(out) = &mut log {
            use std::io::Write;
            let ids: Vec<String> = sent.iter().map(u32::to_string).collect();
            writeln!(
                out,
                "{cycle} {sim_time_ns} {} {}",
                agent.frames_skipped(),
                ids.join(",")
            )
            .context("write --log-cycles")?;
            out.flush().context("write --log-cycles")?;
        }
        if args.jitter_ms > 0 {
            let ms = jitter.random_range(0..=args.jitter_ms);
            std::thread::sleep(Duration::from_millis(ms));
        }
        cycles += 1;
        if args.late_stop_at == Some(cycle) {
            warn!(
                id = args.id,
                cycle, "stopping late on purpose (--late-stop-at)"
            );
            // 1.5 ×, not 2 ×: after 2 × the agent would wake just as the next cycle's
            // timeout ends, and that cycle would time out too, depending on scheduling.
            let late = f64::from(args.late_stop_cycles.max(1)) + 0.5;
            std::thread::sleep(config.sync.stop_timeout.mul_f64(late));
        }
        match agent.stop() {
            Ok(()) => {}
            Err(StopError::HostClosed) => break Ok(()),
            Err(e) => return Err(anyhow::Error::new(e).context("stop")),
        }
        if args.sigstop_after.contains(&cycle) {
            freeze();
        }
    };
    report(&agent, cycles);
    match outcome {
        Ok(()) => Ok(ExitCode::SUCCESS),
        Err(e) => {
            Err(anyhow::Error::new(e).context(format!("agent {} after {cycles} cycles", args.id)))
        }
    }
}

/// Stops this process until it is continued (SIGCONT).
fn freeze() {
    // SAFETY: raise(3) with a valid signal number; SIGSTOP cannot be caught, so no handler
    // runs, and the process simply resumes here when continued.
    unsafe {
        libc::raise(libc::SIGSTOP);
    }
}

fn report(agent: &Agent, cycles: u64) {
    info!(
        id = agent.id(),
        cycles,
        last_cycle = ?agent.last_cycle(),
        skipped = agent.frames_skipped(),
        "agent finished"
    );
}
