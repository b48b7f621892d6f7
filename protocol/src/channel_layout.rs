//! One agent's channels (`[[agent.vector]]`, `[[agent.action]]`) as host and agent compare
//! them **at connect**: a short canonical text, its hash (what a network agent's hello
//! carries), and the difference between two layouts, naming the first channel that
//! differs.
//!
//! The text is one entry per channel, separated by `;`, vectors first, each in config
//! order: `v:joints:6` (a vector of 6 floats), `a:torque:7:<bounds hash, 16 hex digits>`
//! (a continuous action of 7 floats), `d:gear:3` (a discrete action with 3 choices).
//! Channel names are `[A-Za-z0-9_.-]{1,16}` (the config checks it), so the text needs no
//! escaping; at most [`MAX_VECTORS`] + [`MAX_ACTIONS`] entries make it at most
//! [`MAX_TEXT`] bytes.

use core::fmt;

use crate::wire::{ActionDesc, CHANNEL_NAME_LEN, MAX_ACTIONS, MAX_VECTORS, VectorDesc};

/// Longest layout text: every vector and action with a 16-byte name and the widest
/// numbers.
pub const MAX_TEXT: usize = MAX_VECTORS * (2 + CHANNEL_NAME_LEN + 1 + 10 + 1)
    + MAX_ACTIONS * (2 + CHANNEL_NAME_LEN + 1 + 10 + 1 + 16 + 1);

/// One channel as the connect check compares it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Channel {
    /// A vector of `len` floats the host writes into every sensor frame.
    Vector {
        /// Its name.
        name: String,
        /// Number of floats.
        len: u32,
    },
    /// A continuous action of `len` floats within bounds that hash to `bounds_hash`
    /// ([`crate::wire::bounds_hash`]).
    Continuous {
        /// Its name.
        name: String,
        /// Number of floats.
        len: u32,
        /// Hash of its `low` and `high` bounds.
        bounds_hash: u64,
    },
    /// A discrete action: a choice in `0..n`.
    Discrete {
        /// Its name.
        name: String,
        /// Number of choices.
        n: u32,
    },
}

impl Channel {
    /// The channel's name.
    pub fn name(&self) -> &str {
        match self {
            Self::Vector { name, .. }
            | Self::Continuous { name, .. }
            | Self::Discrete { name, .. } => name,
        }
    }

    /// "vector" or "action": the config table it comes from (`[[agent.vector]]`, ...).
    pub fn table(&self) -> &'static str {
        match self {
            Self::Vector { .. } => "vector",
            Self::Continuous { .. } | Self::Discrete { .. } => "action",
        }
    }

    /// What the channel is, for people: "6 floats", "7 floats (bounds 00ab…)", "a choice
    /// in 0..3".
    pub fn shape(&self) -> String {
        match self {
            Self::Vector { len, .. } => format!("{len} floats"),
            Self::Continuous {
                len, bounds_hash, ..
            } => format!("{len} floats (bounds {bounds_hash:016x})"),
            Self::Discrete { n, .. } => format!("a choice in 0..{n}"),
        }
    }

    fn write_text(&self, out: &mut String) {
        use fmt::Write as _;
        let _ = match self {
            Self::Vector { name, len } => write!(out, "v:{name}:{len}"),
            Self::Continuous {
                name,
                len,
                bounds_hash,
            } => write!(out, "a:{name}:{len}:{bounds_hash:016x}"),
            Self::Discrete { name, n } => write!(out, "d:{name}:{n}"),
        };
    }

    fn parse(entry: &str) -> Option<Self> {
        let mut parts = entry.split(':');
        let tag = parts.next()?;
        let name = parts.next().filter(|n| valid_name(n))?.to_owned();
        let number = parts.next()?.parse::<u32>().ok()?;
        let channel = match tag {
            "v" => Self::Vector { name, len: number },
            "a" => Self::Continuous {
                name,
                len: number,
                bounds_hash: parts
                    .next()
                    .filter(|h| h.len() == 16)
                    .and_then(|h| u64::from_str_radix(h, 16).ok())?,
            },
            "d" => Self::Discrete { name, n: number },
            _ => return None,
        };
        parts.next().is_none().then_some(channel)
    }
}

