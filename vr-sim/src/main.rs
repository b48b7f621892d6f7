//! `vr-sim`: the headless simulator standing in for the Unity VR app.

mod bench;
mod cli;
mod events;
mod geometry;
mod picture;
mod record;
mod render;
mod replay;
mod rerun_log;
mod run;
mod spawn;
mod world;
mod world_config;

use std::path::Path;
use std::process::ExitCode;

use anyhow::Context;
use clap::Parser;
use vrsync_bridge::{Config, ConfigLoadError};

use crate::cli::{BenchArgs, Cli, Command, DemoArgs, ReplayArgs, RunArgs};
use crate::run::{RunOptions, print_summary};

// Counts allocations for `vr-sim bench` (allocs_per_cycle); one relaxed atomic add per
// allocation otherwise.
#[global_allocator]
static ALLOC: vrsync_alloc_count::CountingAlloc = vrsync_alloc_count::CountingAlloc;

/// Exit code of bad usage or bad config.
const EXIT_USAGE: u8 = 2;

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(c) => c,
        Err(e) => {
            let _ = e.print();
            return if e.use_stderr() {
                ExitCode::from(EXIT_USAGE)
            } else {
                ExitCode::SUCCESS
            };
        }
    };
    // The bench prints a table: its hosts' and agents' progress lines (info) would
    // interleave with it. RUST_LOG still decides when set.
    let default_filter = match cli.command {
        Command::Bench(_) => "warn",
        _ => "info",
    };
    {
        use tracing_subscriber::layer::SubscriberExt;
        use tracing_subscriber::util::SubscriberInitExt;
        use tracing_subscriber::{EnvFilter, Layer};
        let filter = EnvFilter::try_from_default_env()
            .unwrap_or_else(|_| EnvFilter::new(vrsync_bridge::default_log_filter(default_filter)));
        tracing_subscriber::registry()
            .with(
                tracing_subscriber::fmt::layer()
                    .with_writer(std::io::stderr)
                    .with_ansi(vrsync_bridge::ansi_on_stderr())
                    .with_filter(filter),
            )
            // Peers dropped in a TLS handshake count as refused (whatever RUST_LOG).
            .with(vrsync_bridge::refusal_layer())
            .init();
    }
    match run(cli) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("vr-sim: error: {e:#}");
            if e.downcast_ref::<ConfigLoadError>().is_some()
                || e.downcast_ref::<vrsync_bridge::ShmBudgetError>().is_some()
                || e.downcast_ref::<world_config::WorldConfigError>().is_some()
                || e.downcast_ref::<replay::RecordReadError>().is_some()
                || e.downcast_ref::<rerun_log::RerunUnavailable>().is_some()
            {
                ExitCode::from(EXIT_USAGE)
            } else {
                ExitCode::from(1)
            }
        }
    }
}

fn run(cli: Cli) -> anyhow::Result<ExitCode> {
    match cli.command {
        Command::Demo(args) => demo(args),
        Command::Run(args) => run_cmd(args),
        Command::Bench(args) => bench_cmd(args),
        Command::Replay(args) => replay_cmd(args),
    }
}

fn replay_cmd(args: ReplayArgs) -> anyhow::Result<ExitCode> {
    let done = replay::replay(&replay::ReplayOptions {
        record: args.record.clone(),
        config: args.config,
        camera_size: args.camera_size,
        dump_frames: args.dump_frames.clone().map(|d| (d, args.every)),
        map: args.map,
        render_threads: args.render_threads,
        render_affinity: args.render_affinity,
    })?;
    println!(
        "vr-sim replay: {} cycles of {} agents ({} commands applied, {} rejected) follow {}; \
         trajectory hash {} as recorded",
        done.cycles,
        done.agents,
        done.commands_applied,
        done.commands_rejected,
        args.record.display(),
        done.trajectory_hash
    );
    if let Some(dir) = &args.dump_frames {
        println!(
            "  {} images written to {}",
            done.frames_written,
            dir.display()
        );
    }
    Ok(ExitCode::SUCCESS)
}

fn bench_cmd(args: BenchArgs) -> anyhow::Result<ExitCode> {
    if cfg!(debug_assertions) {
        eprintln!("vr-sim bench: warning: this is a debug build; measure with --release");
    }
    bench::run(&bench::BenchOptions {
        quick: args.quick,
        json: args.json,
        csv: args.csv,
        plot: args.plot,
        python: (!args.no_python).then_some(args.python),
        only: args.only,
    })?;
    Ok(ExitCode::SUCCESS)
}

fn write_summary(path: &Path, summary: &run::Summary) -> anyhow::Result<()> {
    let text = serde_json::to_string_pretty(summary).context("serialise summary")?;
    std::fs::write(path, text + "\n").with_context(|| format!("cannot write {}", path.display()))
}

