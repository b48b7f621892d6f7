//! `vr-sim replay RECORD`: re-runs a recorded run's commands without agents and checks
//! that the world takes the same trajectory.
//!
//! The world is built from the config in the record's header. Cycle by cycle, as `run`
//! does: the agents whose sensor frame the run wrote (`sensed`) hand over their pending
//! statuses, collisions and reward; every recorded command is applied in the recorded
//! order (the run's application order: config's agent order, then the order sent), and
//! must be accepted or rejected as it was in the run; the world advances one step; each
//! agent's state is compared with its line. The first difference ends the replay (exit 1,
//! naming the cycle, agent and field); at the end the trajectory hash is compared with the
//! record's.
//!
//! Images are rendered only for `--dump-frames`, with the record's cameras or others
//! (`--config`, `--camera-size`): the world keeps the recorded cameras, so commands that
//! name a pixel resolve exactly as in the run.

use std::fs::File;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};

use anyhow::Context;
use serde::Deserialize;
use serde_json::Value;
use tracing::warn;
use vrsync_bridge::{AgentConfig, Config, ImageMut, SensorHeader};

use crate::picture::{Trails, dump_image, write_map};
use crate::record::{self, AgentLine, End, Header, STATE_KEYS, Sent};
use crate::render::Renderer;
use crate::world::{CameraSpec, World};

/// What to replay and what to write.
#[derive(Debug)]
pub struct ReplayOptions {
    /// The `vr-sim run --record` file.
    pub record: PathBuf,
    /// Render with the cameras of this config's `[[agent]]` entries (by agent id).
    pub config: Option<PathBuf>,
    /// Render every camera at this size (horizontal field of view kept).
    pub camera_size: Option<(u32, u32)>,
    /// Write every sensed agent's images as PNG into this folder every `.1` cycles.
    pub dump_frames: Option<(PathBuf, u64)>,
    /// Top-down map of the replayed trajectories.
    pub map: Option<PathBuf>,
    /// Threads shading image rows.
    pub render_threads: usize,
    /// Whether the render threads are bound to CPUs.
    pub render_affinity: crate::render::Affinity,
}

/// A record that cannot be replayed: unreadable, malformed, truncated or of another
/// format version. Bad input: `vr-sim replay` exits with 2.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RecordReadError {
    /// The file cannot be read.
    #[error("cannot read the record {path}: {error}")]
    Read {
        /// The record.
        path: PathBuf,
        /// Why.
        error: std::io::Error,
    },
    /// A line is not what the format says.
    #[error("{path}:{line}: not a vr-sim record line: {reason}")]
    Malformed {
        /// The record.
        path: PathBuf,
        /// Line number (1-based).
        line: u64,
        /// What is wrong.
        reason: String,
    },
    /// The record ends before its end line.
    #[error(
        "{path} is truncated: {reason} (the run did not end normally, or the file was cut); \
         the cycles it holds replayed identically, but its trajectory hash cannot be checked"
    )]
    Truncated {
        /// The record.
        path: PathBuf,
        /// What is missing.
        reason: String,
    },
    /// A record of another format version.
    #[error(
        "{path}: {reason}; this vr-sim replays records of format version {}",
        record::VERSION
    )]
    Version {
        /// The record.
        path: PathBuf,
        /// What was found.
        reason: String,
    },
}

/// The replay left the recorded trajectory: `vr-sim replay` exits with 1.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ReplayDivergedError {
    /// An agent's state, or the fate of one of its commands, differs at a cycle.
    #[error("the replay diverges from {path} at cycle {cycle}, agent {agent}: {what}")]
    Cycle {
        /// The record.
        path: PathBuf,
        /// The first cycle that differs.
        cycle: u64,
        /// The first agent (in application order) that differs in it.
        agent: u32,
        /// What differs.
        what: String,
    },
    /// Every agent line matched, the trajectory hash did not (an object's position).
    #[error(
        "the replay of {path} matches every agent line but not the trajectory hash: \
         {recorded} recorded, {replayed} replayed"
    )]
    Hash {
        /// The record.
        path: PathBuf,
        /// The record's hash.
        recorded: String,
        /// The replay's hash.
        replayed: String,
    },
}

