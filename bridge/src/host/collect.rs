//! The second half of a cycle: draining the agents' batches into the report, noticing
//! lost and leaving agents, and waiting for the stops (sync) or the next tick (async).

use super::*;

impl<T: HostTransport> Host<T> {
    pub(super) fn drain(&mut self, sync: bool) -> Result<(), HostCycleError> {
        let barrier = &mut self.barrier;
        let report = &mut self.report;
        let stats = &mut self.stats;
        let slots = &mut self.slots;
        let leaving = &mut self.leaving;
        let cycle = self.cycle;
        self.backend.drain(&mut |slot, header, commands| {
            // Any batch may acknowledge a frame, a late one too; never one not yet sent.
            if let Some(read) = header.acknowledged().filter(|&c| c <= cycle)
                && let Some(s) = slots.get_mut(slot)
                && s.read_cycle.is_none_or(|r| read > r)
            {
                s.read_cycle = Some(read);
                s.events.acknowledge(read);
                stats.frames_read += 1;
            }
            if header.is_leave() {
                // Not part of any cycle: the agent is gone (see `check_lost`).
                if !leaving.contains(&slot) {
                    leaving.push(slot);
                }
                return;
            }
            let verdict = if sync {
                barrier.on_batch(slot, header.cycle, header.is_stop())
            } else {
                BatchVerdict::Accept { stop: false }
            };
            // Commands from this index on are dropped.
            let applied = match verdict {
                BatchVerdict::Accept { .. } => {
                    let Some(a) = report.agents.get_mut(slot) else {
                        return;
                    };
                    let room = a.commands.capacity() - a.commands.len();
                    let take = commands.len().min(room);
                    for c in &commands[..take] {
                        if c.is_action_chunk() {
                            if !a.actions.take(c) {
                                stats.actions_rejected += 1;
                            }
                        } else {
                            a.commands.push(*c);
                            stats.commands_received += 1;
                        }
                    }
                    if take < commands.len() {
                        stats.commands_overflowed += (commands.len() - take) as u64;
                        warn!(
                            agent = a.agent_id,
                            dropped = commands.len() - take,
                            "too many commands in one cycle"
                        );
                    }
                    take
                }
                BatchVerdict::Late => {
                    report.late_batches += 1;
                    stats.late_batches += 1;
                    debug!(slot, batch_cycle = header.cycle, "late batch dropped");
                    0
                }
                BatchVerdict::Future => {
                    stats.future_batches += 1;
                    // A misbehaving agent must not flood the log: warn at the 1st, 2nd,
                    // 4th, 8th … such batch (the count is in the stats either way).
                    if stats.future_batches.is_power_of_two() {
                        warn!(
                            slot,
                            batch_cycle = header.cycle,
                            total = stats.future_batches,
                            "batch for a future cycle dropped"
                        );
                    }
                    0
                }
                BatchVerdict::NotAwaited => 0,
            };
            // A dropped command never runs: its agent learns so from an `Aborted` status in
            // its next frame (an agent that waits for its action's end must not wait in
            // vain, e.g. after its batch came late).
            if let Some(s) = slots.get_mut(slot) {
                let dropped = commands.get(applied..).unwrap_or(&[]);
                for c in dropped.iter().filter(|c| !c.is_action_chunk()) {
                    if s.events
                        .push_status(c.action_id, ActionState::Aborted as u32, cycle + 1)
                    {
                        stats.statuses_dropped += 1;
                    }
                }
            }
        })?;
        Ok(())
    }

    /// Lets agents that said they leave go (see [`AgentReport::left`]).
    pub(super) fn handle_leaves(&mut self) {
        for i in 0..self.leaving.len() {
            let slot = self.leaving[i];
            let s = &self.slots[slot];
            let id = s.id;
            self.backend.forget_connection(slot);
            // An agent that never took part (or is out already) has nothing to leave.
            let pending = self.barrier.leave(slot);
            if !pending && (!s.seen || s.evicted) {
                continue;
            }
            info!(agent = id, cycle = self.cycle, "agent left the session");
            let s = &mut self.slots[slot];
            s.evicted = true;
            s.left = true;
            s.left_in = Some(self.cycle);
            s.seen = false;
            // A new connection starts afresh, as after an eviction.
            s.events.clear();
            s.read_cycle = None;
            self.stats.leaves += 1;
        }
        self.leaving.clear();
    }