/// The 64-bit FNV-1a hash of `bytes`: a layout's hash (over its canonical text), and the
/// short stable name the shared-memory transport derives from a session name.
pub fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325_u64, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

fn valid_name(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= CHANNEL_NAME_LEN
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b"_-.".contains(&b))
}

/// One agent's channels, in the order its config lists them: what host and agent must
/// agree on before the first frame.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ChannelLayout {
    vectors: Vec<Channel>,
    actions: Vec<Channel>,
}

impl ChannelLayout {
    /// The layout the tables of a sensor frame (or a config's) describe.
    pub fn from_descs(vectors: &[VectorDesc], actions: &[ActionDesc]) -> Self {
        Self {
            vectors: vectors
                .iter()
                .map(|d| Channel::Vector {
                    name: d.name().to_owned(),
                    len: d.len,
                })
                .collect(),
            actions: actions
                .iter()
                .map(|d| match d.n {
                    0 => Channel::Continuous {
                        name: d.name().to_owned(),
                        len: d.len,
                        bounds_hash: d.bounds_hash,
                    },
                    n => Channel::Discrete {
                        name: d.name().to_owned(),
                        n,
                    },
                })
                .collect(),
        }
    }

    /// The vectors, in config order.
    pub fn vectors(&self) -> &[Channel] {
        &self.vectors
    }

    /// The actions, in config order.
    pub fn actions(&self) -> &[Channel] {
        &self.actions
    }

    /// Whether the agent has no channel at all.
    pub fn is_empty(&self) -> bool {
        self.vectors.is_empty() && self.actions.is_empty()
    }

    /// The canonical text (see the module's documentation); empty without channels.
    pub fn to_text(&self) -> String {
        let mut out = String::with_capacity(64);
        for (i, c) in self.vectors.iter().chain(&self.actions).enumerate() {
            if i > 0 {
                out.push(';');
            }
            c.write_text(&mut out);
        }
        out
    }

    /// Reads a canonical text; `None` if it is not one (an unknown entry, a bad name or
    /// number, a vector after an action, more than [`MAX_VECTORS`] vectors or
    /// [`MAX_ACTIONS`] actions, longer than [`MAX_TEXT`]).
    pub fn parse(text: &str) -> Option<Self> {
        let mut layout = Self::default();
        if text.is_empty() {
            return Some(layout);
        }
        if text.len() > MAX_TEXT {
            return None;
        }
        for entry in text.split(';') {
            match Channel::parse(entry)? {
                v @ Channel::Vector { .. } if layout.actions.is_empty() => layout.vectors.push(v),
                Channel::Vector { .. } => return None,
                a => layout.actions.push(a),
            }
        }
        (layout.vectors.len() <= MAX_VECTORS && layout.actions.len() <= MAX_ACTIONS)
            .then_some(layout)
    }

    /// The 64-bit FNV-1a hash of the canonical text: what a network agent's hello carries.
    /// Two layouts have the same hash when their texts are equal (and, with odds of
    /// 2⁻⁶⁴, otherwise).
    pub fn hash(&self) -> u64 {
        fnv1a(self.to_text().as_bytes())
    }

    /// How the `agent`'s layout differs from this one, the host's: the first channel (in
    /// order, vectors first) that differs, or `None` when they are equal.
    pub fn difference(&self, agent: &Self) -> Option<ChannelDifference> {
        first_difference("vector", &self.vectors, &agent.vectors)
            .or_else(|| first_difference("action", &self.actions, &agent.actions))
    }
}

fn first_difference(
    table: &'static str,
    host: &[Channel],
    agent: &[Channel],
) -> Option<ChannelDifference> {
    const NONE: &str = "none of that name there";
    (0..host.len().max(agent.len())).find_map(|i| {
        let (name, host, agent) = match (host.get(i), agent.get(i)) {
            (Some(h), Some(a)) if h == a => return None,
            (Some(h), Some(a)) if h.name() == a.name() => (h.name(), h.shape(), a.shape()),
            (Some(h), _) => (h.name(), h.shape(), NONE.to_owned()),
            (None, Some(a)) => (a.name(), NONE.to_owned(), a.shape()),
            (None, None) => return None,
        };
        Some(ChannelDifference {
            table,
            name: name.to_owned(),
            host,
            agent,
        })
    })
}