/// A replay that followed the record to its end.
#[derive(Debug)]
pub struct Replayed {
    /// Cycles replayed.
    pub cycles: u64,
    /// Agents.
    pub agents: usize,
    /// Commands applied and rejected (as in the run).
    pub commands_applied: u64,
    /// Commands rejected.
    pub commands_rejected: u64,
    /// The trajectory hash (equal to the record's).
    pub trajectory_hash: String,
    /// PNG files written.
    pub frames_written: u64,
}

/// The fields of an agent line the replay reads.
#[derive(Debug, Deserialize)]
struct AgentIn {
    cycle: u64,
    agent: u32,
    sim_time_s: f64,
    outcome: String,
    sensed: bool,
    sent: Vec<Sent>,
}

/// One agent line: what it says and the line as written (for the comparison).
struct Line {
    number: u64,
    agent: AgentIn,
    value: Value,
}

/// The cameras an agent's images are rendered with in the replay, and a buffer for them.
struct RenderSet {
    cameras: Vec<CameraSpec>,
    config: AgentConfig,
    buffer: Vec<u8>,
}

/// The cycle of one cycle's lines (`group`, not empty), checked: it follows `last`, and it
/// has one line per agent of the header (`agents`), in that order.
fn check_group(
    path: &Path,
    group: &[Line],
    last: Option<u64>,
    agents: &[u32],
) -> Result<u64, RecordReadError> {
    let cycle = group[0].agent.cycle;
    if let Some(last) = last
        && cycle <= last
    {
        return Err(RecordReadError::Malformed {
            path: path.to_owned(),
            line: group[0].number,
            reason: format!("cycle {cycle} follows cycle {last}"),
        });
    }
    let ids: Vec<u32> = group.iter().map(|l| l.agent.agent).collect();
    if ids != agents {
        return Err(RecordReadError::Malformed {
            path: path.to_owned(),
            line: group[0].number,
            reason: format!(
                "cycle {cycle} has lines for agents {ids:?}; every cycle has one per \
                 agent of the header, {agents:?}, in that order"
            ),
        });
    }
    Ok(cycle)
}

