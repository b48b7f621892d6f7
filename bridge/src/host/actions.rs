//! The actions an agent sent in one cycle (`[[agent.action]]`), assembled from the chunks
//! its batches carry (see `crate::wire`'s channels), checked against the config.

use crate::wire::{ACTION_CHUNK, MotorCommand};
use vrsync_transport::{ActionConfig, ActionSpace};

/// The value of one action in one cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ActionValue<'a> {
    /// A continuous action's values (as many as its `len`).
    Box(&'a [f32]),
    /// A discrete action's choice (below its `n`).
    Discrete(u32),
}

/// One action of one agent: its spec, the value of this cycle, and the value being
/// assembled from chunks.
#[derive(Debug, Clone)]
struct Inbox {
    spec: ActionConfig,
    /// The last complete value of this cycle (box actions).
    value: Vec<f32>,
    /// The last choice of this cycle (discrete actions).
    choice: u32,
    /// A complete value arrived this cycle.
    sent: bool,
    /// The value being assembled (box actions).
    staging: Vec<f32>,
    /// Chunks of `staging` received, one bit per chunk; `None`: nothing valid under way.
    filled: Option<u64>,
}

/// Every action of one agent.
#[derive(Debug, Clone, Default)]
pub(super) struct AgentActions {
    actions: Vec<Inbox>,
    /// Chunks refused this cycle.
    pub(super) rejected: u32,
}

impl AgentActions {
    pub(super) fn new(specs: &[ActionConfig]) -> Self {
        Self {
            actions: specs
                .iter()
                .map(|spec| Inbox {
                    value: vec![0.0; spec.len()],
                    staging: vec![0.0; spec.len()],
                    spec: spec.clone(),
                    choice: 0,
                    sent: false,
                    filled: None,
                })
                .collect(),
            rejected: 0,
        }
    }

    /// Forgets the previous cycle's values.
    pub(super) fn begin_cycle(&mut self) {
        for a in &mut self.actions {
            a.sent = false;
            a.filled = None;
        }
        self.rejected = 0;
    }

    /// Takes one chunk; `false` if it was refused (unknown action, out of place, wrong
    /// length, non-finite or out of bounds): nothing of it, nor of the value it belongs
    /// to, is applied.
    pub(super) fn take(&mut self, chunk: &MotorCommand) -> bool {
        let ok = self
            .actions
            .get_mut(chunk.action_id as usize)
            .is_some_and(|a| a.take(chunk));
        if !ok {
            self.rejected += 1;
        }
        ok
    }

    /// The value of action `name` this cycle, `None` if none (complete) was sent.
    pub(super) fn get(&self, name: &str) -> Option<ActionValue<'_>> {
        self.actions
            .iter()
            .find(|a| a.spec.name == name)
            .and_then(Inbox::value)
    }

    /// Every action in config order, with its value this cycle.
    pub(super) fn iter(&self) -> impl Iterator<Item = (&str, Option<ActionValue<'_>>)> {
        self.actions
            .iter()
            .map(|a| (a.spec.name.as_str(), a.value()))
    }
}

