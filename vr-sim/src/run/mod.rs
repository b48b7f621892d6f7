//! The host run loop: frame 1 (sensors + start), frame 2 (collect, apply, advance).

use std::collections::BTreeSet;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::ops::ControlFlow;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use tracing::{info, warn};
use vrsync_bridge::{Config, Host, HostCycleError, HostWaitError, SensorFrameMut, SignalHandling};

use crate::events::{CYCLE_EVENT_EVERY, Event, Events};
use crate::picture::{Trails, dump_image, write_map};
use crate::record::{self, AgentCommands, AgentLine};
use crate::render::Renderer;
use crate::rerun_log::{CycleData, RerunLog, RerunOptions};
use crate::spawn::{Agents, PrivateConfig};
use crate::world::World;

mod setup;
mod summary;
mod tally;

use setup::{
    bound_config_for_spawn, install_event_hooks, progress_bar, spawn_agents, wait_for_agents,
};
pub use summary::{Summary, print_summary};
use tally::{CommandTally, Roster};

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
    /// Whether the render threads are bound to CPUs.
    pub render_affinity: crate::render::Affinity,
    /// Live view and/or recording in Rerun (`--rerun`, `--rrd`).
    pub rerun: Option<RerunOptions>,
}

/// Runs the world until `frames` cycles are done (or Ctrl-C).
///
/// One cycle is [`Run::frame1`] (sensors, images, start) then [`Run::frame2`] (collect,
/// apply, advance); when every agent is gone the run pauses in [`Run::wait_for_return`].
///
/// # Errors
/// Host creation, agents missing, transport failures, a spawned agent failing.
pub fn run(opts: RunOptions, events: &mut Events) -> anyhow::Result<Summary> {
    run_observed(opts, events, |_| {})
}

/// The wall time of one cycle of the loop and of two of its parts (for `vr-sim bench`'s
/// whole-loop rows).
#[derive(Debug, Clone, Copy)]
pub struct CycleTimes {
    /// Frame 1 and frame 2: sensors, rendering, publishing, start, the wait for the
    /// agents, applying, the world's step, the trajectory hash.
    pub total: Duration,
    /// Frame 1: the connections, the loans, the sensors, rendering, publishing, start.
    pub frame1: Duration,
    /// Writing the sensors and rendering the images (part of frame 1).
    pub render: Duration,
    /// The wait for every agent's stop (`Host::collect`, part of frame 2): the agents'
    /// own time between the start and their stops, and their wake-ups.
    pub collect: Duration,
}

/// [`run`], calling `observe` after every completed cycle with that cycle's times (not for
/// a cycle that SIGINT/SIGTERM ended).
///
/// # Errors
/// As [`run`].
pub fn run_observed(
    opts: RunOptions,
    events: &mut Events,
    mut observe: impl FnMut(&CycleTimes),
) -> anyhow::Result<Summary> {
    let mut run = Run::new(opts, events)?;
    while run.wants_another_cycle() {
        if run.nobody_connected() && run.wait_for_return()?.is_break() {
            break;
        }
        let started = Instant::now();
        let rendered_before = run.render_time;
        let notable = run.frame1()?;
        let frame1 = started.elapsed();
        if run.frame2(notable)?.is_break() {
            break;
        }
        observe(&CycleTimes {
            total: started.elapsed(),
            frame1,
            render: run.render_time - rendered_before,
            collect: run.last_collect,
        });
    }
    run.finish()
}