fn demo(args: DemoArgs) -> anyhow::Result<ExitCode> {
    let config = Config::embedded_default()?
        .with_agent_count(args.agents)?
        .with_session(&format!("demo-{}", std::process::id()))?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let config_path = args.out.join("config.toml");
    std::fs::write(&config_path, config.to_toml_string())
        .with_context(|| format!("cannot write {}", config_path.display()))?;
    println!(
        "vr-sim demo: {} agents ({}), {} cycles, sync mode, shared memory (outputs in {})",
        args.agents,
        args.policy,
        args.frames,
        args.out.display()
    );
    let frames_dir = args.out.join("frames");
    let map = args.out.join("map.png");
    let summary = run::run(
        RunOptions {
            config,
            agent_config_path: config_path,
            frames: Some(args.frames),
            spawn: true,
            agent_args: vec!["--policy".into(), args.policy.clone()],
            record: Some(args.out.join("record.jsonl")),
            progress: true,
            map: Some(map.clone()),
            // Four moments of the run.
            dump_frames: Some((frames_dir.clone(), (args.frames / 4).max(1))),
            render_threads: args.render_threads,
            render_affinity: args.render_affinity,
            rerun: None,
        },
        &mut events::Events::disabled(),
    )?;
    print_summary(&summary);
    write_summary(&args.out.join("summary.json"), &summary)?;
    if let Some(error) = &summary.error {
        anyhow::bail!("{error}");
    }
    println!("\n  outputs: {}", args.out.display());
    println!("    map         {}", map.display());
    println!("    frames      {}", frames_dir.display());
    println!(
        "    recording   {}",
        args.out.join("record.jsonl").display()
    );
    Ok(ExitCode::SUCCESS)
}

fn run_cmd(args: RunArgs) -> anyhow::Result<ExitCode> {
    let mut events = match &args.events {
        Some(path) => events::Events::create(path)?,
        None => events::Events::disabled(),
    };
    let result = run_with_events(&args, &mut events);
    if let Err(e) = &result {
        // Best effort: the run's own error is what the user must see.
        let _ = events.emit(events::Event::Error {
            message: format!("{e:#}"),
        });
    }
    result
}

fn run_with_events(args: &RunArgs, events: &mut events::Events) -> anyhow::Result<ExitCode> {
    let mut config = Config::load(&args.config)?;
    let mut changed = false;
    if let Some(n) = args.spawn_agents {
        config = config.with_agent_count(n)?;
        changed = true;
        // Each spawned agent is a process of its own; the stacked sample has one reader.
        if let Some((stacked, _)) = vrsync_bridge::shm::stack_shape(&config)
            && stacked > 1
        {
            anyhow::bail!(
                "{}: [transport.shm] stacked_images = true: the {stacked} shared-memory agents' \
                 images are read by one process (a vrsync.AgentGroup or VrsyncVectorEnv), but \
                 --spawn-agents starts a process per agent; run without --spawn-agents and \
                 start that one process, or turn stacked_images off",
                args.config.display()
            );
        }
    }
    if let Some(s) = &args.session {
        config = config.with_session(s)?;
        changed = true;
    }
    if args.frames == Some(0) {
        anyhow::bail!(ConfigLoadError::Invalid {
            path: "--frames".into(),
            line: 0,
            key: "frames".into(),
            reason: "must be at least 1".into(),
        });
    }
    let mut _private = None;
    let agent_config_path = if changed {
        let private = spawn::PrivateConfig::write(&config)?;
        let path = private.path().to_path_buf();
        _private = Some(private);
        path
    } else {
        args.config.clone()
    };
    let summary = run::run(
        RunOptions {
            config,
            agent_config_path,
            frames: args.frames,
            spawn: args.spawn_agents.is_some(),
            agent_args: args.agent_arg.clone(),
            record: args.record.clone(),
            progress: !args.quiet,
            map: args.map.clone(),
            dump_frames: args.dump_frames.clone().map(|d| (d, args.every)),
            render_threads: args.render_threads,
            render_affinity: args.render_affinity,
            rerun: (args.rerun || args.rrd.is_some()).then(|| rerun_log::RerunOptions {
                viewer: args.rerun,
                rrd: args.rrd.clone(),
                image_every: args.rerun_every,
            }),
        },
        events,
    )?;
    print_summary(&summary);
    if let Some(path) = &args.summary_json {
        write_summary(path, &summary)?;
    }
    if let Some(error) = &summary.error {
        // The summary is written; the run still failed (exit 1, an `error` event).
        anyhow::bail!("{error}");
    }
    events.emit(events::Event::Finished {
        frames: summary.frames,
        interrupted: summary.interrupted,
        trajectory_hash: &summary.trajectory_hash,
        summary: args.summary_json.as_deref(),
    })?;
    Ok(ExitCode::SUCCESS)
}
