//! Channels of an agent (`[[agent.vector]]`, `[[agent.action]]`): their typed form and
//! their checks. What they are on the wire: `crate::wire` (`channels`).

use std::collections::BTreeSet;

use toml::Spanned;

use super::ConfigLoadError;
use super::ctx::Ctx;
use super::raw::{RawAction, RawBound, RawVector};
use crate::wire::{
    ActionDesc, CHANNEL_NAME_LEN, MAX_ACTION_LEN, MAX_ACTIONS, MAX_VECTOR_LEN, MAX_VECTORS,
    bounds_hash,
};

/// One `[[agent.vector]]`: a float vector the host writes into every sensor frame of the
/// agent, beside its images (joint readings, proprioception, anything numeric).
#[derive(Debug, Clone, PartialEq)]
pub struct VectorConfig {
    /// Name (1 to 16 bytes), unique among the agent's vectors.
    pub name: String,
    /// Number of `f32` values.
    pub len: u32,
    /// Lower bound of each value for the observation space (`low`, default -∞): not
    /// enforced, the host's values are its own.
    pub low: Vec<f32>,
    /// Upper bound of each value (`high`, default +∞).
    pub high: Vec<f32>,
}

/// What an action (`[[agent.action]]`) holds.
#[derive(Debug, Clone, PartialEq)]
pub enum ActionSpace {
    /// A continuous `f32` vector with per-value bounds (`len`, `low`, `high`): its length
    /// is `low.len()`.
    Box {
        /// Lowest value accepted, per value.
        low: Vec<f32>,
        /// Highest value accepted, per value.
        high: Vec<f32>,
    },
    /// A choice in `0..n` (`n`).
    Discrete {
        /// Number of choices.
        n: u32,
    },
}

/// One `[[agent.action]]`: what the agent sends back each cycle before its stop.
#[derive(Debug, Clone, PartialEq)]
pub struct ActionConfig {
    /// Name (1 to 16 bytes), unique among the agent's actions.
    pub name: String,
    /// Continuous or discrete, with its bounds.
    pub space: ActionSpace,
}

impl ActionConfig {
    /// Number of `f32` values of a continuous action; 1 for a discrete one.
    pub fn len(&self) -> usize {
        match &self.space {
            ActionSpace::Box { low, .. } => low.len(),
            ActionSpace::Discrete { .. } => 1,
        }
    }

    /// Whether the action holds no value (never: the checks refuse `len = 0`).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The action's entry in the sensor header's action table.
    pub fn desc(&self) -> ActionDesc {
        let name = crate::wire::padded_name(&self.name);
        match &self.space {
            ActionSpace::Box { low, high } => ActionDesc {
                name,
                len: low.len() as u32,
                n: 0,
                bounds_hash: bounds_hash(low, high),
            },
            ActionSpace::Discrete { n } => ActionDesc {
                name,
                len: 0,
                n: *n,
                bounds_hash: 0,
            },
        }
    }

    /// What it accepts, for messages: `"7 floats in [-1, 1]"`, `"a choice in 0..3"`.
    pub fn describe(&self) -> String {
        match &self.space {
            ActionSpace::Box { low, high } => {
                let same = |v: &[f32]| v.iter().all(|x| x.to_bits() == v[0].to_bits());
                if !low.is_empty() && same(low) && same(high) {
                    format!("{} floats in [{}, {}]", low.len(), low[0], high[0])
                } else {
                    format!("{} floats within per-value bounds", low.len())
                }
            }
            ActionSpace::Discrete { n } => format!("a choice in 0..{n}"),
        }
    }
}

