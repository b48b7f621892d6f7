//! Events delivered at least once: each agent's action statuses and collisions that it has
//! not acknowledged yet.
//!
//! A sensor frame carries the events since the previous frame, but an agent may skip
//! frames (late in sync mode, slow in async mode, stopped for a while): the newest-frame
//! rule drops the frames in between, and the events with them. So the host keeps, per
//! agent, every event the agent has not acknowledged and writes all of them into every
//! frame, until a batch of the agent acknowledges a frame that carried them
//! ([`crate::wire::MotorHeader::ack_cycle`]). Each event gets a sequence number (one
//! increasing series per agent, statuses and collisions together), so the agent SDK hands
//! each one to the agent's code exactly once however often it arrives.
//!
//! Bounded: at most [`MAX_STATUSES`] statuses and [`MAX_COLLISIONS`] collisions wait per
//! agent, exactly what one header holds, so every frame carries every waiting event. When
//! a new event finds its table full, one waiting event is dropped and counted:
//! - a status: the oldest status *superseded* by a newer one of the same action (the
//!   newest status of every action is kept); if every waiting status is the newest of its
//!   action, the oldest one that is not final (`Finished`/`Aborted` are final); if every
//!   one is final, the oldest;
//! - a collision: the oldest.
//!
//! Pure bookkeeping, no I/O: unit tested here.

use crate::wire::{
    ActionState, ActionStatus, Collision, MAX_COLLISIONS, MAX_STATUSES, SensorHeader,
};

/// Events dropped to make room, by kind (see the module doc for which).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct Dropped {
    /// Statuses dropped.
    pub statuses: u32,
    /// Collisions dropped.
    pub collisions: u32,
}

/// One agent's events that wait for its acknowledgement.
#[derive(Debug)]
pub(crate) struct PendingEvents {
    /// Ascending `seq`; `.1` is the cycle of the first frame that carried it.
    statuses: Vec<(ActionStatus, u64)>,
    /// Ascending `seq`; `.1` as above.
    collisions: Vec<(Collision, u64)>,
    next_seq: u64,
}

fn is_final(state: u32) -> bool {
    matches!(
        ActionState::from_u32(state),
        Some(ActionState::Finished | ActionState::Aborted)
    )
}

impl PendingEvents {
    pub(crate) fn new() -> Self {
        Self {
            statuses: Vec::with_capacity(MAX_STATUSES),
            collisions: Vec::with_capacity(MAX_COLLISIONS),
            next_seq: 1,
        }
    }