    /// Evicts awaited agents that disconnected (when `connections`: it asks the
    /// transports about every agent) or whose process died (when `reap`); lets those that
    /// said they leave go.
    pub(super) fn check_lost(
        &mut self,
        sync: bool,
        reap: bool,
        connections: bool,
    ) -> Result<(), HostCycleError> {
        self.take_refusals();
        self.handle_leaves();
        self.dead.clear();
        if reap {
            self.backend.reap_dead_agents(&mut self.dead);
        }
        // Awaited agents that disconnected, and agents that left between cycles.
        let mut disconnected = false;
        let asked = if connections { self.slots.len() } else { 0 };
        for slot in 0..asked {
            let pending = self.barrier.outcome(slot) == AgentOutcome::TimedOut;
            let known = pending || (self.slots[slot].seen && !self.slots[slot].evicted);
            if known && !self.backend.is_connected(slot) && !self.dead.contains(&slot) {
                self.dead.push(slot);
                disconnected = true;
            }
        }
        if disconnected {
            // An agent that leaves sends its leave batch, then closes: the batch may have
            // come in since the last drain. A leave is not a loss (a slot that left is out
            // already, so the loop below passes it by).
            self.drain(sync)?;
            self.handle_leaves();
        }
        for i in 0..self.dead.len() {
            let slot = self.dead[i];
            let pending = self.barrier.evict(slot);
            if pending || !self.slots[slot].evicted {
                let id = self.slots[slot].id;
                self.backend.forget_connection(slot);
                warn!(
                    agent = id,
                    cycle = self.cycle,
                    "agent lost (process died or disconnected): evicted"
                );
                self.slots[slot].evicted = true;
                self.slots[slot].evicted_in = Some(self.cycle);
                self.stats.evictions += 1;
                self.slots[slot].seen = false;
                // A process that rejoins starts afresh: its events were for the old one.
                self.slots[slot].events.clear();
                self.slots[slot].read_cycle = None;
                if let Some(hook) = &mut self.evicted_hook {
                    hook(id, self.cycle);
                }
                self.lost_this_cycle.push(slot);
                if let Err(pos) = self.stats.evicted_agents.binary_search(&id) {
                    self.stats.evicted_agents.insert(pos, id);
                }
            }
        }
        Ok(())
    }

    /// Drains batches and watches for lost agents until `until` — in sync mode only until
    /// every awaited agent stopped; there `until` is the stop timeout, after which agents
    /// with `wait_for_stop = "timeout"` are given up and the others waited for as long as
    /// they are connected (reported as slow, with the time waited since `started`, when the
    /// wait began: at least the stop timeout) — then applies `on_agent_lost`.
    pub(super) fn wait_cycle(
        &mut self,
        sync: bool,
        started: Instant,
        until: Instant,
    ) -> Result<(), HostCycleError> {
        let timeout = until.saturating_duration_since(started);
        let mut next_reap = started + REAP_PERIOD;
        // The first look of the wait asks about every connection.
        let mut next_connection_check = started;
        // Past the stop timeout (sync mode): when the next slow report is due.
        let mut past_timeout = false;
        let mut next_report = until;
        let mut reports = 0u32;
        self.lost_this_cycle.clear();
        if sync && self.barrier.is_complete() {
            // Nobody to wait for (no frame reached an agent): the transports still get
            // their turn to take in new connections (a TCP hello is served in the wait),
            // or a host that cycles on without agents would never let one (re)join.
            self.wait_activity(Duration::ZERO)?;
        }
        loop {
            self.drain(sync)?;
            let now = Instant::now();
            let reap = now >= next_reap;
            if reap {
                next_reap = now + REAP_PERIOD;
            }
            let connections = reap || now >= next_connection_check;
            if connections {
                next_connection_check = now + CONNECTION_CHECK_PERIOD;
            }
            self.check_lost(sync, reap, connections)?;
            if sync && self.barrier.is_complete() {
                break;
            }
            let mut wake = until;
            if now >= until {
                if !sync {
                    break;
                }
                if !past_timeout {
                    past_timeout = true;
                    for slot in 0..self.slots.len() {
                        if self.slots[slot].wait_for_stop == WaitForStop::Timeout {
                            self.barrier.give_up(slot);
                        }
                    }
                    if self.barrier.is_complete() {
                        break;
                    }
                }
                if now >= next_report {
                    self.report_slow(now.saturating_duration_since(started));
                    reports = reports.saturating_add(1);
                    // 1×, 2×, 4×, … the stop timeout into the cycle.
                    next_report = started + timeout.saturating_mul(1u32 << reports.min(20));
                }
                wake = next_report;
            }
            if !connections {
                wake = wake.min(next_connection_check);
            }
            self.wait_activity(wake.min(next_reap).saturating_duration_since(now))?;
        }
        self.handle_lost()
    }

