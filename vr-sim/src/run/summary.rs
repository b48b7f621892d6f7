//! The run summary: what `--summary` writes as JSON and what is printed at the end.

use serde::Serialize;

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
    /// Times an agent whose link was lost came back within `sync.resume_window` and went
    /// on where it was (not evictions, not rejoins).
    pub resumes: u64,
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
            "evictions, leaves, rejoins, resumes",
            format!(
                "{}, {}, {}, {}",
                s.evictions, s.leaves, s.rejoins, s.resumes
            ),
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