    /// Statuses waiting.
    #[cfg(test)]
    fn statuses(&self) -> impl Iterator<Item = (u32, u32, u64)> + '_ {
        self.statuses
            .iter()
            .map(|(s, _)| (s.action_id, s.state, s.seq))
    }

    /// Queues a status that the frame of `cycle` carries first; returns whether a waiting
    /// status was dropped to make room.
    pub(crate) fn push_status(&mut self, action_id: u32, state: u32, cycle: u64) -> bool {
        let status = ActionStatus {
            action_id,
            state,
            seq: self.next_seq,
        };
        self.next_seq += 1;
        let full = self.statuses.len() >= MAX_STATUSES;
        if full {
            let victim = self.status_victim(action_id);
            self.statuses.remove(victim);
        }
        self.statuses.push((status, cycle));
        full
    }

    /// Takes the events the simulator wrote into `header` for the frame of `cycle` (the
    /// new ones, their `seq` ignored), numbers them, queues them after the waiting ones, and
    /// writes every waiting event back into the header in sequence order.
    pub(crate) fn merge_into(&mut self, header: &mut SensorHeader, cycle: u64) -> Dropped {
        let mut dropped = Dropped::default();
        let new_statuses = header.status_count.min(MAX_STATUSES as u32) as usize;
        for i in 0..new_statuses {
            let ActionStatus {
                action_id, state, ..
            } = header.statuses[i];
            dropped.statuses += u32::from(self.push_status(action_id, state, cycle));
        }
        let new_collisions = header.collision_count.min(MAX_COLLISIONS as u32) as usize;
        for i in 0..new_collisions {
            let mut collision = header.collisions[i];
            collision.seq = self.next_seq;
            self.next_seq += 1;
            if self.collisions.len() >= MAX_COLLISIONS {
                self.collisions.remove(0);
                dropped.collisions += 1;
            }
            self.collisions.push((collision, cycle));
        }
        header.status_count = self.statuses.len() as u32;
        for (dst, (src, _)) in header.statuses.iter_mut().zip(&self.statuses) {
            *dst = *src;
        }
        header.collision_count = self.collisions.len() as u32;
        for (dst, (src, _)) in header.collisions.iter_mut().zip(&self.collisions) {
            *dst = *src;
        }
        dropped
    }

    /// Which waiting status gives way to a new status of `incoming` (see the module doc).
    fn status_victim(&self, incoming: u32) -> usize {
        let superseded = (0..self.statuses.len()).find(|&i| {
            let id = self.statuses[i].0.action_id;
            id == incoming
                || self.statuses[i + 1..]
                    .iter()
                    .any(|(s, _)| s.action_id == id)
        });
        superseded
            .or_else(|| self.statuses.iter().position(|(s, _)| !is_final(s.state)))
            .unwrap_or(0)
    }

    /// The agent read the frame of `cycle`: forget the events that frame (or an earlier
    /// one) carried.
    pub(crate) fn acknowledge(&mut self, cycle: u64) {
        self.statuses.retain(|&(_, first)| first > cycle);
        self.collisions.retain(|&(_, first)| first > cycle);
    }

    /// Forgets every waiting event (the agent was evicted: a process that rejoins starts
    /// afresh). Sequence numbers keep increasing.
    pub(crate) fn clear(&mut self) {
        self.statuses.clear();
        self.collisions.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wire::ActionState::{Aborted, Finished, InExecution, Walking};

    fn frame(statuses: &[(u32, ActionState)], collisions: &[(u32, u32)]) -> SensorHeader {
        let mut h = SensorHeader::default();
        for &(id, state) in statuses {
            assert!(h.push_status(id, state));
        }
        for &(id, collider) in collisions {
            assert!(h.push_collision(id, collider));
        }
        h
    }

    fn seqs(h: &SensorHeader) -> (Vec<u64>, Vec<u64>) {
        (
            h.statuses().iter().map(|s| s.seq).collect(),
            h.collisions().iter().map(|c| c.seq).collect(),
        )
    }

    #[test]
    fn events_repeat_in_every_frame_until_acknowledged() {
        let mut p = PendingEvents::new();
        let mut h = frame(&[(1, InExecution)], &[(1, 1000)]);
        assert_eq!(p.merge_into(&mut h, 0), Dropped::default());
        assert_eq!(seqs(&h), (vec![1], vec![2]));
        // Cycle 1 adds a status; cycle 0's events are still carried.
        let mut h = frame(&[(1, Finished)], &[]);
        p.merge_into(&mut h, 1);
        assert_eq!(seqs(&h), (vec![1, 3], vec![2]));
        assert_eq!(h.statuses()[1].state, Finished as u32);
        // The agent read frame 0: what frame 0 carried goes, cycle 1's stays.
        p.acknowledge(0);
        let mut h = frame(&[], &[]);
        p.merge_into(&mut h, 2);
        assert_eq!(seqs(&h), (vec![3], vec![]));
        p.acknowledge(2);
        let mut h = frame(&[], &[]);
        p.merge_into(&mut h, 3);
        assert_eq!(seqs(&h), (vec![], vec![]));
    }

    #[test]
    fn a_full_table_drops_superseded_statuses_first_and_keeps_each_actions_newest() {
        let mut p = PendingEvents::new();
        // Action 1 walks for many cycles while action 2..=8 finished: never acknowledged.
        for cycle in 0..MAX_STATUSES as u64 {
            let mut h = frame(&[(1, Walking)], &[]);
            p.merge_into(&mut h, cycle);
        }
        let mut h = frame(&[(2, Finished), (3, Aborted)], &[]);
        let dropped = p.merge_into(&mut h, 100);
        assert_eq!(dropped.statuses, 2);
        let kept: Vec<(u32, u32)> = p.statuses().map(|(id, state, _)| (id, state)).collect();
        assert_eq!(kept.len(), MAX_STATUSES);
        assert_eq!(kept[MAX_STATUSES - 2..], [(2, 1), (3, 2)]);
        // A new status of action 1 drops action 1's oldest, never action 2's or 3's.
        for cycle in 101..200 {
            let mut h = frame(&[(1, Walking)], &[]);
            p.merge_into(&mut h, cycle);
        }
        let ids: Vec<u32> = p.statuses().map(|(id, _, _)| id).collect();
        assert!(ids.contains(&2) && ids.contains(&3), "{ids:?}");
        let seqs: Vec<u64> = p.statuses().map(|(_, _, seq)| seq).collect();
        assert!(seqs.windows(2).all(|w| w[0] < w[1]), "{seqs:?}");
    }

    #[test]
    fn without_superseded_statuses_the_oldest_unfinished_goes_then_the_oldest() {
        let mut p = PendingEvents::new();
        let mut h = SensorHeader::default();
        for id in 0..MAX_STATUSES as u32 {
            h.push_status(id, if id == 5 { InExecution } else { Finished });
        }
        p.merge_into(&mut h, 0);
        let mut h = frame(&[(100, Finished)], &[]);
        assert_eq!(p.merge_into(&mut h, 1).statuses, 1);
        let ids: Vec<u32> = p.statuses().map(|(id, _, _)| id).collect();
        assert!(!ids.contains(&5) && ids.contains(&100), "{ids:?}");
        let mut h = frame(&[(101, Finished)], &[]);
        p.merge_into(&mut h, 2);
        let ids: Vec<u32> = p.statuses().map(|(id, _, _)| id).collect();
        assert!(!ids.contains(&0) && ids.contains(&101), "{ids:?}");
    }

    #[test]
    fn a_full_collision_table_drops_the_oldest_and_counts_it() {
        let mut p = PendingEvents::new();
        let all: Vec<(u32, u32)> = (0..MAX_COLLISIONS as u32).map(|i| (i, 1000)).collect();
        let mut h = frame(&[], &all);
        p.merge_into(&mut h, 0);
        let mut h = frame(&[], &[(50, 1001), (51, 1002)]);
        assert_eq!(p.merge_into(&mut h, 1).collisions, 2);
        assert_eq!(h.collisions().len(), MAX_COLLISIONS);
        assert_eq!(h.collisions()[0].action_id, 2);
        assert_eq!(h.collisions()[MAX_COLLISIONS - 1].action_id, 51);
    }

    #[test]
    fn clearing_forgets_the_events_but_not_the_numbering() {
        let mut p = PendingEvents::new();
        let mut h = frame(&[(1, Finished)], &[]);
        p.merge_into(&mut h, 0);
        p.clear();
        let mut h = frame(&[(2, Finished)], &[]);
        p.merge_into(&mut h, 1);
        assert_eq!(seqs(&h), (vec![2], vec![]));
    }
}