    /// Reports every agent still awaited past the stop timeout (all have `wait_for_stop =
    /// "alive"` and are connected: the lost ones were evicted) as slow.
    pub(super) fn report_slow(&mut self, waited: Duration) {
        if (0..self.slots.len()).all(|slot| !self.barrier.is_slow(slot)) {
            self.stats.slow_stops += 1;
        }
        for slot in 0..self.slots.len() {
            if !self.barrier.is_pending(slot) {
                continue;
            }
            self.barrier.mark_slow(slot);
            let agent = self.slots[slot].id;
            warn!(
                agent,
                cycle = self.cycle,
                waited_s = waited.as_secs_f64(),
                "agent is slow: still waiting for its stop past stop_timeout (it is alive; \
                 wait_for_stop = \"alive\")"
            );
            if let Some(hook) = &mut self.slow_hook {
                hook(agent, self.cycle, waited);
            }
        }
    }

    pub(super) fn collect_sync(&mut self) -> Result<(), HostCycleError> {
        let started = Instant::now();
        self.wait_cycle(true, started, started + self.config.sync.stop_timeout)?;
        let mut timed_out = 0u64;
        for (slot, a) in self.report.agents.iter_mut().enumerate() {
            a.outcome = self.barrier.outcome(slot);
            self.slots[slot].last_outcome = match a.outcome {
                AgentOutcome::Stopped => WireOutcome::Stopped,
                AgentOutcome::TimedOut => WireOutcome::TimedOut,
                _ => WireOutcome::None,
            };
            if a.outcome == AgentOutcome::TimedOut {
                timed_out += 1;
            }
        }
        if timed_out > 0 {
            self.report.timed_out = true;
            self.stats.stop_timeouts += 1;
            self.stats.agent_timeouts += timed_out;
            let missing: Vec<u32> = self.report.timed_out_agents().collect();
            warn!(
                cycle = self.cycle,
                ?missing,
                timeout_s = self.config.sync.stop_timeout.as_secs_f64(),
                "stop timeout: cycle ends without these agents"
            );
        }
        Ok(())
    }

    /// Applies `on_agent_lost` to the agents lost this cycle.
    pub(super) fn handle_lost(&mut self) -> Result<(), HostCycleError> {
        let Some(&slot) = self.lost_this_cycle.first() else {
            return Ok(());
        };
        let agent = self.slots[slot].id;
        match self.config.sync.on_agent_lost {
            AgentLostPolicy::Evict => Ok(()),
            AgentLostPolicy::Abort => Err(HostCycleError::AgentLost {
                agent,
                cycle: self.cycle,
            }),
            AgentLostPolicy::Wait => {
                let timeout = self.config.sync.connect_timeout;
                let started = Instant::now();
                for i in 0..self.lost_this_cycle.len() {
                    let slot = self.lost_this_cycle[i];
                    let agent = self.slots[slot].id;
                    warn!(
                        agent,
                        "pausing until the agent reconnects (on_agent_lost = \"wait\")"
                    );
                    while !self.backend.is_connected(slot) {
                        let left = timeout.saturating_sub(started.elapsed());
                        if left.is_zero() {
                            return Err(HostCycleError::AgentNotBack {
                                agent,
                                waited: started.elapsed(),
                            });
                        }
                        self.wait_activity(left.min(Duration::from_secs(1)))?;
                    }
                }
                self.backend.update_connections()?;
                Ok(())
            }
        }
    }

    pub(super) fn collect_async(&mut self) -> Result<(), HostCycleError> {
        let period = self.config.sync.simulation_time_per_frame;
        let now = Instant::now();
        let tick = match self.next_tick {
            // Keep a fixed rate; if we fell behind by more than a period, resynchronise
            // instead of bursting to catch up.
            Some(t) if t + period > now => t,
            _ => now + period,
        };
        self.wait_cycle(false, Instant::now(), tick)?;
        self.next_tick = Some(tick + period);
        for a in &mut self.report.agents {
            a.outcome = AgentOutcome::Async;
        }
        Ok(())
    }
}
