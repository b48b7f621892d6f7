//! The lock-step barrier: which agents a cycle waits for, and what each batch means.
//!
//! Pure bookkeeping, no I/O, so every rule is unit tested here:
//! - a batch counts only for the cycle it names: a stop for `f-1` arriving during `f` is
//!   *late* and never completes `f` (the "wrong frame" bug of lock-step systems);
//! - a batch naming a future cycle is a protocol violation and is dropped;
//! - a batch after the agent's stop of the same cycle is late too;
//! - the cycle is complete when every awaited agent stopped, was given up (its stop
//!   timeout passed: `wait_for_stop = "timeout"`) or was evicted.

/// How one agent's part of a cycle ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum AgentOutcome {
    /// The agent's stop for this cycle arrived in time.
    Stopped,
    /// The stop timeout passed before the agent's stop arrived.
    TimedOut,
    /// No frame was published to this agent this cycle (not connected), so it was not
    /// waited for.
    NotAwaited,
    /// Async mode: commands were taken as they arrived; stops are ignored.
    Async,
    /// The agent was lost during the cycle (process died or disconnected) and evicted.
    Evicted,
    /// The agent left the session during the cycle, gracefully (it said so: `close()` or
    /// drop of its SDK handle), before its stop.
    Left,
}

impl AgentOutcome {
    /// Lowercase name for logs and summaries.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Stopped => "stopped",
            Self::TimedOut => "timed_out",
            Self::NotAwaited => "not_awaited",
            Self::Async => "async",
            Self::Evicted => "evicted",
            Self::Left => "left",
        }
    }
}

/// What the barrier made of one received batch.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BatchVerdict {
    /// Belongs to this cycle: apply its commands. `stop` = it ended the agent's cycle.
    Accept {
        /// Whether this batch carried the stop.
        stop: bool,
    },
    /// For an earlier cycle, or after the agent's stop: dropped and counted.
    Late,
    /// Names a cycle that has not started: dropped and counted.
    Future,
    /// The agent was not awaited this cycle: dropped.
    NotAwaited,
}

/// Barrier state of one cycle over `n` agent slots.
#[derive(Debug, Clone)]
pub struct CycleBarrier {
    cycle: u64,
    awaited: Vec<bool>,
    stopped: Vec<bool>,
    evicted: Vec<bool>,
    /// Given up at the stop timeout while the cycle went on (waiting for others).
    given_up: Vec<bool>,
    /// Left gracefully before its stop.
    left: Vec<bool>,
    /// Reported as slow (waited for past the stop timeout).
    slow: Vec<bool>,
    pending: usize,
}

impl CycleBarrier {
    /// A barrier over `slots` agents.
    pub fn new(slots: usize) -> Self {
        Self {
            cycle: 0,
            awaited: vec![false; slots],
            stopped: vec![false; slots],
            evicted: vec![false; slots],
            given_up: vec![false; slots],
            left: vec![false; slots],
            slow: vec![false; slots],
            pending: 0,
        }
    }

    /// Starts cycle `cycle` with nobody awaited yet.
    pub fn begin(&mut self, cycle: u64) {
        self.cycle = cycle;
        self.awaited.fill(false);
        self.stopped.fill(false);
        self.evicted.fill(false);
        self.given_up.fill(false);
        self.left.fill(false);
        self.slow.fill(false);
        self.pending = 0;
    }

    /// Marks `slot` as awaited (its frame was published this cycle).
    pub fn await_slot(&mut self, slot: usize) {
        if let Some(a) = self.awaited.get_mut(slot)
            && !*a
        {
            *a = true;
            self.pending += 1;
        }
    }

    /// Classifies a batch from `slot` that names `batch_cycle`.
    pub fn on_batch(&mut self, slot: usize, batch_cycle: u64, stop: bool) -> BatchVerdict {
        if batch_cycle < self.cycle {
            return BatchVerdict::Late;
        }
        if batch_cycle > self.cycle {
            return BatchVerdict::Future;
        }
        if self.given_up.get(slot) == Some(&true) {
            // Its cycle ended at the stop timeout: what comes now is late, as it would be
            // in the next cycle.
            return BatchVerdict::Late;
        }
        match (self.awaited.get(slot), self.stopped.get(slot)) {
            (Some(true), Some(true)) => BatchVerdict::Late,
            (Some(true), Some(false)) => {
                if stop {
                    self.stopped[slot] = true;
                    self.pending -= 1;
                }
                BatchVerdict::Accept { stop }
            }
            _ => BatchVerdict::NotAwaited,
        }
    }