/// Replays `opts.record`.
///
/// # Errors
/// [`RecordReadError`] for a record that cannot be replayed, [`ReplayDivergedError`] when
/// the trajectory differs, config and world errors for the header's or `--config`'s
/// config, I/O errors writing frames or the map.
pub fn replay(opts: &ReplayOptions) -> anyhow::Result<Replayed> {
    let path = &opts.record;
    let file = File::open(path).map_err(|error| RecordReadError::Read {
        path: path.clone(),
        error,
    })?;
    let mut lines = Lines {
        path: path.clone(),
        inner: BufReader::new(file).lines(),
        number: 0,
    };
    let header = lines.header()?;
    let config = Config::from_toml_str(
        &header.config,
        &PathBuf::from(format!("{} (header config)", path.display())),
    )?;
    let config_ids: Vec<u32> = config.agents.iter().map(|a| a.id).collect();
    if config_ids != header.agents {
        return Err(lines.malformed(format!(
            "the header lists agents {:?}, its config {config_ids:?}",
            header.agents
        )));
    }
    let mut world = World::from_config(&config)?;
    let mut renders = render_sets(&config, opts)?;
    let mut renderer = match &opts.dump_frames {
        Some((dir, _)) => {
            std::fs::create_dir_all(dir)
                .with_context(|| format!("cannot create {}", dir.display()))?;
            Some(Renderer::with_affinity(
                opts.render_threads,
                opts.render_affinity,
            )?)
        }
        None => None,
    };
    let mut trails = opts.map.as_ref().map(|_| Trails::new(&world));
    let mut hasher = blake3::Hasher::new();
    let mut scratch = SensorHeader::default();
    let mut state = Counts::default();
    let mut group: Vec<Line> = Vec::with_capacity(header.agents.len());
    let end = loop {
        let next = lines.next_line()?;
        let ends_group = match &next {
            Some(Next::Agent(l)) => group
                .first()
                .is_some_and(|g| g.agent.cycle != l.agent.cycle),
            Some(Next::End(_)) | None => !group.is_empty(),
        };
        if ends_group {
            let cycle = check_group(path, &group, state.last_cycle, &header.agents)?;
            if let (Some(r), Some((dir, every))) = (&mut renderer, &opts.dump_frames)
                && cycle.is_multiple_of(*every)
            {
                for l in group.iter().filter(|l| l.agent.sensed) {
                    state.frames_written +=
                        render(r, &world, l.agent.agent, &mut renders, dir, cycle)?;
                }
            }
            for l in &group {
                if l.agent.sensed {
                    world.write_sensors(l.agent.agent, &mut scratch);
                }
            }
            let mut replayed = Vec::with_capacity(group.len());
            for l in &group {
                replayed.push(apply(&mut world, path, cycle, l, &mut state)?);
            }
            world.step();
            hasher.update(&cycle.to_le_bytes());
            world.hash_into(&mut hasher);
            if let Some(t) = &mut trails {
                t.push(&world);
            }
            for (l, (names, rejected)) in group.iter().zip(replayed) {
                compare(&world, path, cycle, l, names, rejected)?;
            }
            state.last_cycle = Some(cycle);
            state.cycles += 1;
            group.clear();
        }
        match next {
            Some(Next::Agent(l)) => group.push(l),
            Some(Next::End(end)) => break end,
            None => {
                return Err(RecordReadError::Truncated {
                    path: path.clone(),
                    reason: match state.last_cycle {
                        Some(c) => format!(
                            "no end line after {} cycles (last: cycle {c})",
                            state.cycles
                        ),
                        None => "no end line and no cycle".into(),
                    },
                }
                .into());
            }
        }
    };
    lines.expect_eof()?;
    if let (Some(map), Some(trails)) = (&opts.map, &trails) {
        write_map(map, &world, trails)?;
    }
    if end.cycles != state.cycles {
        return Err(RecordReadError::Truncated {
            path: path.clone(),
            reason: format!(
                "the end line counts {} cycles, the record holds {}",
                end.cycles, state.cycles
            ),
        }
        .into());
    }
    let trajectory_hash = hasher.finalize().to_hex().to_string();
    if trajectory_hash != end.trajectory_hash {
        return Err(ReplayDivergedError::Hash {
            path: path.clone(),
            recorded: end.trajectory_hash,
            replayed: trajectory_hash,
        }
        .into());
    }
    Ok(Replayed {
        cycles: state.cycles,
        agents: header.agents.len(),
        commands_applied: state.applied,
        commands_rejected: state.rejected,
        trajectory_hash,
        frames_written: state.frames_written,
    })
}

/// What the replay counted.
#[derive(Debug, Default)]
struct Counts {
    cycles: u64,
    last_cycle: Option<u64>,
    applied: u64,
    rejected: u64,
    frames_written: u64,
}

