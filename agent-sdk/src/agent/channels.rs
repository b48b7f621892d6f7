//! The agent's channels (`[[agent.vector]]`, `[[agent.action]]`): reading vectors from a
//! frame, sending actions, and the check that host and agent agree on them.

use vrsync_transport::{
    ActionConfig, ActionDesc, ActionSpace, AgentConfig, AgentFrame, ChannelLayout, MAX_ACTIONS,
    MAX_VECTORS, SensorHeader, VectorDesc, action_chunks, discrete_action_chunk,
};

use super::{Agent, Frame, SendError};

/// Why [`Agent::act`] or [`Agent::act_discrete`] refused a value. Nothing was queued.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ActError {
    /// The config declares no action of that name for this agent.
    #[error("agent {agent} has no action {name:?} (its actions: {known})")]
    UnknownAction {
        /// This agent.
        agent: u32,
        /// The name asked for.
        name: String,
        /// The agent's actions, comma separated (or "none").
        known: String,
    },
    /// A continuous action's value has the wrong length.
    #[error("action {action:?} takes {expected} floats, got {found}")]
    WrongLength {
        /// The action.
        action: String,
        /// Its `len`.
        expected: usize,
        /// The value's length.
        found: usize,
    },
    /// A value is outside the action's bounds, or not finite.
    #[error("action {action:?}: value {index} is {value}, outside [{low}, {high}]")]
    OutOfBounds {
        /// The action.
        action: String,
        /// Index of the value.
        index: usize,
        /// The value.
        value: f32,
        /// Its lower bound.
        low: f32,
        /// Its upper bound.
        high: f32,
    },
    /// A discrete action's choice is not below its `n`.
    #[error("action {action:?} is a choice in 0..{n}, got {choice}")]
    ChoiceOutOfRange {
        /// The action.
        action: String,
        /// Number of choices.
        n: u32,
        /// The choice given.
        choice: u32,
    },
    /// The action is continuous and was given a choice, or the other way round.
    #[error("action {action:?} is {is}: use {use_instead}")]
    WrongKind {
        /// The action.
        action: String,
        /// What it is ("continuous", "discrete").
        is: &'static str,
        /// The call to use.
        use_instead: &'static str,
    },
    /// The value does not fit this cycle's queue (`max_commands_per_cycle`; a continuous
    /// action takes one entry per 4 values).
    #[error(transparent)]
    Queue(#[from] SendError),
}

/// What this agent's config says of its channels, in the form the host's frames carry it.
#[derive(Debug, Clone)]
pub(super) struct Channels {
    vectors: [VectorDesc; MAX_VECTORS],
    vector_count: usize,
    actions: [ActionDesc; MAX_ACTIONS],
    action_count: usize,
    specs: Vec<ActionConfig>,
}

impl Channels {
    pub(super) fn new(agent: Option<&AgentConfig>) -> Self {
        let (vectors, vector_count, actions, action_count, specs) = match agent {
            Some(a) => (
                a.vector_layout().0,
                a.vectors.len(),
                a.action_table(),
                a.actions.len(),
                a.actions.clone(),
            ),
            None => Default::default(),
        };
        Self {
            vectors,
            vector_count,
            actions,
            action_count,
            specs,
        }
    }

    /// The action specs, in wire order.
    pub(super) fn specs(&self) -> &[ActionConfig] {
        &self.specs
    }

    /// Checks that the host's frame carries the channels this agent's config declares;
    /// the error names the first channel that differs. (Host and agent compare their
    /// layouts at connect already; this catches a host that writes other tables than its
    /// config declares.)
    pub(super) fn check(&self, h: &SensorHeader, payload_len: usize) -> Result<(), String> {
        let ours = &self.vectors[..self.vector_count];
        let actions = &self.actions[..self.action_count];
        if h.vector_descs() != ours || h.action_descs() != actions {
            let host = ChannelLayout::from_descs(h.vector_descs(), h.action_descs());
            let agent = ChannelLayout::from_descs(ours, actions);
            return Err(match host.difference(&agent) {
                Some(d) => d.to_string(),
                None => "the host's frame places the vectors elsewhere than this agent's \
                         config (do both configs have the same cameras?)"
                    .to_owned(),
            });
        }
        if let Some(d) = ours
            .iter()
            .find(|d| d.offset + d.byte_len() > payload_len as u64)
        {
            return Err(format!(
                "vector {:?} does not fit the {payload_len}-byte payload",
                d.name()
            ));
        }
        Ok(())
    }
}