    /// Stops waiting for `slot` this cycle (its process died or disconnected). Returns
    /// whether it was pending.
    pub fn evict(&mut self, slot: usize) -> bool {
        if self.stopped.get(slot) == Some(&true) {
            // It finished this cycle before it left: the cycle keeps its stop.
            return false;
        }
        let pending = self.awaited.get(slot) == Some(&true);
        if let Some(e) = self.evicted.get_mut(slot) {
            *e = true;
        }
        if pending {
            self.awaited[slot] = false;
            if self.given_up[slot] {
                // No longer counted as pending since it was given up.
                self.given_up[slot] = false;
            } else {
                self.pending -= 1;
            }
        }
        pending
    }

    /// Stops waiting for `slot` this cycle because it left gracefully: as
    /// [`CycleBarrier::evict`], with the outcome [`AgentOutcome::Left`] if it was awaited
    /// (an agent that stopped first keeps its stop). Returns whether it was pending.
    pub fn leave(&mut self, slot: usize) -> bool {
        if self.stopped.get(slot) == Some(&true) || self.awaited.get(slot) != Some(&true) {
            return false;
        }
        let pending = self.evict(slot);
        if let Some(l) = self.left.get_mut(slot) {
            *l = true;
        }
        pending
    }

    /// Stops waiting for `slot` this cycle because its stop timeout passed while the cycle
    /// goes on for others: its outcome is [`AgentOutcome::TimedOut`] and its batches for
    /// this cycle are late from now on. Returns whether it was pending.
    pub fn give_up(&mut self, slot: usize) -> bool {
        let pending = self.is_pending(slot);
        if pending {
            self.given_up[slot] = true;
            self.pending -= 1;
        }
        pending
    }

    /// Marks `slot` as slow this cycle (waited for past the stop timeout). Returns whether
    /// it was not marked yet.
    pub fn mark_slow(&mut self, slot: usize) -> bool {
        match self.slow.get_mut(slot) {
            Some(s) if !*s => {
                *s = true;
                true
            }
            _ => false,
        }
    }

    /// Whether `slot` was waited for past the stop timeout this cycle.
    pub fn is_slow(&self, slot: usize) -> bool {
        self.slow.get(slot) == Some(&true)
    }

    /// Whether `slot` is awaited and has neither stopped nor been given up or evicted.
    pub fn is_pending(&self, slot: usize) -> bool {
        self.awaited.get(slot) == Some(&true)
            && self.stopped.get(slot) == Some(&false)
            && self.given_up.get(slot) == Some(&false)
    }

    /// Whether every awaited agent stopped.
    pub fn is_complete(&self) -> bool {
        self.pending == 0
    }

    /// Number of awaited agents that have not stopped.
    #[cfg(test)]
    pub fn pending(&self) -> usize {
        self.pending
    }