/// One run of the host loop: what it set up, what it writes, what it counts.
///
/// Fields drop in declaration order: on an error the outputs are flushed, spawned agents
/// killed, their private config removed, then the host closed, as the locals of the one
/// function this was did.
struct Run {
    bar: Option<indicatif::ProgressBar>,
    /// JSON-lines recording (`--record`).
    record: Option<BufWriter<File>>,
    /// Trajectories for the map (`--map`).
    trails: Option<Trails>,
    /// The Rerun log (`--rerun`, `--rrd`).
    rerun: Option<RerunLog>,
    agents: Agents,
    /// The config spawned agents read when `tcp_listen` asked for any free port.
    _bound_config: Option<PrivateConfig>,
    host: Host,
    renderer: Renderer,
    world: World,
    opts: RunOptions,
    events: Events,
    roster: Roster,
    /// Scratch of [`Run::frame1`]: the roster indices of the agents rendered together.
    batch: Vec<usize>,
    /// Scratch of [`Run::render_and_publish`]: the batch's loaned frames (reused, so a
    /// cycle allocates no list of its own).
    frames: Vec<(usize, SensorFrameMut)>,
    commands: CommandTally,
    /// Every agent's pose and status after every cycle.
    hasher: blake3::Hasher,
    /// Writing sensors and rendering images, summed over the cycles.
    render_time: Duration,
    /// `render_time` at the start of the current cycle.
    render_time_at_cycle_start: Duration,
    /// The last cycle's wait in `Host::collect`.
    last_collect: Duration,
    loop_started: Instant,
    /// Cycles completed.
    done: u64,
    interrupted: bool,
    /// Set when the host paused with nobody attached and nobody came back in time.
    error: Option<String>,
}

impl Run {
    /// Checks the config, builds the world and the host, spawns the agents (`--spawn`),
    /// waits for every agent, then opens the outputs.
    fn new(opts: RunOptions, events: &mut Events) -> anyhow::Result<Self> {
        let config = &opts.config;
        // Pre-flight: a session that does not fit /dev/shm is a configuration error (exit 2),
        // found before anything starts rather than as a SIGBUS later.
        vrsync_bridge::check_shm_budget(config)?;
        // The world first: a bad [world] section is a config error, reported before anything
        // is started.
        let world = World::from_config(config)?;
        let renderer = Renderer::with_affinity(opts.render_threads, opts.render_affinity)?;
        // Before the host and the agents: a viewer that cannot be started (or a vr-sim
        // built without the feature) is reported at once.
        let rerun = match &opts.rerun {
            Some(r) => Some(RerunLog::open(r, config, &world)?),
            None => None,
        };
        if let Some((dir, _)) = &opts.dump_frames {
            std::fs::create_dir_all(dir)
                .with_context(|| format!("cannot create {}", dir.display()))?;
        }
        let mut host = Host::builder(config)
            .signal_handling(SignalHandling::Install)
            .create()
            .context("cannot create the host")?;
        let ids: Vec<u32> = host.agent_ids().collect();
        if events.enabled() {
            install_event_hooks(&mut host, events);
        }
        events.emit(Event::Listening {
            session: &config.session,
            transport: config.transport.kind.as_str(),
            address: host.tcp_local_addr().map(|a| a.to_string()),
        })?;
        let bound_config = bound_config_for_spawn(&opts, &host)?;
        let mut agents = if opts.spawn {
            let path = bound_config
                .as_ref()
                .map_or(opts.agent_config_path.as_path(), |p| p.path());
            spawn_agents(config, path, &opts.agent_args)?
        } else {
            Agents::default()
        };
        wait_for_agents(&mut host, &mut agents, &ids, events, &opts)?;

        let trails = opts.map.as_ref().map(|_| Trails::new(&world));
        let record = match &opts.record {
            Some(p) => {
                let mut out = BufWriter::new(
                    File::create(p).with_context(|| format!("cannot create {}", p.display()))?,
                );
                write_line(&mut out, &record::Header::of(config))?;
                Some(out)
            }
            None => None,
        };
        let bar = opts.progress.then(|| progress_bar(opts.frames));
        let agent_count = ids.len();
        Ok(Self {
            bar,
            record,
            trails,
            rerun,
            agents,
            _bound_config: bound_config,
            host,
            renderer,
            world,
            opts,
            events: events.clone(),
            roster: Roster {
                ids,
                connected: vec![true; agent_count],
                sensed: vec![false; agent_count],
                evicted: vec![false; agent_count],
            },
            batch: Vec::with_capacity(agent_count),
            frames: Vec::with_capacity(agent_count),
            commands: CommandTally {
                applied: 0,
                rejected: 0,
                logged: BTreeSet::new(),
                rejected_per_agent: Vec::with_capacity(agent_count),
            },
            hasher: blake3::Hasher::new(),
            render_time: Duration::ZERO,
            render_time_at_cycle_start: Duration::ZERO,
            last_collect: Duration::ZERO,
            loop_started: Instant::now(),
            done: 0,
            interrupted: false,
            error: None,
        })
    }

