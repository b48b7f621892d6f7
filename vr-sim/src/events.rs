//! `vr-sim run --events FILE`: what happens in a run, one JSON object per line, written
//! and flushed as it happens, for tests and users' tooling (instead of reading log text).
//!
//! Every line has `"event"` (the kind) and `"wall_s"` (seconds since the run started);
//! the other keys depend on the kind:
//!
//! | event | keys |
//! |---|---|
//! | `listening` | `session`, `transport`, `address` (TCP: the *bound* address, so `tcp_listen` port 0 works; `null` on shared memory) |
//! | `waiting_for_agents` | `agents` (the ids not connected yet) |
//! | `agent_connected` | `agent`, `cycle` (`null` before cycle 0) |
//! | `all_agents_connected` | `agents` (how many) |
//! | `agent_left` | `agent`, `cycle`, `graceful`: `true`: the agent said it leaves (its SDK's `close()` or drop), written when the host read that (the cycle it left in); `false`: its connection was seen gone at a cycle boundary (the cycle about to start) |
//! | `agent_evicted` | `agent`, `cycle`, `reason`: written as the host evicts it (also while a cycle waits for it) |
//! | `agent_rejoined` | `agent`, `cycle` (the first cycle it takes part in again) |
//! | `agent_slow` | `agent`, `cycle`, `waited_s`: the host still waits for this live agent's stop past `stop_timeout` (`wait_for_stop = "alive"`); written as it happens, at 1×, 2×, 4×, … `stop_timeout` into the cycle |
//! | `peer_refused` | `kind` (`malformed`, `version`, `token`, `unknown_agent`, `id_in_use`, `silent`, `too_many`, `tls`), `agent` (the id it claimed, or `null`), `peer` (its address), `reason`: a connection the host refused or dropped before admitting it as an agent (at most 256 per wait are itemised; the summary counts all) |
//! | `command_rejected` | `agent`, `cycle`, `kind`, `reason`: the first rejection per agent and command kind (later ones are only counted in the summary) |
//! | `cycle` | `cycle`, `timed_out_agents`, `slow_agents`, `late_batches`: sampled, see below |
//! | `finished` | `frames`, `interrupted`, `trajectory_hash`, `summary` (the `--summary-json` path or `null`) |
//! | `error` | `message`: the run failed (exit 1 or 2); nothing follows |
//!
//! `cycle` lines are sampled to keep the file small on long runs: cycle 0, every 1000th
//! cycle, and every cycle in which something happened (a stop timeout, late batches
//! dropped, an agent slow, evicted or rejoined).

use std::cell::RefCell;
use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::rc::Rc;
use std::time::Instant;

use anyhow::Context;
use serde::Serialize;

/// Cycles whose number is a multiple of this get a `cycle` event even when nothing happened.
pub const CYCLE_EVENT_EVERY: u64 = 1000;

/// One event (see the module doc for the keys).
#[derive(Debug, Serialize)]
#[serde(tag = "event", rename_all = "snake_case")]
pub enum Event<'a> {
    /// The host exists and accepts agents.
    Listening {
        /// Session name.
        session: &'a str,
        /// `shm` or `tcp`.
        transport: &'a str,
        /// TCP: the bound address.
        address: Option<String>,
    },
    /// The host waits for these agents.
    WaitingForAgents {
        /// Ids not connected yet.
        agents: Vec<u32>,
    },
    /// An agent connected.
    AgentConnected {
        /// Agent id.
        agent: u32,
        /// The cycle about to start (`None` before cycle 0).
        cycle: Option<u64>,
    },
    /// Every configured agent is connected; cycle 0 starts.
    AllAgentsConnected {
        /// Number of agents.
        agents: usize,
    },
    /// An agent's connection is gone.
    AgentLeft {
        /// Agent id.
        agent: u32,
        /// Graceful: the cycle it left in; else the cycle about to start.
        cycle: u64,
        /// The agent said it leaves (a graceful leave), rather than its connection being
        /// seen gone.
        graceful: bool,
    },
    /// The host evicted an agent.
    AgentEvicted {
        /// Agent id.
        agent: u32,
        /// The cycle during which it was evicted.
        cycle: u64,
        /// Why, as far as vr-sim knows.
        reason: String,
    },
    /// An evicted agent is back.
    AgentRejoined {
        /// Agent id.
        agent: u32,
        /// The first cycle it takes part in again.
        cycle: u64,
    },
    /// The host still waits for a live agent's stop past `stop_timeout`.
    AgentSlow {
        /// Agent id.
        agent: u32,
        /// The cycle.
        cycle: u64,
        /// Seconds waited in this cycle so far.
        waited_s: f64,
    },
    /// The host refused or dropped a peer before admitting it as an agent.
    PeerRefused {
        /// Why, as a category (`RefusalKind::as_str`).
        kind: &'static str,
        /// The agent id it claimed, if it got that far.
        agent: Option<u32>,
        /// Its address.
        peer: String,
        /// Why, for a person.
        reason: String,
    },
    /// A command was rejected (first of its agent and kind).
    CommandRejected {
        /// Agent id.
        agent: u32,
        /// Cycle.
        cycle: u64,
        /// Command kind.
        kind: &'a str,
        /// Why.
        reason: String,
    },
    /// A cycle ended (sampled).
    Cycle {
        /// Cycle number.
        cycle: u64,
        /// Agents whose stop did not arrive within `stop_timeout`.
        timed_out_agents: Vec<u32>,
        /// Agents waited for past `stop_timeout` (alive and busy).
        slow_agents: Vec<u32>,
        /// Late batches dropped during this cycle.
        late_batches: u32,
    },
    /// The run ended normally.
    Finished {
        /// Cycles completed.
        frames: u64,
        /// Whether SIGINT/SIGTERM ended it.
        interrupted: bool,
        /// The run's trajectory hash.
        trajectory_hash: &'a str,
        /// Where the summary JSON was written.
        summary: Option<&'a Path>,
    },
    /// The run failed.
    Error {
        /// The error, with its causes.
        message: String,
    },
}