    /// Slots still awaited (neither stopped, given up nor evicted).
    #[cfg(test)]
    pub fn pending_slots(&self) -> impl Iterator<Item = usize> + '_ {
        (0..self.awaited.len()).filter(|&s| self.is_pending(s))
    }

    /// Outcome of `slot` if the cycle ended now.
    pub fn outcome(&self, slot: usize) -> AgentOutcome {
        if self.left.get(slot) == Some(&true) {
            return AgentOutcome::Left;
        }
        if self.evicted.get(slot) == Some(&true) {
            return AgentOutcome::Evicted;
        }
        match (self.awaited.get(slot), self.stopped.get(slot)) {
            (Some(true), Some(true)) => AgentOutcome::Stopped,
            (Some(true), _) => AgentOutcome::TimedOut,
            _ => AgentOutcome::NotAwaited,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cycle_completes_when_every_awaited_agent_stopped() {
        let mut b = CycleBarrier::new(3);
        b.begin(7);
        b.await_slot(0);
        b.await_slot(2);
        b.await_slot(2); // idempotent
        assert_eq!(b.pending(), 2);
        assert_eq!(
            b.on_batch(0, 7, false),
            BatchVerdict::Accept { stop: false }
        );
        assert!(!b.is_complete());
        assert_eq!(b.on_batch(0, 7, true), BatchVerdict::Accept { stop: true });
        assert_eq!(b.on_batch(2, 7, true), BatchVerdict::Accept { stop: true });
        assert!(b.is_complete());
        assert_eq!(b.outcome(0), AgentOutcome::Stopped);
        assert_eq!(b.outcome(1), AgentOutcome::NotAwaited);
    }

    #[test]
    fn a_late_stop_never_completes_the_next_cycle() {
        let mut b = CycleBarrier::new(2);
        b.begin(10);
        b.await_slot(0);
        b.await_slot(1);
        assert_eq!(b.on_batch(0, 10, true), BatchVerdict::Accept { stop: true });
        // agent 1 misses cycle 10: timeout
        assert_eq!(b.outcome(1), AgentOutcome::TimedOut);
        assert_eq!(b.pending_slots().collect::<Vec<_>>(), [1]);
        b.begin(11);
        b.await_slot(0);
        b.await_slot(1);
        // its stop for 10 arrives now
        assert_eq!(b.on_batch(1, 10, true), BatchVerdict::Late);
        assert_eq!(b.pending(), 2);
        assert!(!b.is_complete());
        assert_eq!(b.on_batch(1, 12, true), BatchVerdict::Future);
        assert_eq!(b.on_batch(1, 11, true), BatchVerdict::Accept { stop: true });
        assert_eq!(
            b.on_batch(1, 11, false),
            BatchVerdict::Late,
            "after its stop"
        );
        assert_eq!(b.pending(), 1);
    }

    #[test]
    fn an_evicted_agent_no_longer_holds_the_cycle() {
        let mut b = CycleBarrier::new(2);
        b.begin(3);
        b.await_slot(0);
        b.await_slot(1);
        assert_eq!(b.on_batch(0, 3, true), BatchVerdict::Accept { stop: true });
        assert!(b.evict(1));
        assert!(b.is_complete());
        assert_eq!(b.outcome(1), AgentOutcome::Evicted);
        assert!(!b.evict(1), "evicting twice is harmless");
        assert!(!b.evict(0), "an agent that stopped keeps its stop");
        assert_eq!(b.outcome(0), AgentOutcome::Stopped);
        assert_eq!(b.on_batch(1, 3, true), BatchVerdict::NotAwaited);
    }

    #[test]
    fn a_slot_given_up_at_its_timeout_stops_holding_the_cycle_and_its_stop_is_late() {
        let mut b = CycleBarrier::new(3);
        b.begin(4);
        for slot in 0..3 {
            b.await_slot(slot);
        }
        assert!(b.give_up(0));
        assert!(!b.give_up(0), "once");
        assert_eq!(b.pending(), 2);
        assert_eq!(b.pending_slots().collect::<Vec<_>>(), [1, 2]);
        assert_eq!(b.outcome(0), AgentOutcome::TimedOut);
        assert_eq!(b.on_batch(0, 4, true), BatchVerdict::Late);
        assert!(b.mark_slow(1) && !b.mark_slow(1) && b.is_slow(1));
        // Evicting a slot given up does not count it twice.
        assert!(b.evict(0));
        assert_eq!(b.pending(), 2);
        assert_eq!(b.outcome(0), AgentOutcome::Evicted);
        assert_eq!(b.on_batch(1, 4, true), BatchVerdict::Accept { stop: true });
        assert!(b.evict(2));
        assert!(b.is_complete());
        b.begin(5);
        assert!(!b.is_slow(1));
    }

    #[test]
    fn a_slot_that_leaves_stops_holding_the_cycle_unless_it_stopped_first() {
        let mut b = CycleBarrier::new(2);
        b.begin(1);
        b.await_slot(0);
        b.await_slot(1);
        assert_eq!(b.on_batch(0, 1, true), BatchVerdict::Accept { stop: true });
        assert!(!b.leave(0), "it stopped first");
        assert_eq!(b.outcome(0), AgentOutcome::Stopped);
        assert!(b.leave(1));
        assert!(b.is_complete());
        assert_eq!(b.outcome(1), AgentOutcome::Left);
        b.begin(2);
        assert!(!b.leave(1), "not awaited");
        assert_eq!(b.outcome(1), AgentOutcome::NotAwaited);
    }

    #[test]
    fn batches_from_agents_not_awaited_are_dropped() {
        let mut b = CycleBarrier::new(2);
        b.begin(0);
        b.await_slot(0);
        assert_eq!(b.on_batch(1, 0, true), BatchVerdict::NotAwaited);
        assert_eq!(b.on_batch(5, 0, true), BatchVerdict::NotAwaited);
        assert_eq!(b.pending(), 1);
    }
}