/// Applies line `l`'s commands as the run did; returns the applied `[name, action id]`
/// list and the rejected count the line must show.
fn apply(
    world: &mut World,
    path: &Path,
    cycle: u64,
    l: &Line,
    counts: &mut Counts,
) -> anyhow::Result<(Vec<(&'static str, u32)>, u32)> {
    let agent = l.agent.agent;
    let mut names = Vec::new();
    let mut rejected = 0u32;
    for (k, sent) in l.agent.sent.iter().enumerate() {
        let result = match sent.command.command() {
            Some(cmd) => world
                .apply(agent, sent.action, cmd)
                .map(|()| cmd)
                .map_err(|e| e.to_string()),
            // Rejected at decoding in the run: it never reached the world.
            None => Err(sent
                .error
                .clone()
                .unwrap_or_else(|| "did not decode".into())),
        };
        let fate = |ok: bool| if ok { "applied" } else { "rejected" };
        if result.is_ok() == sent.error.is_some() {
            return Err(ReplayDivergedError::Cycle {
                path: path.to_path_buf(),
                cycle,
                agent,
                what: format!(
                    "command {k} of the cycle (action {}, {:?}) was {} in the run{} and is {} \
                     in the replay{}",
                    sent.action,
                    sent.command,
                    fate(sent.error.is_none()),
                    sent.error
                        .as_ref()
                        .map(|e| format!(" ({e})"))
                        .unwrap_or_default(),
                    fate(result.is_ok()),
                    result
                        .as_ref()
                        .err()
                        .map(|e| format!(" ({e})"))
                        .unwrap_or_default(),
                ),
            }
            .into());
        }
        match result {
            Ok(cmd) => {
                counts.applied += 1;
                names.push((cmd.name(), sent.action));
            }
            Err(_) => {
                counts.rejected += 1;
                rejected += 1;
            }
        }
    }
    Ok((names, rejected))
}

/// Compares agent `l`'s state after the cycle with its line, field by field, each as the
/// run would have written it.
fn compare(
    world: &World,
    path: &Path,
    cycle: u64,
    l: &Line,
    names: Vec<(&'static str, u32)>,
    rejected: u32,
) -> anyhow::Result<()> {
    let a = &l.agent;
    let body = world
        .bodies()
        .iter()
        .find(|b| b.id == a.agent)
        .with_context(|| format!("agent {} has no body", a.agent))?;
    let line = AgentLine::of(
        body,
        cycle,
        a.sim_time_s,
        &a.outcome,
        a.sensed,
        names,
        rejected,
        &a.sent,
    );
    // Through text, as the run wrote it: equal values give equal JSON.
    let replayed: Value = serde_json::from_str(&serde_json::to_string(&line)?)?;
    for key in STATE_KEYS {
        if replayed[key] != l.value[key] {
            return Err(ReplayDivergedError::Cycle {
                path: path.to_path_buf(),
                cycle,
                agent: a.agent,
                what: format!(
                    "`{key}` is {} in the record (line {}), {} in the replay",
                    l.value[key], l.number, replayed[key]
                ),
            }
            .into());
        }
    }
    Ok(())
}

/// Renders agent `id`'s images with its replay cameras and writes them as PNG; returns
/// how many.
fn render(
    renderer: &mut Renderer,
    world: &World,
    id: u32,
    renders: &mut [(u32, RenderSet)],
    dir: &Path,
    cycle: u64,
) -> anyhow::Result<u64> {
    let Some((_, set)) = renders.iter_mut().find(|(a, _)| *a == id) else {
        return Ok(0);
    };
    let Some(body) = world.bodies().iter().find(|b| b.id == id) else {
        return Ok(0);
    };
    let view = body.with_cameras(set.cameras.clone());
    let (descs, _) = set.config.image_layout();
    let mut written = 0;
    for desc in &descs[..set.cameras.len()] {
        let (start, len) = (desc.offset as usize, desc.len as usize);
        let data = set
            .buffer
            .get_mut(start..start + len)
            .context("image layout outside its buffer")?;
        renderer.render_image(
            world,
            &view,
            ImageMut {
                desc: *desc,
                data: &mut *data,
            },
        );
        dump_image(dir, cycle, id, &ImageMut { desc: *desc, data })?;
        written += 1;
    }
    Ok(written)
}

/// Every agent's replay cameras: the record's, those of `--config` for the agents it
/// lists, then resized by `--camera-size`.
fn render_sets(recorded: &Config, opts: &ReplayOptions) -> anyhow::Result<Vec<(u32, RenderSet)>> {
    let other = opts.config.as_ref().map(Config::load).transpose()?;
    if let Some(other) = &other {
        if other.world != recorded.world {
            warn!(
                "{}: its [world] differs from the record's; replay uses only its cameras",
                other.source.display()
            );
        }
        for a in &other.agents {
            if recorded.agent(a.id).is_none() {
                warn!(
                    "{}: agent {} is not in the record; its cameras are not used",
                    other.source.display(),
                    a.id
                );
            }
        }
    }
    let mut sets = Vec::with_capacity(recorded.agents.len());
    for a in &recorded.agents {
        let mut agent = other.as_ref().and_then(|o| o.agent(a.id)).map_or_else(
            || a.clone(),
            |o| AgentConfig {
                id: a.id,
                ..o.clone()
            },
        );
        if let Some((w, h)) = opts.camera_size {
            for c in &mut agent.cameras {
                if u64::from(w) * u64::from(c.height_px) != u64::from(h) * u64::from(c.width_px) {
                    // Square pixels: the horizontal field of view stays, the vertical one
                    // follows the new aspect.
                    let half_h = (c.fov_horizontal_deg.to_radians() / 2.0).tan();
                    c.fov_vertical_deg = (2.0 * (half_h * h as f32 / w as f32).atan()).to_degrees();
                }
                (c.width_px, c.height_px) = (w, h);
            }
        }
        let (_, bytes) = agent.image_layout();
        sets.push((
            a.id,
            RenderSet {
                cameras: agent.cameras.iter().map(CameraSpec::from).collect(),
                buffer: vec![0; bytes],
                config: agent,
            },
        ));
    }
    Ok(sets)
}

/// What follows the header.
enum Next {
    Agent(Line),
    End(End),
}

/// The record's lines, numbered.
struct Lines {
    path: PathBuf,
    inner: std::io::Lines<BufReader<File>>,
    number: u64,
}

impl Lines {
    fn malformed(&self, reason: String) -> anyhow::Error {
        RecordReadError::Malformed {
            path: self.path.clone(),
            line: self.number,
            reason,
        }
        .into()
    }

    /// The next line as JSON (`None` at the end of the file).
    fn next_value(&mut self) -> anyhow::Result<Option<Value>> {
        let Some(text) = self.inner.next() else {
            return Ok(None);
        };
        self.number += 1;
        let text = text.map_err(|error| RecordReadError::Read {
            path: self.path.clone(),
            error,
        })?;
        serde_json::from_str(&text).map(Some).map_err(|e| {
            if e.is_eof() {
                RecordReadError::Truncated {
                    path: self.path.clone(),
                    reason: format!("line {} is cut off ({e})", self.number),
                }
                .into()
            } else {
                self.malformed(format!("{e}"))
            }
        })
    }

    fn header(&mut self) -> anyhow::Result<Header> {
        let Some(value) = self.next_value()? else {
            return Err(RecordReadError::Truncated {
                path: self.path.clone(),
                reason: "the file is empty".into(),
            }
            .into());
        };
        if value.get("agent").is_some() && value.get("record").is_none() {
            return Err(RecordReadError::Version {
                path: self.path.clone(),
                reason: "no header line: a record of format version 1 (vr-sim before replay: no \
                         config, no command arguments)"
                    .into(),
            }
            .into());
        }
        if value["record"] != "header" || value["format"] != record::FORMAT {
            return Err(self.malformed(format!(
                "the first line is not a header {{\"record\":\"header\",\"format\":\"{}\",…}}",
                record::FORMAT
            )));
        }
        if value["version"] != record::VERSION {
            return Err(RecordReadError::Version {
                path: self.path.clone(),
                reason: format!("format version {}", value["version"]),
            }
            .into());
        }
        Header::deserialize(&value).map_err(|e| self.malformed(format!("header: {e}")))
    }

    /// The next agent line or the end line (`None`: the file ended without an end line).
    fn next_line(&mut self) -> anyhow::Result<Option<Next>> {
        let Some(value) = self.next_value()? else {
            return Ok(None);
        };
        if value.get("agent").is_some() {
            let agent = AgentIn::deserialize(&value)
                .map_err(|e| self.malformed(format!("agent line: {e}")))?;
            return Ok(Some(Next::Agent(Line {
                number: self.number,
                agent,
                value,
            })));
        }
        if value["record"] == "end" {
            let end =
                End::deserialize(&value).map_err(|e| self.malformed(format!("end line: {e}")))?;
            return Ok(Some(Next::End(end)));
        }
        Err(self.malformed("neither an agent line nor the end line".into()))
    }

    /// Nothing but blank lines after the end line.
    fn expect_eof(&mut self) -> anyhow::Result<()> {
        while let Some(text) = self.inner.next() {
            self.number += 1;
            let text = text.map_err(|error| RecordReadError::Read {
                path: self.path.clone(),
                error,
            })?;
            if !text.trim().is_empty() {
                return Err(self.malformed("a line after the end line".into()));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests;