/// The events file of a run, or nothing (every call is then a no-op). Clones write to the
/// same file (the host's eviction hook holds one).
#[derive(Debug, Clone)]
pub struct Events {
    out: Option<Rc<RefCell<(File, PathBuf)>>>,
    started: Instant,
}

impl Events {
    /// No events file.
    pub fn disabled() -> Self {
        Self {
            out: None,
            started: Instant::now(),
        }
    }

    /// Creates (truncates) `path`.
    ///
    /// # Errors
    /// The file cannot be created.
    pub fn create(path: &Path) -> anyhow::Result<Self> {
        let file =
            File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
        Ok(Self {
            out: Some(Rc::new(RefCell::new((file, path.to_path_buf())))),
            started: Instant::now(),
        })
    }

    /// Whether events are written.
    pub fn enabled(&self) -> bool {
        self.out.is_some()
    }

    /// Writes one event line and flushes it (unbuffered: one `write` per event, so a
    /// reader never sees half a line once the line is complete).
    ///
    /// # Errors
    /// The file cannot be written.
    pub fn emit(&mut self, event: Event<'_>) -> anyhow::Result<()> {
        let Some(out) = &self.out else {
            return Ok(());
        };
        let (file, path) = &mut *out.borrow_mut();
        #[derive(Serialize)]
        struct Line<'a> {
            #[serde(flatten)]
            event: Event<'a>,
            wall_s: f64,
        }
        let mut line = serde_json::to_vec(&Line {
            event,
            wall_s: self.started.elapsed().as_secs_f64(),
        })
        .context("serialise event")?;
        line.push(b'\n');
        file.write_all(&line)
            .and_then(|()| file.flush())
            .with_context(|| format!("cannot write {}", path.display()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn events_are_one_json_object_per_line_tagged_by_kind() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("events.jsonl");
        let mut events = Events::create(&path).unwrap();
        events
            .emit(Event::Listening {
                session: "s",
                transport: "tcp",
                address: Some("127.0.0.1:4000".into()),
            })
            .unwrap();
        events
            .emit(Event::AgentEvicted {
                agent: 1,
                cycle: 9,
                reason: "gone".into(),
            })
            .unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        let lines: Vec<serde_json::Value> = text
            .lines()
            .map(|l| serde_json::from_str(l).unwrap())
            .collect();
        assert_eq!(lines.len(), 2);
        assert_eq!(lines[0]["event"], "listening");
        assert_eq!(lines[0]["address"], "127.0.0.1:4000");
        assert!(lines[0]["wall_s"].as_f64().unwrap() >= 0.0);
        assert_eq!(lines[1]["event"], "agent_evicted");
        assert_eq!(lines[1]["agent"], 1);
        assert_eq!(lines[1]["cycle"], 9);
    }

    #[test]
    fn a_disabled_events_file_writes_nothing() {
        let mut events = Events::disabled();
        assert!(!events.enabled());
        events
            .emit(Event::WaitingForAgents { agents: vec![0] })
            .unwrap();
    }
}