    /// Whether `--frames` cycles are not done yet (always, without `--frames`).
    fn wants_another_cycle(&self) -> bool {
        self.opts.frames.is_none_or(|n| self.done < n)
    }

    /// Every agent left or was evicted.
    fn nobody_connected(&self) -> bool {
        self.roster
            .ids
            .iter()
            .all(|&id| !self.host.is_connected(id))
    }

    /// Nobody attached any more: no cycles, no world advance, until the agents are back,
    /// as at the start. Breaks when nobody came back within `sync.connect_timeout` (the
    /// summary then carries the error) or on SIGINT/SIGTERM.
    fn wait_for_return(&mut self) -> anyhow::Result<ControlFlow<()>> {
        let config = &self.opts.config;
        let cycle = self.host.cycle();
        for (i, &agent) in self.roster.ids.iter().enumerate() {
            if self.roster.connected[i] {
                self.roster.connected[i] = false;
                self.events.emit(Event::AgentLeft {
                    agent,
                    cycle,
                    graceful: false,
                })?;
            }
        }
        self.events.emit(Event::WaitingForAgents {
            agents: self.roster.ids.clone(),
        })?;
        let timeout = config.sync.connect_timeout;
        warn!(
            session = %config.session,
            cycle,
            "no agent is connected: paused, waiting up to {} (sync.connect_timeout) for \
             every agent to connect again",
            vrsync_bridge::Rounded(timeout)
        );
        let paused = Instant::now();
        loop {
            let left = timeout.saturating_sub(paused.elapsed());
            match self
                .host
                .wait_for_agents(left.min(Duration::from_millis(500)))
            {
                Ok(()) => {
                    self.events.emit(Event::AllAgentsConnected {
                        agents: self.roster.ids.len(),
                    })?;
                    info!(cycle, "agents back: the run goes on");
                    return Ok(ControlFlow::Continue(()));
                }
                Err(HostWaitError::AgentsMissing { missing, .. }) => {
                    if left.is_zero() {
                        self.error = Some(format!(
                            "session {:?}: no agent connected after cycle {cycle}; the \
                             host waited {} (sync.connect_timeout) for agents {missing:?} to \
                             connect again and gives up",
                            config.session,
                            vrsync_bridge::Rounded(paused.elapsed())
                        ));
                        return Ok(ControlFlow::Break(()));
                    }
                }
                Err(HostWaitError::Terminated) => {
                    self.interrupted = true;
                    return Ok(ControlFlow::Break(()));
                }
                Err(e) => return Err(e).context("waiting for agents to come back"),
            }
        }
    }

    /// Frame 1: every connected agent's sensors and images, written in place, then one
    /// start. Returns whether an agent rejoined (the cycle is then reported whatever its
    /// number).
    fn frame1(&mut self) -> anyhow::Result<bool> {
        // Connections first, then the frames: the events come in the same order
        // whatever the batch size (the number of render threads).
        for i in 0..self.roster.ids.len() {
            self.roster.sensed[i] = self.note_connection(i)?;
        }
        let mut notable = false;
        let per_batch = self.renderer.agents_per_batch();
        let mut batch = std::mem::take(&mut self.batch);
        for i in 0..self.roster.ids.len() {
            if !self.roster.sensed[i] {
                continue;
            }
            batch.push(i);
            if batch.len() == per_batch {
                notable |= self.render_and_publish(&batch)?;
                batch.clear();
            }
        }
        if !batch.is_empty() {
            notable |= self.render_and_publish(&batch)?;
            batch.clear();
        }
        self.batch = batch;
        self.host.start()?;
        Ok(notable)
    }

