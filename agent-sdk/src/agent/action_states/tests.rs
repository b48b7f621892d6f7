//! The O(1) structure against the plain one it replaced (a list searched from end to end),
//! kept here as the reference model of what the agent remembers and forgets.

use proptest::prelude::*;

use super::*;
use crate::agent::ACTION_STATES_CAPACITY;

/// The reference: `(action id, state, seq)` in a list; a known action's entry is updated
/// in place; when full, the entry with the smallest seq among the finished and aborted
/// ones goes, else the one with the smallest seq.
struct Reference {
    entries: Vec<(u32, ActionState, u64)>,
    capacity: usize,
}

impl Reference {
    fn new(capacity: usize) -> Self {
        Self {
            entries: Vec::new(),
            capacity,
        }
    }

    fn get(&self, action_id: u32) -> Option<ActionState> {
        self.entries.iter().find(|e| e.0 == action_id).map(|e| e.1)
    }

    fn update(&mut self, status: &ActionStatus) {
        let Some(state) = ActionState::from_u32(status.state) else {
            return;
        };
        if let Some(e) = self.entries.iter_mut().find(|e| e.0 == status.action_id) {
            *e = (status.action_id, state, status.seq);
            return;
        }
        if self.entries.len() >= self.capacity {
            let oldest = |done: bool| {
                self.entries
                    .iter()
                    .enumerate()
                    .filter(|(_, e)| {
                        !done || matches!(e.1, ActionState::Finished | ActionState::Aborted)
                    })
                    .min_by_key(|(_, e)| e.2)
                    .map(|(i, _)| i)
            };
            if let Some(i) = oldest(true).or_else(|| oldest(false)) {
                self.entries.swap_remove(i);
            }
        }
        self.entries.push((status.action_id, state, status.seq));
    }

    fn sorted(&self) -> Vec<(u32, ActionState)> {
        let mut v: Vec<_> = self.entries.iter().map(|e| (e.0, e.1)).collect();
        v.sort_by_key(|e| e.0);
        v
    }
}

fn sorted(states: &ActionStates) -> Vec<(u32, ActionState)> {
    let mut v: Vec<_> = states.iter().collect();
    v.sort_by_key(|e| e.0);
    v
}

fn status(action_id: u32, state: u32, seq: u64) -> ActionStatus {
    ActionStatus {
        action_id,
        state,
        seq,
    }
}

/// Feeds `updates` (action id, state) with ascending seqs to both and compares them after
/// every update, asking for every id in `ids`.
fn same_as_reference(
    capacity: usize,
    updates: &[(u32, u32)],
    ids: impl Iterator<Item = u32> + Clone,
) {
    let mut states = ActionStates::with_capacity(capacity);
    let mut reference = Reference::new(capacity);
    for (n, &(action_id, state)) in updates.iter().enumerate() {
        let s = status(action_id, state, n as u64 + 1);
        states.update(&s);
        reference.update(&s);
        assert_eq!(
            sorted(&states),
            reference.sorted(),
            "after update {n}: {s:?}"
        );
        for id in ids.clone() {
            assert_eq!(
                states.get(id),
                reference.get(id),
                "action {id} after update {n}"
            );
        }
    }
}

#[test]
fn remembers_the_latest_state_of_each_action() {
    let mut states = ActionStates::with_capacity(4);
    states.update(&status(7, ActionState::InExecution as u32, 1));
    states.update(&status(9, ActionState::Walking as u32, 2));
    states.update(&status(7, ActionState::Finished as u32, 3));
    assert_eq!(states.get(7), Some(ActionState::Finished));
    assert_eq!(states.get(9), Some(ActionState::Walking));
    assert_eq!(states.get(8), None);
    // An unknown state is ignored.
    states.update(&status(9, 99, 4));
    assert_eq!(states.get(9), Some(ActionState::Walking));
}

#[test]
fn when_full_forgets_the_oldest_finished_or_aborted_action_first() {
    let mut states = ActionStates::with_capacity(3);
    states.update(&status(1, ActionState::InExecution as u32, 1));
    states.update(&status(2, ActionState::Finished as u32, 2));
    states.update(&status(3, ActionState::Aborted as u32, 3));
    states.update(&status(4, ActionState::Walking as u32, 4));
    assert_eq!(states.get(2), None, "the oldest done action goes");
    assert_eq!(states.get(1), Some(ActionState::InExecution));
    states.update(&status(5, ActionState::Rotating as u32, 5));
    assert_eq!(states.get(3), None, "then the next done one");
    // Nothing done left: the oldest of all goes.
    states.update(&status(6, ActionState::Rotating as u32, 6));
    assert_eq!(states.get(1), None);
    assert_eq!(sorted(&states).len(), 3);
    // A status of a known action moves it to the newest end.
    states.update(&status(4, ActionState::WalkingRotating as u32, 7));
    states.update(&status(8, ActionState::InExecution as u32, 8));
    assert_eq!(states.get(5), None);
    assert_eq!(states.get(4), Some(ActionState::WalkingRotating));
}

/// The agent's steady state: a fresh action id every cycle (as `Agent::send` numbers
/// them), each reported in execution, then finished, far beyond the capacity; and ids
/// that wrap around `u32::MAX`.
#[test]
fn steady_churn_at_full_capacity_matches_the_reference() {
    let mut updates = Vec::new();
    for id in 1..=3 * ACTION_STATES_CAPACITY as u32 {
        updates.push((id, ActionState::InExecution as u32));
        if id > 2 {
            updates.push((id - 2, ActionState::Finished as u32));
        }
    }
    let mut states = ActionStates::with_capacity(ACTION_STATES_CAPACITY);
    let mut reference = Reference::new(ACTION_STATES_CAPACITY);
    for (n, &(id, state)) in updates.iter().enumerate() {
        let s = status(id, state, n as u64 + 1);
        states.update(&s);
        reference.update(&s);
    }
    assert_eq!(sorted(&states), reference.sorted());
    for id in 0..=3 * ACTION_STATES_CAPACITY as u32 + 1 {
        assert_eq!(states.get(id), reference.get(id), "action {id}");
    }
    let high: Vec<(u32, u32)> = (0..40u32)
        .map(|i| ((u32::MAX - 20).wrapping_add(i), i % 6))
        .collect();
    same_as_reference(
        16,
        &high,
        (0..40u32).map(|i| (u32::MAX - 20).wrapping_add(i)),
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    /// Any sequence of statuses (ids from a small range so that they repeat, states
    /// including unknown values) at small capacities: the same states remembered and
    /// forgotten as the reference, after every status.
    #[test]
    fn behaves_as_the_reference(
        capacity in 1usize..10,
        updates in proptest::collection::vec((0u32..24, 0u32..8), 0..200),
    ) {
        same_as_reference(capacity, &updates, 0u32..25);
    }

    /// Ids spread over the whole range (collisions in the index, wrap-around of probes).
    #[test]
    fn behaves_as_the_reference_with_any_ids(
        capacity in 1usize..40,
        pool in proptest::collection::vec(any::<u32>(), 1..60),
        picks in proptest::collection::vec((any::<proptest::sample::Index>(), 0u32..7), 0..300),
    ) {
        let updates: Vec<(u32, u32)> =
            picks.iter().map(|(i, s)| (pool[i.index(pool.len())], *s)).collect();
        same_as_reference(capacity, &updates, pool.iter().copied());
    }
}
