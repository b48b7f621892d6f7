//! The host run loop: frame 1 (sensors + start), frame 2 (collect, apply, advance).

use std::collections::BTreeSet;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use serde::Serialize;
use tracing::{info, warn};
use vrsync_bridge::{Config, Host, HostCycleError, HostWaitError, SignalHandling};

use crate::events::{CYCLE_EVENT_EVERY, Event, Events};
use crate::picture::{Trails, dump_image, write_map};
use crate::render::Renderer;
use crate::spawn::Agents;
use crate::world::World;

/// What to run.
#[derive(Debug)]
pub struct RunOptions {
    /// The validated config.
    pub config: Config,
    /// The file spawned agents are given.
    pub agent_config_path: PathBuf,
    /// Cycles to run (`None`: until Ctrl-C).
    pub frames: Option<u64>,
    /// Spawn `vr-agent` for every configured agent.
    pub spawn: bool,
    /// Extra arguments for spawned agents.
    pub agent_args: Vec<String>,
    /// JSON-lines recording.
    pub record: Option<PathBuf>,
    /// Show a progress bar.
    pub progress: bool,
    /// Top-down map with every agent's trajectory, written at the end.
    pub map: Option<PathBuf>,
    /// Write every agent's camera images as PNG into this folder every `.1` cycles.
    pub dump_frames: Option<(PathBuf, u64)>,
    /// Threads shading image rows (1: the host thread only; 0: one per core).
    pub render_threads: usize,
}

/// The run summary (DESIGN §8 keys, plus a few more).
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    /// `sync` or `async`.
    pub mode: String,
    /// `shm` or `tcp`.
    pub transport: String,
    /// Number of agents.
    pub agents: usize,
    /// Cycles completed.
    pub frames: u64,
    /// Simulated seconds.
    pub sim_time_s: f64,
    /// Wall-clock seconds of the cycle loop.
    pub wall_s: f64,
    /// Cycles per wall-clock second.
    pub frames_per_s: f64,
    /// Cycles that ended by the stop timeout.
    pub stop_timeouts: u64,
    /// Agent-cycles that timed out.
    pub agent_timeouts: u64,
    /// Late batches (stops for an earlier cycle) dropped.
    pub late_stops: u64,
    /// Cycles in which the host waited past `stop_timeout` for a live agent
    /// (`wait_for_stop = "alive"`): slow, not timed out.
    pub slow_stops: u64,
    /// Agents evicted (dead).
    pub evicted_agents: Vec<u32>,
    /// Connections refused or dropped before they were admitted as agents.
    pub peers_refused: u64,
    /// Evictions (an agent evicted twice counts 2).
    pub evictions: u64,
    /// Times an evicted agent, or one that left, came back.
    pub rejoins: u64,
    /// Graceful leaves (an agent's SDK said it leaves): not evictions, not timeouts.
    pub leaves: u64,
    /// Frames delivered to an agent (one per agent and cycle when nothing goes wrong).
    pub frames_delivered: u64,
    /// Frames an agent acknowledged having read; `frames_delivered - frames_read` were
    /// skipped by their agent (async mode: a newer one was read first) or still being read.
    pub frames_read: u64,
    /// Frames that reached no agent (not connected, or async TCP with a full socket).
    pub frames_undelivered: u64,
    /// Stops dropped because they named a cycle that had not started.
    pub future_stops: u64,
    /// Commands dropped because an agent exceeded `max_commands_per_cycle`.
    pub commands_overflowed: u64,
    /// Action statuses dropped because an agent did not acknowledge frames for a while.
    pub statuses_dropped: u64,
    /// Collisions dropped because an agent did not acknowledge frames for a while.
    pub collisions_dropped: u64,
    /// Commands applied to the world.
    pub commands_applied: u64,
    /// Commands rejected (undecodable, out of range, unsupported).
    pub commands_rejected: u64,
    /// Hash of every agent's pose and status after every cycle (blake3, hex).
    pub trajectory_hash: String,
    /// Mean time to write sensors and render all agents' images per cycle, µs.
    pub render_us: f64,
    /// Threads that shaded image rows.
    pub render_threads: usize,
    /// Whether the run ended early by SIGINT/SIGTERM.
    pub interrupted: bool,
    /// Why the run failed after it started, `null` when it did not: no agent was connected
    /// any more and none came back within `sync.connect_timeout` (vr-sim then exits 1,
    /// after writing this summary).
    pub error: Option<String>,
}