impl Inbox {
    fn value(&self) -> Option<ActionValue<'_>> {
        if !self.sent {
            return None;
        }
        Some(match self.spec.space {
            ActionSpace::Box { .. } => ActionValue::Box(&self.value),
            ActionSpace::Discrete { .. } => ActionValue::Discrete(self.choice),
        })
    }

    fn take(&mut self, chunk: &MotorCommand) -> bool {
        match &self.spec.space {
            ActionSpace::Discrete { n } => {
                if chunk.object_id >= *n || chunk.args != [0.0; ACTION_CHUNK] {
                    return false;
                }
                self.choice = chunk.object_id;
                self.sent = true;
                true
            }
            ActionSpace::Box { low, high } => {
                let len = low.len();
                let start = chunk.object_id as usize;
                let k = start / ACTION_CHUNK;
                if !start.is_multiple_of(ACTION_CHUNK) || start >= len {
                    self.filled = None;
                    return false;
                }
                let count = (len - start).min(ACTION_CHUNK);
                let values = &chunk.args[..count];
                let in_bounds = values
                    .iter()
                    .enumerate()
                    .all(|(i, v)| v.is_finite() && *v >= low[start + i] && *v <= high[start + i]);
                // The first chunk starts a value; the others continue the one under way,
                // in order.
                let expected = if k == 0 {
                    Some(0)
                } else {
                    self.filled.filter(|f| *f == (1u64 << k) - 1)
                };
                if !in_bounds || expected.is_none() || chunk.args[count..].iter().any(|v| *v != 0.0)
                {
                    self.filled = None;
                    return false;
                }
                self.staging[start..start + count].copy_from_slice(values);
                let filled = expected.unwrap_or(0) | (1u64 << k);
                if start + count == len {
                    self.value.copy_from_slice(&self.staging);
                    self.sent = true;
                    self.filled = None;
                } else {
                    self.filled = Some(filled);
                }
                true
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wire::{action_chunks, discrete_action_chunk};

    fn specs() -> Vec<ActionConfig> {
        vec![
            ActionConfig {
                name: "torque".into(),
                space: ActionSpace::Box {
                    low: vec![-1.0; 7],
                    high: vec![1.0; 7],
                },
            },
            ActionConfig {
                name: "gear".into(),
                space: ActionSpace::Discrete { n: 3 },
            },
        ]
    }

    #[test]
    fn the_last_complete_value_of_the_cycle_wins() {
        let mut a = AgentActions::new(&specs());
        a.begin_cycle();
        assert_eq!(a.get("torque"), None);
        let v1 = [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7];
        let v2 = [-0.1, -0.2, -0.3, -0.4, -0.5, -0.6, -0.7];
        for c in action_chunks(0, &v1).chain(action_chunks(0, &v2)) {
            assert!(a.take(&c));
        }
        assert!(a.take(&discrete_action_chunk(1, 2)));
        assert_eq!(a.get("torque"), Some(ActionValue::Box(&v2)));
        assert_eq!(a.get("gear"), Some(ActionValue::Discrete(2)));
        let names: Vec<_> = a.iter().map(|(n, _)| n).collect();
        assert_eq!(names, ["torque", "gear"]);
        a.begin_cycle();
        assert_eq!(a.get("torque"), None);
        assert_eq!(a.get("gear"), None);
        assert_eq!(a.rejected, 0);
    }

    #[test]
    fn malformed_chunks_are_refused_and_never_applied() {
        let mut a = AgentActions::new(&specs());
        a.begin_cycle();
        let good = [0.5; 7];
        for c in action_chunks(0, &good) {
            assert!(a.take(&c));
        }
        // Out of bounds: the value under way is dropped, the last good one stays.
        let mut bad: Vec<_> = action_chunks(0, &[0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 0.0]).collect();
        assert!(!a.take(&bad[0]));
        assert!(
            !a.take(&bad[1]),
            "a continuation without its start is refused"
        );
        // NaN, unknown action, a chunk past the end, a choice out of range.
        bad[0].args[1] = f32::NAN;
        assert!(!a.take(&bad[0]));
        let mut unknown = bad[1];
        unknown.action_id = 7;
        assert!(!a.take(&unknown));
        let mut past = bad[1];
        past.object_id = 8;
        assert!(!a.take(&past));
        assert!(!a.take(&discrete_action_chunk(1, 3)));
        // Too short: the value never completes.
        let short: Vec<_> = action_chunks(0, &[0.9; 4]).collect();
        assert!(a.take(&short[0]));
        assert_eq!(a.rejected, 6);
        assert_eq!(a.get("torque"), Some(ActionValue::Box(&good)));
        assert_eq!(a.get("gear"), None);
    }
}
