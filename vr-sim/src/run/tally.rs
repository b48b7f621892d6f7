//! What the run keeps per agent: the roster (ids, and what the events last said of each)
//! and the tally of the commands applied to the world.

use std::collections::BTreeSet;

use tracing::warn;
use vrsync_bridge::{CycleReport, Host};

use crate::events::{Event, Events};
use crate::record::{self, AgentCommands, Sent};
use crate::world::World;

/// The agents of the run and what the events last said about each (index = position in
/// `ids`).
pub(super) struct Roster {
    pub(super) ids: Vec<u32>,
    /// Connected as last reported (all connected after the first wait).
    pub(super) connected: Vec<bool>,
    /// Whether this cycle's frame 1 wrote the agent's sensors (which clears its pending
    /// statuses, collisions and reward): recorded for the replay.
    pub(super) sensed: Vec<bool>,
    /// Evicted or left, remembered to report a rejoin.
    pub(super) evicted: Vec<bool>,
}

/// Applies the agents' commands to the world and counts them.
pub(super) struct CommandTally {
    pub(super) applied: u64,
    pub(super) rejected: u64,
    /// (agent, command kind) rejections already logged: further ones are counted only.
    pub(super) logged: BTreeSet<(u32, &'static str)>,
    /// Reused every cycle: no allocation per cycle in the steady state.
    pub(super) rejected_per_agent: Vec<(u32, u32)>,
}

impl Roster {
    /// Reports the agents that left gracefully during the report's cycle; returns whether
    /// one did.
    pub(super) fn note_leaves(
        &mut self,
        report: &CycleReport,
        events: &mut Events,
    ) -> anyhow::Result<bool> {
        let mut notable = false;
        for (i, &id) in self.ids.iter().enumerate() {
            if report.agent(id).is_some_and(|a| a.left) {
                // Reported here, not again at the next cycle boundary; a new connection
                // of the id shows as connected, then rejoined.
                self.connected[i] = false;
                self.evicted[i] = true;
                notable = true;
                events.emit(Event::AgentLeft {
                    agent: id,
                    cycle: report.cycle,
                    graceful: true,
                })?;
            }
        }
        Ok(notable)
    }

    /// Remembers the agents the host evicted (its on_evicted hook reported them) for their
    /// rejoin; returns whether there was a new one.
    pub(super) fn note_evictions(&mut self, host: &Host) -> bool {
        let mut notable = false;
        for (i, &id) in self.ids.iter().enumerate() {
            if !self.evicted[i] && host.is_evicted(id) {
                self.evicted[i] = true;
                notable = true;
            }
        }
        notable
    }
}

impl CommandTally {
    /// Applies every agent's commands of `report` to the world in (agent id, order sent)
    /// order, counting and reporting rejections (each (agent, kind) logged once); fills
    /// `rejected_per_agent`. Returns what the recording needs (nothing when `recording`
    /// is off).
    pub(super) fn apply(
        &mut self,
        report: &CycleReport,
        world: &mut World,
        events: &mut Events,
        recording: bool,
    ) -> anyhow::Result<Vec<AgentCommands>> {
        let mut per_agent = Vec::with_capacity(if recording { report.agents().len() } else { 0 });
        self.rejected_per_agent.clear();
        for a in report.agents() {
            let mut rejected = 0u32;
            let mut names = Vec::new();
            let mut sent = Vec::new();
            for wire in a.commands() {
                let decoded = wire.decode();
                let result = decoded
                    .map_err(crate::world::CommandRejected::from)
                    .and_then(|cmd| world.apply(a.agent_id, wire.action_id, cmd).map(|()| cmd));
                if recording {
                    sent.push(Sent {
                        action: wire.action_id,
                        command: decoded.map_or(
                            record::RecordedCommand::Undecoded { tag: wire.kind },
                            Into::into,
                        ),
                        error: result.as_ref().err().map(ToString::to_string),
                    });
                }
                match result {
                    Ok(cmd) => {
                        self.applied += 1;
                        if recording {
                            names.push((cmd.name(), wire.action_id));
                        }
                    }
                    Err(e) => {
                        rejected += 1;
                        let kind = vrsync_bridge::kind_name(wire.kind);
                        if self.logged.insert((a.agent_id, kind)) {
                            events.emit(Event::CommandRejected {
                                agent: a.agent_id,
                                cycle: report.cycle,
                                kind,
                                reason: e.to_string(),
                            })?;
                            warn!(
                                agent = a.agent_id,
                                cycle = report.cycle,
                                "command rejected: {e} (further `{kind}` rejections of this agent are counted, not logged)"
                            );
                        }
                    }
                }
            }
            self.rejected += u64::from(rejected);
            self.rejected_per_agent.push((a.agent_id, rejected));
            if recording {
                per_agent.push(AgentCommands {
                    agent: a.agent_id,
                    outcome: a.outcome,
                    applied: names,
                    rejected,
                    sent,
                });
            }
        }
        Ok(per_agent)
    }
}