#[derive(Serialize)]
struct RecordLine<'a> {
    cycle: u64,
    sim_time_s: f64,
    agent: u32,
    outcome: &'a str,
    position: [f32; 3],
    rotation: [f32; 4],
    heading_deg: f32,
    eyes_deg: [f32; 3],
    held: Option<u32>,
    commands: Vec<(&'static str, u32)>,
    rejected: u32,
    statuses: Vec<(u32, u32)>,
    collisions: Vec<(u32, u32)>,
    reward: f32,
}

/// Runs the world until `frames` cycles are done (or Ctrl-C).
///
/// # Errors
/// Host creation, agents missing, transport failures, a spawned agent failing.
pub fn run(opts: RunOptions, events: &mut Events) -> anyhow::Result<Summary> {
    let config = &opts.config;
    // Pre-flight: a session that does not fit /dev/shm is a configuration error (exit 2),
    // found before anything starts rather than as a SIGBUS later.
    vrsync_bridge::check_shm_budget(config)?;
    // The world first: a bad [world] section is a config error, reported before anything
    // is started.
    let mut world = World::from_config(config)?;
    let mut renderer = Renderer::new(opts.render_threads)?;
    if let Some((dir, _)) = &opts.dump_frames {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    let mut host = Host::builder(config)
        .signal_handling(SignalHandling::Install)
        .create()
        .context("cannot create the host")?;
    let ids: Vec<u32> = host.agent_ids().collect();
    if events.enabled() {
        // As it happens: collect may block for a lost agent (on_agent_lost = "wait").
        let mut hook_events = events.clone();
        host.on_evicted(move |agent, cycle| {
            let event = Event::AgentEvicted {
                agent,
                cycle,
                reason: "lost: process died or disconnected".into(),
            };
            if let Err(e) = hook_events.emit(event) {
                warn!("{e:#}");
            }
        });
    }
    if events.enabled() {
        let mut hook_events = events.clone();
        host.on_slow(move |agent, cycle, waited| {
            let event = Event::AgentSlow {
                agent,
                cycle,
                waited_s: waited.as_secs_f64(),
            };
            if let Err(e) = hook_events.emit(event) {
                warn!("{e:#}");
            }
        });
    }
    if events.enabled() {
        let mut hook_events = events.clone();
        host.on_peer_refused(move |r| {
            let event = Event::PeerRefused {
                kind: r.kind.as_str(),
                agent: r.agent,
                peer: r.peer.clone(),
                reason: r.reason.clone(),
            };
            if let Err(e) = hook_events.emit(event) {
                warn!("{e:#}");
            }
        });
    }
    events.emit(Event::Listening {
        session: &config.session,
        transport: config.transport.kind.as_str(),
        address: host.tcp_local_addr().map(|a| a.to_string()),
    })?;
    // `tcp_listen` with port 0 binds a free port: spawned agents must learn the real one.
    let mut _bound_config = None;
    let mut agent_config_path = opts.agent_config_path.clone();
    if let Some(addr) = host.tcp_local_addr()
        && addr != config.transport.tcp_listen
        && opts.spawn
    {
        let mut bound = config.clone();
        bound.transport.tcp_listen = addr;
        let private = crate::spawn::PrivateConfig::write(&bound)?;
        agent_config_path = private.path().to_path_buf();
        _bound_config = Some(private);
    }
    let mut agents = if opts.spawn {
        // Legacy agents are programs written for the original system: started by the
        // user, never by vr-sim.
        let spawn_ids: Vec<u32> = config
            .agents
            .iter()
            .filter(|a| a.transport != vrsync_bridge::TransportKind::Legacy)
            .map(|a| a.id)
            .collect();
        Agents::spawn(&agent_config_path, &spawn_ids, &opts.agent_args)?
    } else {
        Agents::default()
    };

    // Wait for every agent, in slices so a spawned agent that fails is reported at once
    // (and connections are reported as events).
    let mut missing_before: Vec<u32> = ids
        .iter()
        .copied()
        .filter(|&id| !host.is_connected(id))
        .collect();
    if !missing_before.is_empty() {
        events.emit(Event::WaitingForAgents {
            agents: missing_before.clone(),
        })?;
    }
    let wait_started = Instant::now();
    loop {
        let left = config
            .sync
            .connect_timeout
            .saturating_sub(wait_started.elapsed());
        let result = host.wait_for_agents(left.min(Duration::from_millis(500)));
        let missing: &[u32] = match &result {
            Err(HostWaitError::AgentsMissing { missing, .. }) => missing,
            _ => &[],
        };
        if result.is_ok() || matches!(result, Err(HostWaitError::AgentsMissing { .. })) {
            for &agent in missing_before.iter().filter(|id| !missing.contains(id)) {
                events.emit(Event::AgentConnected { agent, cycle: None })?;
            }
            missing_before = missing.to_vec();
        }
        match result {
            Ok(()) => {
                events.emit(Event::AllAgentsConnected { agents: ids.len() })?;
                break;
            }
            Err(HostWaitError::AgentsMissing {
                missing,
                left: gone,
                ..
            }) => {
                if let Some((id, status)) = agents.failed() {
                    bail!("agent {id} exited before connecting ({status})");
                }
                if left.is_zero() {
                    // Agents that connected and left again are named as such, not as
                    // agents that never came.
                    let never: Vec<u32> = missing
                        .iter()
                        .copied()
                        .filter(|id| !gone.contains(id))
                        .collect();
                    let mut why = Vec::new();
                    if !never.is_empty() {
                        why.push(format!(
                            "agents {never:?} did not connect within {}",
                            vrsync_agent::log::Rounded(config.sync.connect_timeout)
                        ));
                    }
                    if !gone.is_empty() {
                        why.push(format!("agents {gone:?} connected and left again"));
                    }
                    // Legacy agents are programs written for the original system, not
                    // vr-agent: say where they connect.
                    let legacy: Vec<u32> = missing
                        .iter()
                        .copied()
                        .filter(|&id| {
                            config.agent(id).is_some_and(|a| {
                                a.transport == vrsync_bridge::TransportKind::Legacy
                            })
                        })
                        .collect();
                    if !legacy.is_empty() {
                        let port = config.transport.legacy.local_port;
                        why.push(format!(
                            "agents {legacy:?} use the original system's protocol: start their \
                             programs against port {port} (agent N listens on {port} + 1 + N)"
                        ));
                    }
                    bail!(
                        "{}; start them with `vr-agent --config {} --id <id>`",
                        why.join("; "),
                        opts.agent_config_path.display()
                    );
                }
            }
            Err(HostWaitError::Terminated) => bail!("interrupted while waiting for agents"),
            Err(e) => return Err(e).context("waiting for agents"),
        }
    }

    let dt = config.sync.simulation_time_per_frame;
    let mut trails = opts.map.as_ref().map(|_| Trails::new(&world));
    let mut record = match &opts.record {
        Some(p) => Some(BufWriter::new(
            File::create(p).with_context(|| format!("cannot create {}", p.display()))?,
        )),
        None => None,
    };
    let bar = opts.progress.then(|| {
        let bar = match opts.frames {
            Some(n) => indicatif::ProgressBar::new(n),
            None => indicatif::ProgressBar::new_spinner(),
        };
        bar.set_style(
            indicatif::ProgressStyle::with_template(
                "{spinner} [{elapsed_precise}] {bar:40} {pos}/{len} cycles {msg}",
            )
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        bar
    });

    let mut hasher = blake3::Hasher::new();
    let mut applied = 0u64;
    let mut rejected_total = 0u64;
    let mut logged_rejections: BTreeSet<(u32, &'static str)> = BTreeSet::new();
    let mut render_time = Duration::ZERO;
    // Reused every cycle: no allocation per cycle in the steady state.
    let mut rejected_per_agent: Vec<(u32, u32)> = Vec::with_capacity(ids.len());
    let mut interrupted = false;
    // What the events report changes of (all connected now, nobody evicted).
    let mut connected: Vec<bool> = vec![true; ids.len()];
    let mut evicted: Vec<bool> = vec![false; ids.len()];
    let loop_started = Instant::now();
    let mut done = 0u64;
    // Set when the host paused with nobody attached and nobody came back in time.
    let mut error = None;

    'cycles: while opts.frames.is_none_or(|n| done < n) {
        // Nobody attached any more (every agent left or was evicted): no cycles, no world
        // advance, until the agents are back, as at the start.
        if ids.iter().all(|&id| !host.is_connected(id)) {
            let cycle = host.cycle();
            for (i, &agent) in ids.iter().enumerate() {
                if connected[i] {
                    connected[i] = false;
                    events.emit(Event::AgentLeft {
                        agent,
                        cycle,
                        graceful: false,
                    })?;
                }
            }
            events.emit(Event::WaitingForAgents {
                agents: ids.clone(),
            })?;
            let timeout = config.sync.connect_timeout;
            warn!(
                session = %config.session,
                cycle,
                "no agent is connected: paused, waiting up to {} (sync.connect_timeout) for \
                 every agent to connect again",
                vrsync_agent::log::Rounded(timeout)
            );
            let paused = Instant::now();
            loop {
                let left = timeout.saturating_sub(paused.elapsed());
                match host.wait_for_agents(left.min(Duration::from_millis(500))) {
                    Ok(()) => {
                        events.emit(Event::AllAgentsConnected { agents: ids.len() })?;
                        info!(cycle, "agents back: the run goes on");
                        break;
                    }
                    Err(HostWaitError::AgentsMissing { missing, .. }) => {
                        if left.is_zero() {
                            error = Some(format!(
                                "session {:?}: no agent connected after cycle {cycle}; the \
                                 host waited {} (sync.connect_timeout) for agents {missing:?} to \
                                 connect again and gives up",
                                config.session,
                                vrsync_agent::log::Rounded(paused.elapsed())
                            ));
                            break 'cycles;
                        }
                    }
                    Err(HostWaitError::Terminated) => {
                        interrupted = true;
                        break 'cycles;
                    }
                    Err(e) => return Err(e).context("waiting for agents to come back"),
                }
            }
        }
        // Frame 1: every connected agent's sensors, written in place, then one start.
        let mut notable = false;
        for (i, &id) in ids.iter().enumerate() {
            let now_connected = host.is_connected(id);
            if now_connected != connected[i] {
                connected[i] = now_connected;
                let cycle = host.cycle();
                events.emit(if now_connected {
                    Event::AgentConnected {
                        agent: id,
                        cycle: Some(cycle),
                    }
                } else {
                    Event::AgentLeft {
                        agent: id,
                        cycle,
                        graceful: false,
                    }
                })?;
            }
            if !now_connected {
                continue;
            }
            let mut frame = host.loan_frame(id)?;
            let cycle = frame.header().cycle;
            let t = Instant::now();
            let (header, images) = frame.parts_mut();
            world.write_sensors(id, header);
            renderer.render_agent(&world, id, images);
            render_time += t.elapsed();
            if let Some((dir, every)) = &opts.dump_frames
                && cycle % every == 0
            {
                for image in frame.images_mut() {
                    dump_image(dir, cycle, id, &image)?;
                }
            }
            host.publish(frame)?;
            if evicted[i] && !host.is_evicted(id) && !host.has_left(id) {
                evicted[i] = false;
                notable = true;
                events.emit(Event::AgentRejoined { agent: id, cycle })?;
            }
        }
        host.start()?;

        // Frame 2: collect, apply in (agent id, order sent) order, advance.
        let report = match host.collect() {
            Ok(r) => r,
            Err(HostCycleError::Terminated) => {
                interrupted = true;
                break;
            }
            Err(e) => {
                return Err(e).context("cycle failed");
            }
        };
        let cycle = report.cycle;
        let timed_out_agents: Vec<u32> = report.timed_out_agents().collect();
        let slow_agents: Vec<u32> = report.slow_agents().collect();
        for (i, &id) in ids.iter().enumerate() {
            if report.agent(id).is_some_and(|a| a.left) {
                // Reported here, not again at the next cycle boundary; a new connection
                // of the id shows as connected, then rejoined.
                connected[i] = false;
                evicted[i] = true;
                notable = true;
                events.emit(Event::AgentLeft {
                    agent: id,
                    cycle,
                    graceful: true,
                })?;
            }
        }
        let late_batches = report.late_batches;
        let mut per_agent = Vec::with_capacity(if record.is_some() { ids.len() } else { 0 });
        rejected_per_agent.clear();
        for a in report.agents() {
            let mut rejected = 0u32;
            let mut names = Vec::new();
            for wire in a.commands() {
                let result = wire
                    .decode()
                    .map_err(crate::world::CommandRejected::from)
                    .and_then(|cmd| world.apply(a.agent_id, wire.action_id, cmd).map(|()| cmd));
                match result {
                    Ok(cmd) => {
                        applied += 1;
                        if record.is_some() {
                            names.push((cmd.name(), wire.action_id));
                        }
                    }
                    Err(e) => {
                        rejected += 1;
                        let kind = vrsync_bridge::kind_name(wire.kind);
                        if logged_rejections.insert((a.agent_id, kind)) {
                            events.emit(Event::CommandRejected {
                                agent: a.agent_id,
                                cycle,
                                kind,
                                reason: e.to_string(),
                            })?;
                            warn!(
                                agent = a.agent_id,
                                cycle,
                                "command rejected: {e} (further `{kind}` rejections of this agent are counted, not logged)"
                            );
                        }
                    }
                }
            }
            rejected_total += u64::from(rejected);
            rejected_per_agent.push((a.agent_id, rejected));
            if record.is_some() {
                per_agent.push((a.agent_id, a.outcome, names, rejected));
            }
        }
        for &(id, n) in &rejected_per_agent {
            host.set_rejected(id, n);
        }
        for (i, &id) in ids.iter().enumerate() {
            // Written by the host's on_evicted hook; remembered here for rejoins.
            if !evicted[i] && host.is_evicted(id) {
                evicted[i] = true;
                notable = true;
            }
        }
        if events.enabled()
            && (notable
                || cycle % CYCLE_EVENT_EVERY == 0
                || late_batches > 0
                || !timed_out_agents.is_empty()
                || !slow_agents.is_empty())
        {
            events.emit(Event::Cycle {
                cycle,
                timed_out_agents,
                slow_agents,
                late_batches,
            })?;
        }
        world.step();
        hasher.update(&cycle.to_le_bytes());
        world.hash_into(&mut hasher);
        if let Some(t) = &mut trails {
            t.push(&world);
        }

        if let Some(out) = &mut record {
            let sim_time_s = (cycle as f64 + 1.0) * dt.as_secs_f64();
            for (id, outcome, commands, rejected) in per_agent {
                let Some(body) = world.bodies().iter().find(|b| b.id == id) else {
                    continue;
                };
                let pose = body.pose();
                let line = RecordLine {
                    cycle,
                    sim_time_s,
                    agent: id,
                    outcome: outcome.as_str(),
                    position: pose.position,
                    rotation: pose.rotation,
                    heading_deg: body.heading_deg,
                    eyes_deg: [
                        body.eyes.pan_left_deg,
                        body.eyes.pan_right_deg,
                        body.eyes.tilt_deg,
                    ],
                    held: body.held,
                    commands,
                    rejected,
                    statuses: body
                        .pending_statuses()
                        .iter()
                        .map(|&(a, s)| (a, s as u32))
                        .collect(),
                    collisions: body.pending_collisions().to_vec(),
                    reward: body.pending_reward(),
                };
                serde_json::to_writer(&mut *out, &line).context("write record")?;
                out.write_all(b"\n").context("write record")?;
            }
        }
        done += 1;
        if let Some(bar) = &bar {
            bar.inc(1);
        }
        if let Some((id, status)) = agents.failed()
            && !host.stats().evicted_agents.contains(&id)
            && config.sync.on_agent_lost != vrsync_bridge::AgentLostPolicy::Evict
        {
            bail!("agent {id} exited during cycle {cycle} ({status})");
        }
        if host.termination_requested() {
            interrupted = true;
            break;
        }
    }
    let wall = loop_started.elapsed();
    if let Some(bar) = bar {
        bar.finish_and_clear();
    }
    if let Some(mut out) = record {
        out.flush().context("write record")?;
    }
    if let (Some(path), Some(trails)) = (&opts.map, &trails) {
        write_map(path, &world, trails)?;
    }
    let stats = host.stats().clone();
    let sync_mode = config.sync.sync_mode;
    drop(host); // tells the agents the session is closed
    let failures = agents.finish(Duration::from_secs(5));
    for (id, why) in &failures {
        warn!(agent = id, "agent did not end cleanly: {why}");
    }
    // An evicted agent's failure was handled by on_agent_lost = "evict"; any other failure
    // of a spawned agent fails the run.
    let unhandled: Vec<_> = failures
        .iter()
        .filter(|(id, _)| !stats.evicted_agents.contains(id))
        .collect();
    if !interrupted && !unhandled.is_empty() {
        bail!("spawned agents failed: {unhandled:?}");
    }
    let wall_s = wall.as_secs_f64();
    let summary = Summary {
        mode: if sync_mode { "sync" } else { "async" }.into(),
        transport: config.transport.kind.as_str().into(),
        agents: ids.len(),
        frames: done,
        sim_time_s: done as f64 * dt.as_secs_f64(),
        wall_s,
        frames_per_s: if wall_s > 0.0 {
            done as f64 / wall_s
        } else {
            0.0
        },
        stop_timeouts: stats.stop_timeouts,
        agent_timeouts: stats.agent_timeouts,
        late_stops: stats.late_batches,
        slow_stops: stats.slow_stops,
        evicted_agents: stats.evicted_agents.clone(),
        peers_refused: stats.peers_refused,
        evictions: stats.evictions,
        rejoins: stats.rejoins,
        leaves: stats.leaves,
        frames_delivered: stats.frames_delivered,
        frames_read: stats.frames_read,
        frames_undelivered: stats.frames_undelivered,
        future_stops: stats.future_batches,
        commands_overflowed: stats.commands_overflowed,
        statuses_dropped: stats.statuses_dropped,
        collisions_dropped: stats.collisions_dropped,
        commands_applied: applied,
        commands_rejected: rejected_total,
        trajectory_hash: hasher.finalize().to_hex().to_string(),
        render_us: if done > 0 {
            render_time.as_secs_f64() * 1e6 / done as f64
        } else {
            0.0
        },
        render_threads: renderer.threads(),
        interrupted,
        error,
    };
    info!(frames = done, wall_s, "run finished");
    Ok(summary)
}

/// Prints the summary as a table.
pub fn print_summary(s: &Summary) {
    let rows: [(&str, String); 22] = [
        ("mode", s.mode.clone()),
        ("transport", s.transport.clone()),
        ("agents", s.agents.to_string()),
        ("cycles", s.frames.to_string()),
        ("simulated time", format!("{:.2} s", s.sim_time_s)),
        ("wall time", format!("{:.2} s", s.wall_s)),
        ("cycles per second", format!("{:.1}", s.frames_per_s)),
        ("stop timeouts", s.stop_timeouts.to_string()),
        ("late stops dropped", s.late_stops.to_string()),
        ("slow stops waited", s.slow_stops.to_string()),
        ("future stops dropped", s.future_stops.to_string()),
        ("evicted agents", format!("{:?}", s.evicted_agents)),
        (
            "evictions, leaves, rejoins",
            format!("{}, {}, {}", s.evictions, s.leaves, s.rejoins),
        ),
        ("peers refused", s.peers_refused.to_string()),
        (
            "frames delivered",
            format!(
                "{} ({} read, {} undelivered)",
                s.frames_delivered, s.frames_read, s.frames_undelivered
            ),
        ),
        ("statuses dropped", s.statuses_dropped.to_string()),
        ("collisions dropped", s.collisions_dropped.to_string()),
        ("commands applied", s.commands_applied.to_string()),
        ("commands rejected", s.commands_rejected.to_string()),
        ("commands overflowed", s.commands_overflowed.to_string()),
        (
            "render per cycle",
            format!("{:.0} µs ({} threads)", s.render_us, s.render_threads),
        ),
        ("trajectory hash", s.trajectory_hash[..16].to_string()),
    ];
    println!();
    for (k, v) in rows {
        println!("  {k:<20} {v}");
    }
    if s.interrupted {
        println!("  (interrupted)");
    }
}
