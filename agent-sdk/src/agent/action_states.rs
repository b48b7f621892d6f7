//! The latest status per action id, bounded, in O(1) per status.
//!
//! Every frame of every agent brings statuses, so this runs per frame: a hash index from
//! action id to a slot, and two queues of slots in the order their statuses came (the
//! finished or aborted actions', the others'), which give the one to forget when full
//! without a search. Nothing is allocated after [`ActionStates::with_capacity`].

use vrsync_transport::{ActionState, ActionStatus};

/// No slot (end of a queue, an empty bucket of the index).
const NIL: u32 = u32::MAX;

/// One remembered action.
#[derive(Debug, Clone, Copy)]
struct Slot {
    action_id: u32,
    state: ActionState,
    /// The neighbours in the slot's queue (towards older, towards newer).
    older: u32,
    newer: u32,
}

/// A queue of slots, oldest status first.
#[derive(Debug, Clone, Copy)]
struct Queue {
    oldest: u32,
    newest: u32,
}

impl Queue {
    const EMPTY: Self = Self {
        oldest: NIL,
        newest: NIL,
    };
}

/// Which queue a state's slot is in: finished and aborted actions are forgotten first.
fn done(state: ActionState) -> bool {
    matches!(state, ActionState::Finished | ActionState::Aborted)
}

/// The latest status per action id: at most `capacity` actions; beyond, the action whose
/// latest status came earliest is forgotten, a finished or aborted one first.
///
/// Statuses must come in the order of their sequence numbers (the agent hands them out
/// so): then "came earliest" is "has the smallest sequence number".
#[derive(Debug)]
pub(super) struct ActionStates {
    slots: Vec<Slot>,
    capacity: usize,
    /// Open addressing with linear probing: slot numbers, `NIL` for empty buckets; at
    /// least twice `capacity` buckets, a power of two.
    index: Box<[u32]>,
    /// log2 of `index.len()`.
    index_bits: u32,
    /// The finished and aborted actions, and the others.
    done: Queue,
    live: Queue,
}

impl ActionStates {
    /// Room for `capacity` actions (at least 1), allocated now.
    pub(super) fn with_capacity(capacity: usize) -> Self {
        let capacity = capacity.clamp(1, (NIL / 2) as usize);
        let buckets = (2 * capacity).next_power_of_two();
        Self {
            slots: Vec::with_capacity(capacity),
            capacity,
            index: vec![NIL; buckets].into_boxed_slice(),
            index_bits: buckets.trailing_zeros(),
            done: Queue::EMPTY,
            live: Queue::EMPTY,
        }
    }

    /// The latest state of `action_id`, if remembered.
    pub(super) fn get(&self, action_id: u32) -> Option<ActionState> {
        let (_, slot) = self.find(action_id)?;
        self.slots.get(slot as usize).map(|s| s.state)
    }

    /// Every remembered action and its latest state, in no particular order.
    pub(super) fn iter(&self) -> impl Iterator<Item = (u32, ActionState)> + '_ {
        self.slots.iter().map(|s| (s.action_id, s.state))
    }

    /// Takes a status in (one with an unknown state is ignored).
    pub(super) fn update(&mut self, status: &ActionStatus) {
        let Some(state) = ActionState::from_u32(status.state) else {
            return;
        };
        if let Some((_, slot)) = self.find(status.action_id) {
            self.unlink(slot);
            self.set(slot, status.action_id, state);
            return;
        }
        let slot = if self.slots.len() < self.capacity {
            let slot = self.slots.len() as u32;
            self.slots.push(Slot {
                action_id: status.action_id,
                state,
                older: NIL,
                newer: NIL,
            });
            slot
        } else {
            // Full: forget the oldest finished or aborted action, else the oldest.
            let victim = if self.done.oldest != NIL {
                self.done.oldest
            } else {
                self.live.oldest
            };
            let Some(old_id) = self.slots.get(victim as usize).map(|s| s.action_id) else {
                return;
            };
            self.unlink(victim);
            self.remove_from_index(old_id);
            victim
        };
        self.set(slot, status.action_id, state);
        self.insert_into_index(status.action_id, slot);
    }

    /// Gives `slot` its action and state and appends it to its state's queue.
    fn set(&mut self, slot: u32, action_id: u32, state: ActionState) {
        let queue = if done(state) {
            &mut self.done
        } else {
            &mut self.live
        };
        let newest = core::mem::replace(&mut queue.newest, slot);
        if newest == NIL {
            queue.oldest = slot;
        }
        if let Some(s) = self.slots.get_mut(newest as usize) {
            s.newer = slot;
        }
        if let Some(s) = self.slots.get_mut(slot as usize) {
            *s = Slot {
                action_id,
                state,
                older: newest,
                newer: NIL,
            };
        }
    }

    /// Takes `slot` out of its queue.
    fn unlink(&mut self, slot: u32) {
        let Some(&Slot {
            state,
            older,
            newer,
            ..
        }) = self.slots.get(slot as usize)
        else {
            return;
        };
        let queue = if done(state) {
            &mut self.done
        } else {
            &mut self.live
        };
        match self.slots.get_mut(older as usize) {
            Some(s) => s.newer = newer,
            None => queue.oldest = newer,
        }
        match self.slots.get_mut(newer as usize) {
            Some(s) => s.older = older,
            None => queue.newest = older,
        }
    }

    /// The home bucket of `action_id` (Fibonacci hashing: sequential ids spread).
    fn home(&self, action_id: u32) -> usize {
        (action_id.wrapping_mul(0x9E37_79B9) >> (32 - self.index_bits)) as usize
    }

    /// The bucket and slot of `action_id`.
    fn find(&self, action_id: u32) -> Option<(usize, u32)> {
        let mask = self.index.len() - 1;
        let mut bucket = self.home(action_id);
        loop {
            let slot = *self.index.get(bucket)?;
            if slot == NIL {
                return None;
            }
            if self.slots.get(slot as usize)?.action_id == action_id {
                return Some((bucket, slot));
            }
            bucket = (bucket + 1) & mask;
        }
    }

    fn insert_into_index(&mut self, action_id: u32, slot: u32) {
        let mask = self.index.len() - 1;
        let mut bucket = self.home(action_id);
        // The index has at least twice as many buckets as slots: an empty one exists.
        while let Some(b) = self.index.get_mut(bucket) {
            if *b == NIL {
                *b = slot;
                return;
            }
            bucket = (bucket + 1) & mask;
        }
    }

    /// Empties the bucket of `action_id` and moves later entries of its probe run back
    /// (no tombstones: lookups stay short however many actions came and went).
    fn remove_from_index(&mut self, action_id: u32) {
        let Some((mut hole, _)) = self.find(action_id) else {
            return;
        };
        let mask = self.index.len() - 1;
        let mut bucket = hole;
        loop {
            bucket = (bucket + 1) & mask;
            let slot = self.index.get(bucket).copied().unwrap_or(NIL);
            if slot == NIL {
                break;
            }
            let Some(id) = self.slots.get(slot as usize).map(|s| s.action_id) else {
                break;
            };
            // An entry may move back to the hole unless its home lies after the hole,
            // up to the entry itself (cyclically).
            let home = self.home(id);
            let stays = if hole <= bucket {
                hole < home && home <= bucket
            } else {
                hole < home || home <= bucket
            };
            if !stays {
                if let Some(b) = self.index.get_mut(hole) {
                    *b = slot;
                }
                hole = bucket;
            }
        }
        if let Some(b) = self.index.get_mut(hole) {
            *b = NIL;
        }
    }
}

#[cfg(test)]
mod tests;