impl Ctx<'_> {
    fn channel_name(
        &self,
        name: &Spanned<String>,
        key: &str,
        agent: u32,
        names: &mut BTreeSet<String>,
    ) -> Result<String, ConfigLoadError> {
        let n = name.get_ref();
        let ok = !n.is_empty()
            && n.len() <= CHANNEL_NAME_LEN
            && n.bytes()
                .all(|b| b.is_ascii_alphanumeric() || b"_-.".contains(&b));
        if !ok {
            return Err(self.invalid(
                name.span(),
                key,
                format!("{n:?}: use 1 to {CHANNEL_NAME_LEN} characters from A-Z a-z 0-9 _ - ."),
            ));
        }
        if !names.insert(n.clone()) {
            return Err(self.invalid(
                name.span(),
                key,
                format!("agent {agent} has two channels named {n:?} of this kind"),
            ));
        }
        Ok(n.clone())
    }

    fn channel_len(
        &self,
        len: &Spanned<i64>,
        key: &str,
        max: u32,
    ) -> Result<usize, ConfigLoadError> {
        let n = *len.get_ref();
        if !(1..=i64::from(max)).contains(&n) {
            return Err(self.invalid(len.span(), key, format!("must be 1..={max}, found {n}")));
        }
        Ok(n as usize)
    }

    /// A bound expanded to `len` values; `default` when absent.
    fn bound(
        &self,
        b: Option<&Spanned<RawBound>>,
        key: &str,
        len: usize,
        default: f32,
    ) -> Result<Vec<f32>, ConfigLoadError> {
        let Some(b) = b else {
            return Ok(vec![default; len]);
        };
        let values = match b.get_ref() {
            RawBound::One(v) => vec![*v; len],
            RawBound::Each(v) if v.len() == len => v.clone(),
            RawBound::Each(v) => {
                return Err(self.invalid(
                    b.span(),
                    key,
                    format!("has {} values, the channel has {len}", v.len()),
                ));
            }
        };
        if let Some(v) = values.iter().find(|v| v.is_nan()) {
            return Err(self.invalid(b.span(), key, format!("{v} is not a number")));
        }
        Ok(values.into_iter().map(|v| v as f32).collect())
    }

    fn low_high(
        &self,
        low: Option<&Spanned<RawBound>>,
        high: Option<&Spanned<RawBound>>,
        key: &str,
        len: usize,
    ) -> Result<(Vec<f32>, Vec<f32>), ConfigLoadError> {
        let lo = self.bound(low, &format!("{key}.low"), len, f32::NEG_INFINITY)?;
        let hi = self.bound(high, &format!("{key}.high"), len, f32::INFINITY)?;
        if let Some(i) = (0..len).find(|&i| lo[i] > hi[i]) {
            let span = high.or(low).map(Spanned::span).unwrap_or(0..0);
            return Err(self.invalid(
                span,
                &format!("{key}.high"),
                format!("value {i}: high {} is below low {}", hi[i], lo[i]),
            ));
        }
        Ok((lo, hi))
    }

    /// The `[[agent.vector]]` entries of agent `agent`.
    pub(super) fn vectors(
        &self,
        raw: Vec<Spanned<RawVector>>,
        agent: u32,
    ) -> Result<Vec<VectorConfig>, ConfigLoadError> {
        if let Some(extra) = raw.get(MAX_VECTORS) {
            return Err(self.invalid(
                extra.span(),
                "agent.vector",
                format!(
                    "agent {agent} has {} vectors, at most {MAX_VECTORS}",
                    raw.len()
                ),
            ));
        }
        let mut names = BTreeSet::new();
        raw.into_iter()
            .map(|v| {
                let v = v.into_inner();
                let name = self.channel_name(&v.name, "agent.vector.name", agent, &mut names)?;
                let len = self.channel_len(&v.len, "agent.vector.len", MAX_VECTOR_LEN)?;
                let (low, high) =
                    self.low_high(v.low.as_ref(), v.high.as_ref(), "agent.vector", len)?;
                Ok(VectorConfig {
                    name,
                    len: len as u32,
                    low,
                    high,
                })
            })
            .collect()
    }

    /// The `[[agent.action]]` entries of agent `agent`.
    pub(super) fn actions(
        &self,
        raw: Vec<Spanned<RawAction>>,
        agent: u32,
    ) -> Result<Vec<ActionConfig>, ConfigLoadError> {
        if let Some(extra) = raw.get(MAX_ACTIONS) {
            return Err(self.invalid(
                extra.span(),
                "agent.action",
                format!(
                    "agent {agent} has {} actions, at most {MAX_ACTIONS}",
                    raw.len()
                ),
            ));
        }
        let mut names = BTreeSet::new();
        raw.into_iter()
            .map(|a| {
                let span = a.span();
                let a = a.into_inner();
                let name = self.channel_name(&a.name, "agent.action.name", agent, &mut names)?;
                let space = match (&a.len, &a.n) {
                    (Some(len), None) => {
                        let len = self.channel_len(len, "agent.action.len", MAX_ACTION_LEN)?;
                        if a.low.is_none() || a.high.is_none() {
                            return Err(self.invalid(
                                span,
                                "agent.action",
                                format!(
                                    "continuous action {name:?} of agent {agent} needs both \
                                     `low` and `high` (a number or a list of {len})"
                                ),
                            ));
                        }
                        let (low, high) =
                            self.low_high(a.low.as_ref(), a.high.as_ref(), "agent.action", len)?;
                        if let Some(v) = low.iter().chain(&high).find(|v| !v.is_finite()) {
                            return Err(self.invalid(
                                span,
                                "agent.action",
                                format!("action {name:?}: bounds must be finite, found {v}"),
                            ));
                        }
                        ActionSpace::Box { low, high }
                    }
                    (None, Some(n)) => {
                        if a.low.is_some() || a.high.is_some() {
                            return Err(self.invalid(
                                span,
                                "agent.action",
                                format!("discrete action {name:?} takes no `low`/`high`"),
                            ));
                        }
                        let n = self.channel_len(n, "agent.action.n", u32::MAX)?;
                        ActionSpace::Discrete { n: n as u32 }
                    }
                    _ => {
                        return Err(self.invalid(
                            span,
                            "agent.action",
                            format!(
                                "action {name:?} of agent {agent}: give either `len` with \
                                 `low`/`high` (continuous) or `n` (discrete), not both"
                            ),
                        ));
                    }
                };
                Ok(ActionConfig { name, space })
            })
            .collect()
    }
}
