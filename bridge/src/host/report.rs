//! What a cycle and the host's life so far report: per agent, per cycle, counters.

use super::*;

/// The commands and outcome of one agent in one cycle.
#[derive(Debug, Clone)]
pub struct AgentReport {
    /// Agent id.
    pub agent_id: u32,
    /// How its cycle ended.
    pub outcome: AgentOutcome,
    /// The newest cycle whose frame the agent acknowledged having read (its batches say
    /// so), `None` before its first acknowledgement (and again after an eviction). A frame
    /// delivered to it and older than this, and never acknowledged, was skipped.
    pub read_cycle: Option<u64>,
    /// The agent was evicted during this cycle (lost: its process died or it
    /// disconnected), also when its stop had arrived first (then `outcome` stays
    /// [`AgentOutcome::Stopped`]).
    pub evicted: bool,
    /// The agent rejoined in this cycle: its first frame since an eviction or a leave
    /// reached it.
    pub rejoined: bool,
    /// The agent left the session gracefully during this cycle (its SDK's `close()` or
    /// drop said so): not a fault, not evicted; its id is free for a new connection, which
    /// takes part from the next cycle. If its stop had arrived first, `outcome` stays
    /// [`AgentOutcome::Stopped`].
    pub left: bool,
    /// The host waited for its stop past `stop_timeout` (its `wait_for_stop` is `"alive"`
    /// and it stayed connected): a slow agent, reported, not timed out.
    pub slow: bool,
    pub(super) commands: Vec<MotorCommand>,
    pub(super) actions: AgentActions,
}

impl AgentReport {
    /// Commands received this cycle, in the order the agent sent them. Decode each with
    /// [`MotorCommand::decode`]; the simulator decides what is out of range.
    pub fn commands(&self) -> &[MotorCommand] {
        &self.commands
    }

    /// The value of the action (`[[agent.action]]`) called `name` this cycle: the last
    /// complete value the agent sent in this cycle; `None` if it sent none (or `name` is
    /// not one of its actions). Values the config's bounds refuse never show up here
    /// ([`AgentReport::actions_rejected`]).
    pub fn action(&self, name: &str) -> Option<ActionValue<'_>> {
        self.actions.get(name)
    }

    /// Every action of the agent in config order, with its value this cycle (as
    /// [`AgentReport::action`]).
    pub fn actions(&self) -> impl Iterator<Item = (&str, Option<ActionValue<'_>>)> {
        self.actions.iter()
    }

    /// Action chunks refused this cycle: an unknown action, a value of the wrong length,
    /// out of its bounds or not finite, a choice out of range. None of it was applied.
    pub fn actions_rejected(&self) -> u32 {
        self.actions.rejected
    }
}

/// The result of one cycle.
#[derive(Debug, Clone)]
pub struct CycleReport {
    /// Cycle number.
    pub cycle: u64,
    /// Simulated time at the start of the cycle, ns.
    pub sim_time_ns: u64,
    /// Whether the cycle ended by the stop timeout.
    pub timed_out: bool,
    /// Batches for earlier cycles (or after a stop) dropped during this cycle.
    pub late_batches: u32,
    pub(super) agents: Vec<AgentReport>,
}

impl CycleReport {
    /// Every agent's report, in the config's agent order.
    pub fn agents(&self) -> &[AgentReport] {
        &self.agents
    }

    /// The report of agent `id` (`None`: not an agent of this session).
    pub fn agent(&self, id: u32) -> Option<&AgentReport> {
        self.agents.iter().find(|a| a.agent_id == id)
    }

    /// Ids of agents evicted during this cycle ([`AgentReport::evicted`]).
    pub fn evicted_agents(&self) -> impl Iterator<Item = u32> + '_ {
        self.agents.iter().filter(|a| a.evicted).map(|a| a.agent_id)
    }

    /// Ids of agents that rejoined in this cycle ([`AgentReport::rejoined`]).
    pub fn rejoined_agents(&self) -> impl Iterator<Item = u32> + '_ {
        self.agents
            .iter()
            .filter(|a| a.rejoined)
            .map(|a| a.agent_id)
    }

    /// Ids of agents that left gracefully during this cycle ([`AgentReport::left`]).
    pub fn left_agents(&self) -> impl Iterator<Item = u32> + '_ {
        self.agents.iter().filter(|a| a.left).map(|a| a.agent_id)
    }

    /// Ids of agents waited for past `stop_timeout` this cycle ([`AgentReport::slow`]).
    pub fn slow_agents(&self) -> impl Iterator<Item = u32> + '_ {
        self.agents.iter().filter(|a| a.slow).map(|a| a.agent_id)
    }

    /// Ids of agents that timed out this cycle.
    pub fn timed_out_agents(&self) -> impl Iterator<Item = u32> + '_ {
        self.agents
            .iter()
            .filter(|a| a.outcome == AgentOutcome::TimedOut)
            .map(|a| a.agent_id)
    }
}

/// Counters since the host was created.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct HostStats {
    /// Cycles completed.
    pub cycles: u64,
    /// Cycles that ended by the stop timeout.
    pub stop_timeouts: u64,
    /// Agent-cycles that timed out (one cycle with two missing agents counts 2).
    pub agent_timeouts: u64,
    /// Cycles in which the host waited past `stop_timeout` for an agent whose
    /// `wait_for_stop` is `"alive"` (it was busy, not lost: nothing was dropped).
    pub slow_stops: u64,
    /// Batches dropped because they named an earlier cycle or followed the stop.
    pub late_batches: u64,
    /// Batches dropped because they named a cycle that had not started.
    pub future_batches: u64,
    /// Commands received and handed over.
    pub commands_received: u64,
    /// Action chunks refused (see [`AgentReport::actions_rejected`]).
    pub actions_rejected: u64,
    /// Commands dropped because an agent exceeded `max_commands_per_cycle`.
    pub commands_overflowed: u64,
    /// Frames that reached no agent (not connected, or async TCP with a full socket).
    pub frames_undelivered: u64,
    /// Frames delivered to an agent.
    pub frames_delivered: u64,
    /// Frames an agent acknowledged having read (see [`AgentReport::read_cycle`]).
    /// `frames_delivered - frames_read` frames were skipped by their agent (a newer one
    /// was read first) or are still being read.
    pub frames_read: u64,
    /// Action statuses dropped because an agent's table of unacknowledged events was full
    /// (it did not acknowledge frames for a while): superseded statuses first, so the
    /// newest status of every action is kept as long as there is room (see
    /// `MAX_STATUSES`).
    pub statuses_dropped: u64,
    /// Collisions dropped because an agent's table of unacknowledged collisions was full
    /// (the oldest goes; see `MAX_COLLISIONS`).
    pub collisions_dropped: u64,
    /// Agents evicted at least once (process died or disconnected), ascending.
    pub evicted_agents: Vec<u32>,
    /// Times an evicted agent, or one that left, came back.
    pub rejoins: u64,
    /// Graceful leaves: an agent's SDK said it leaves (`close()`, drop). Not evictions.
    pub leaves: u64,
    /// Evictions (an agent evicted twice counts 2).
    pub evictions: u64,
    /// Peers refused or dropped before they were admitted as agents (see
    /// [`Host::on_peer_refused`]).
    pub peers_refused: u64,
    /// Times an agent whose link was lost came back within the resume window
    /// (`[sync] resume_window`) and went on where it was: not evictions, not rejoins.
    pub resumes: u64,
}