/// The first channel on which a host's and an agent's configs disagree.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ChannelDifference {
    /// "vector" or "action".
    pub table: &'static str,
    /// The channel's name (as the host's config has it, or the agent's when the host has
    /// no channel at that place).
    pub name: String,
    /// What the host's config says of it ("6 floats", "none of that name there", ...).
    pub host: String,
    /// What the agent's config says of it.
    pub agent: String,
}

impl fmt::Display for ChannelDifference {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let Self {
            table,
            name,
            host,
            agent,
        } = self;
        write!(
            f,
            "host and agent configs disagree on {table} {name:?}: the host's says {host}, \
             this agent's says {agent} (both must list the same [[agent.{table}]] entries in \
             the same order)"
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn channel() -> impl Strategy<Value = Channel> {
        let name = "[A-Za-z0-9_.-]{1,16}";
        prop_oneof![
            (name, any::<u32>()).prop_map(|(name, len)| Channel::Vector { name, len }),
            (name, any::<u32>(), any::<u64>()).prop_map(|(name, len, bounds_hash)| {
                Channel::Continuous {
                    name,
                    len,
                    bounds_hash,
                }
            }),
            (name, any::<u32>()).prop_map(|(name, n)| Channel::Discrete { name, n }),
        ]
    }

    fn layout() -> impl Strategy<Value = ChannelLayout> {
        (
            proptest::collection::vec(channel(), 0..=MAX_VECTORS),
            proptest::collection::vec(channel(), 0..=MAX_ACTIONS),
        )
            .prop_map(|(v, a)| ChannelLayout {
                vectors: v
                    .into_iter()
                    .map(|c| Channel::Vector {
                        name: c.name().to_owned(),
                        len: 3,
                    })
                    .collect(),
                actions: a
                    .into_iter()
                    .filter(|c| !matches!(c, Channel::Vector { .. }))
                    .collect(),
            })
    }

    proptest! {
        #[test]
        fn layouts_round_trip_through_their_text(l in layout()) {
            let text = l.to_text();
            prop_assert!(text.len() <= MAX_TEXT);
            prop_assert_eq!(ChannelLayout::parse(&text), Some(l.clone()));
            prop_assert_eq!(l.difference(&l), None);
        }

        #[test]
        fn parsing_never_panics(text in ".{0,300}") {
            if let Some(l) = ChannelLayout::parse(&text) {
                prop_assert_eq!(ChannelLayout::parse(&l.to_text()), Some(l));
            }
        }
    }

    #[test]
    fn the_difference_names_the_first_channel_that_differs() {
        let host = ChannelLayout::parse("v:joints:6;v:pose:3;a:torque:6:00000000000000ff").unwrap();
        let longer =
            ChannelLayout::parse("v:joints:7;v:pose:3;a:torque:6:00000000000000ff").unwrap();
        let d = host.difference(&longer).unwrap();
        assert_eq!((d.table, d.name.as_str()), ("vector", "joints"));
        assert!(
            d.to_string().contains(
                "vector \"joints\": the host's says 6 floats, this \
                 agent's says 7 floats"
            ),
            "{d}"
        );
        assert_ne!(host.hash(), longer.hash());
        let choice = ChannelLayout::parse("v:joints:6;v:pose:3;d:torque:4").unwrap();
        let d = host.difference(&choice).unwrap();
        assert_eq!((d.table, d.agent.as_str()), ("action", "a choice in 0..4"));
        let fewer = ChannelLayout::parse("v:joints:6").unwrap();
        let d = host.difference(&fewer).unwrap();
        assert_eq!(
            (d.name.as_str(), d.agent.as_str()),
            ("pose", "none of that name there")
        );
        assert_eq!(ChannelLayout::default().to_text(), "");
        assert_eq!(ChannelLayout::parse(""), Some(ChannelLayout::default()));
        for bad in [
            "v:joints",
            "x:joints:1",
            "v:jo ints:1",
            "a:t:1:ff",
            "d:gear:3;v:late:1",
            "v:a:1;",
        ] {
            assert_eq!(ChannelLayout::parse(bad), None, "{bad}");
        }
    }
}