    /// Reports agent `ids[i]` connecting or leaving since the last report; returns whether
    /// it is connected now.
    fn note_connection(&mut self, i: usize) -> anyhow::Result<bool> {
        let id = self.roster.ids[i];
        let now_connected = self.host.is_connected(id);
        if now_connected != self.roster.connected[i] {
            self.roster.connected[i] = now_connected;
            let cycle = self.host.cycle();
            self.events.emit(if now_connected {
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
        Ok(now_connected)
    }

    /// Writes the sensors of agents `ids[i]` (`i` in `batch`) and renders their images
    /// into loaned frames (in parallel, see [`Renderer::render_agents`]), dumping them as
    /// PNG every `--dump-frames` cycles, then publishes them in order. Returns whether an
    /// evicted agent rejoined.
    fn render_and_publish(&mut self, batch: &[usize]) -> anyhow::Result<bool> {
        let mut frames = std::mem::take(&mut self.frames);
        frames.clear();
        for &i in batch {
            frames.push((i, self.host.loan_frame(self.roster.ids[i])?));
        }
        let t = Instant::now();
        for (i, frame) in &mut frames {
            self.world
                .write_sensors(self.roster.ids[*i], frame.header_mut());
        }
        let ids = &self.roster.ids;
        self.renderer.render_agents(
            &self.world,
            frames.iter_mut().map(|(i, f)| (ids[*i], f.images_mut())),
        );
        self.render_time += t.elapsed();
        let mut rejoined = false;
        for (i, mut frame) in frames.drain(..) {
            let id = self.roster.ids[i];
            let cycle = frame.header().cycle;
            if let Some((dir, every)) = &self.opts.dump_frames
                && cycle % every == 0
            {
                for image in frame.images_mut() {
                    dump_image(dir, cycle, id, &image)?;
                }
            }
            if let Some(log) = &mut self.rerun
                && log.wants_images(cycle)
            {
                for image in frame.images_mut() {
                    log.log_image(cycle, id, &image)?;
                }
            }
            self.host.publish(frame)?;
            if self.roster.evicted[i] && !self.host.is_evicted(id) && !self.host.has_left(id) {
                self.roster.evicted[i] = false;
                rejoined = true;
                self.events
                    .emit(Event::AgentRejoined { agent: id, cycle })?;
            }
        }
        self.frames = frames;
        Ok(rejoined)
    }

    /// Frame 2: collect, apply in (agent id, order sent) order, report, advance the world,
    /// record. Breaks on SIGINT/SIGTERM.
    fn frame2(&mut self, mut notable: bool) -> anyhow::Result<ControlFlow<()>> {
        let wait_started = Instant::now();
        let collected = self.host.collect();
        let wait = wait_started.elapsed();
        self.last_collect = wait;
        let report = match collected {
            Ok(r) => r,
            Err(HostCycleError::Terminated) => {
                self.interrupted = true;
                return Ok(ControlFlow::Break(()));
            }
            Err(e) => {
                return Err(e).context("cycle failed");
            }
        };
        let cycle = report.cycle;
        let timed_out_agents: Vec<u32> = report.timed_out_agents().collect();
        let slow_agents: Vec<u32> = report.slow_agents().collect();
        let late_batches = report.late_batches;
        notable |= self.roster.note_leaves(report, &mut self.events)?;
        let per_agent = self.commands.apply(
            report,
            &mut self.world,
            &mut self.events,
            self.record.is_some() || self.rerun.is_some(),
        )?;
        for &(id, n) in &self.commands.rejected_per_agent {
            self.host.set_rejected(id, n);
        }
        notable |= self.roster.note_evictions(&self.host);
        if self.events.enabled()
            && (notable
                || cycle % CYCLE_EVENT_EVERY == 0
                || late_batches > 0
                || !timed_out_agents.is_empty()
                || !slow_agents.is_empty())
        {
            self.events.emit(Event::Cycle {
                cycle,
                timed_out_agents,
                slow_agents,
                late_batches,
            })?;
        }
        self.world.step();
        self.hasher.update(&cycle.to_le_bytes());
        self.world.hash_into(&mut self.hasher);
        if let Some(t) = &mut self.trails {
            t.push(&self.world);
        }
        if let Some(log) = &mut self.rerun {
            log.log_cycle(&CycleData {
                cycle,
                world: &self.world,
                commands: &per_agent,
                agents: &self.roster.ids,
                sensed: &self.roster.sensed,
                wait,
                render: self.render_time - self.render_time_at_cycle_start,
                stop_timeouts: self.host.stats().stop_timeouts,
            })?;
        }
        self.render_time_at_cycle_start = self.render_time;
        self.write_record(cycle, per_agent)?;
        self.done += 1;
        if let Some(bar) = &self.bar {
            bar.inc(1);
        }
        self.end_of_cycle(cycle)
    }

    /// Appends one line per agent of `cycle` to the recording (`--record`).
    fn write_record(&mut self, cycle: u64, per_agent: Vec<AgentCommands>) -> anyhow::Result<()> {
        let Some(out) = &mut self.record else {
            return Ok(());
        };
        let dt = self.opts.config.sync.simulation_time_per_frame;
        let sim_time_s = (cycle as f64 + 1.0) * dt.as_secs_f64();
        for agent in per_agent {
            let Some(body) = self.world.bodies().iter().find(|b| b.id == agent.agent) else {
                continue;
            };
            let sensed = self
                .roster
                .ids
                .iter()
                .position(|&id| id == agent.agent)
                .is_some_and(|i| self.roster.sensed[i]);
            let line = AgentLine::of(
                body,
                cycle,
                sim_time_s,
                agent.outcome.as_str(),
                sensed,
                agent.applied,
                agent.rejected,
                &agent.sent,
            );
            write_line(out, &line)?;
        }
        Ok(())
    }

    /// After a cycle: a spawned agent that exited fails the run (unless evicted under
    /// `on_agent_lost = "evict"`); SIGINT/SIGTERM ends it.
    fn end_of_cycle(&mut self, cycle: u64) -> anyhow::Result<ControlFlow<()>> {
        if let Some((id, status)) = self.agents.failed()
            && !self.host.stats().evicted_agents.contains(&id)
            && self.opts.config.sync.on_agent_lost != vrsync_bridge::AgentLostPolicy::Evict
        {
            bail!("agent {id} exited during cycle {cycle} ({status})");
        }
        if self.host.termination_requested() {
            self.interrupted = true;
            return Ok(ControlFlow::Break(()));
        }
        Ok(ControlFlow::Continue(()))
    }

    /// Flushes the outputs, closes the session, waits for spawned agents and sums up.
    fn finish(self) -> anyhow::Result<Summary> {
        let Self {
            bar,
            record,
            trails,
            rerun,
            agents,
            _bound_config,
            host,
            renderer,
            world,
            opts,
            events: _,
            roster,
            batch: _,
            frames: _,
            commands,
            hasher,
            render_time,
            render_time_at_cycle_start: _,
            last_collect: _,
            loop_started,
            done,
            interrupted,
            error,
        } = self;
        let config = &opts.config;
        let wall = loop_started.elapsed();
        if let Some(bar) = bar {
            bar.finish_and_clear();
        }
        let trajectory_hash = hasher.finalize().to_hex().to_string();
        if let Some(mut out) = record {
            write_line(
                &mut out,
                &record::End {
                    record: "end".into(),
                    cycles: done,
                    trajectory_hash: trajectory_hash.clone(),
                    interrupted,
                    commands_applied: commands.applied,
                    commands_rejected: commands.rejected,
                },
            )?;
            out.flush().context("write record")?;
        }
        if let Some(log) = rerun
            && let Err(e) = log.finish()
        {
            // The run itself is done: a viewer closed before the end is no failure.
            warn!("the Rerun log may be incomplete: {e}");
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
        let dt = config.sync.simulation_time_per_frame;
        let wall_s = wall.as_secs_f64();
        let summary = Summary {
            mode: if sync_mode { "sync" } else { "async" }.into(),
            transport: config.transport.kind.as_str().into(),
            agents: roster.ids.len(),
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
            resumes: stats.resumes,
            frames_delivered: stats.frames_delivered,
            frames_read: stats.frames_read,
            frames_undelivered: stats.frames_undelivered,
            future_stops: stats.future_batches,
            commands_overflowed: stats.commands_overflowed,
            statuses_dropped: stats.statuses_dropped,
            collisions_dropped: stats.collisions_dropped,
            commands_applied: commands.applied,
            commands_rejected: commands.rejected,
            trajectory_hash,
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
}

/// Writes one JSON line of the recording.
fn write_line(out: &mut impl Write, line: &impl serde::Serialize) -> anyhow::Result<()> {
    serde_json::to_writer(&mut *out, line).context("write record")?;
    out.write_all(b"\n").context("write record")
}