impl Frame {
    /// The vector (`[[agent.vector]]`) called `name`: its values straight in shared memory
    /// on the shm transport. `None` if the agent has no such vector.
    pub fn vector(&self, name: &str) -> Option<&[f32]> {
        let d = self
            .header()
            .vector_descs()
            .iter()
            .find(|d| d.name() == name)?;
        d.values(self.inner.payload())
    }

    /// The vector descriptions of this frame, in payload order.
    pub fn vector_descs(&self) -> &[VectorDesc] {
        self.header().vector_descs()
    }
}

impl Agent {
    /// This agent's actions (`[[agent.action]]`), in config order.
    pub fn actions(&self) -> &[ActionConfig] {
        self.channels.specs()
    }

    fn action(&self, name: &str) -> Result<(u32, &ActionConfig), ActError> {
        let specs = self.channels.specs();
        match specs.iter().position(|a| a.name == name) {
            Some(i) => Ok((i as u32, &specs[i])),
            None => Err(ActError::UnknownAction {
                agent: self.id,
                name: name.to_owned(),
                known: if specs.is_empty() {
                    "none".to_owned()
                } else {
                    specs
                        .iter()
                        .map(|a| a.name.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                },
            }),
        }
    }

    /// Queues the value of the continuous action `name` for this cycle; it goes with the
    /// next [`Agent::stop`]. The host takes the last value sent in a cycle.
    ///
    /// # Errors
    /// [`ActError`]: no such action, the wrong length, a value out of bounds or not finite,
    /// a discrete action, or a full queue. Nothing is queued then.
    pub fn act(&mut self, name: &str, value: &[f32]) -> Result<(), ActError> {
        let (index, spec) = self.action(name)?;
        let ActionSpace::Box { low, high } = &spec.space else {
            return Err(ActError::WrongKind {
                action: name.to_owned(),
                is: "discrete",
                use_instead: "act_discrete",
            });
        };
        if value.len() != low.len() {
            return Err(ActError::WrongLength {
                action: name.to_owned(),
                expected: low.len(),
                found: value.len(),
            });
        }
        if let Some((i, &v)) = value
            .iter()
            .enumerate()
            .find(|&(i, v)| !(v.is_finite() && *v >= low[i] && *v <= high[i]))
        {
            return Err(ActError::OutOfBounds {
                action: name.to_owned(),
                index: i,
                value: v,
                low: low[i],
                high: high[i],
            });
        }
        let chunks = value.len().div_ceil(vrsync_transport::ACTION_CHUNK);
        self.reserve(chunks)?;
        self.queue.extend(action_chunks(index, value));
        Ok(())
    }

    /// Queues the choice of the discrete action `name` for this cycle (as [`Agent::act`]).
    ///
    /// # Errors
    /// [`ActError`]: no such action, a choice not below its `n`, a continuous action, or
    /// a full queue.
    pub fn act_discrete(&mut self, name: &str, choice: u32) -> Result<(), ActError> {
        let (index, spec) = self.action(name)?;
        let ActionSpace::Discrete { n } = spec.space else {
            return Err(ActError::WrongKind {
                action: name.to_owned(),
                is: "continuous",
                use_instead: "act",
            });
        };
        if choice >= n {
            return Err(ActError::ChoiceOutOfRange {
                action: name.to_owned(),
                n,
                choice,
            });
        }
        self.reserve(1)?;
        self.queue.push(discrete_action_chunk(index, choice));
        Ok(())
    }

    fn reserve(&self, entries: usize) -> Result<(), SendError> {
        if self.queue.len() + entries > self.max_commands {
            return Err(SendError::QueueFull {
                max: self.max_commands,
            });
        }
        Ok(())
    }
}
