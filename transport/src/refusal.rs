//! Peers a transport refused or dropped before admitting them as agents: why
//! ([`RefusalKind`]), who ([`PeerRefusal`]), and the bounded record a transport keeps of them
//! until the host takes it ([`Refusals`]).

/// Why a transport refused a peer that was not (yet) an admitted agent.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum RefusalKind {
    /// Bytes that are not this protocol: garbage, a malformed or oversized record.
    Malformed,
    /// Another protocol version or memory layout.
    Version,
    /// A wrong or missing session token.
    Token,
    /// An agent id the host does not serve.
    UnknownAgent,
    /// An agent id that is already connected.
    IdInUse,
    /// The agent's channels differ from those the host's config declares for it.
    Channels,
    /// Connected, then sent no complete hello in time (or closed without one).
    Silent,
    /// Turned away at once: too many connections are waiting for their hello.
    TooMany,
    /// Dropped in the TLS handshake (zenoh `tls/` endpoints): no certificate of the CA,
    /// or not TLS at all.
    Tls,
}

impl RefusalKind {
    /// The kind of a refusal sent with reject code `code` (`record::reject`).
    pub(crate) fn of_reject(code: u32) -> Self {
        use super::record::reject;
        match code {
            reject::VERSION => Self::Version,
            reject::TOKEN => Self::Token,
            reject::UNKNOWN_AGENT => Self::UnknownAgent,
            reject::ID_IN_USE => Self::IdInUse,
            reject::CHANNELS => Self::Channels,
            _ => Self::Malformed,
        }
    }

    /// Lowercase name for events and summaries.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Malformed => "malformed",
            Self::Version => "version",
            Self::Token => "token",
            Self::UnknownAgent => "unknown_agent",
            Self::IdInUse => "id_in_use",
            Self::Channels => "channels",
            Self::Silent => "silent",
            Self::TooMany => "too_many",
            Self::Tls => "tls",
        }
    }
}

/// A peer a transport refused or dropped before admitting it as an agent (hostile,
/// misconfigured or merely confused); the host counts them and hands them to its
/// embedder (`vrsync_bridge::Host::on_peer_refused`).
#[derive(Debug, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub struct PeerRefusal {
    /// Why, as a category.
    pub kind: RefusalKind,
    /// The agent id the peer claimed, if it got that far.
    pub agent: Option<u32>,
    /// Where the peer is (an address, or the transport's name for it).
    pub peer: String,
    /// Why, for a person.
    pub reason: String,
}

impl PeerRefusal {
    /// A refusal of `kind` of the peer at `peer` that claimed agent id `agent`, for
    /// `reason` (for transports outside this crate: the struct is `#[non_exhaustive]`).
    pub fn new(kind: RefusalKind, agent: Option<u32>, peer: String, reason: String) -> Self {
        Self {
            kind,
            agent,
            peer,
            reason,
        }
    }
}

/// Refusals a transport keeps between two [`HostConnections::take_refusals`](super::HostConnections::take_refusals) calls with
/// their details; beyond that only their number.
pub const MAX_KEPT_REFUSALS: usize = 256;

/// Refusals recorded by a transport until the host takes them (bounded: a flood of
/// strangers costs [`MAX_KEPT_REFUSALS`] entries and a counter).
#[derive(Debug, Default)]
pub struct Refusals {
    kept: Vec<PeerRefusal>,
    unkept: u64,
}

impl Refusals {
    /// Records one refusal (the caller logs it).
    pub fn push(&mut self, refusal: PeerRefusal) {
        if self.kept.len() < MAX_KEPT_REFUSALS {
            self.kept.push(refusal);
        } else {
            self.unkept += 1;
        }
    }

    /// Records `n` refusals of `kind` without details.
    pub fn count(&mut self, n: u64) {
        self.unkept += n;
    }

    /// Hands every kept refusal to `sink`; returns how many more were refused without
    /// details. Leaves the record empty.
    pub fn take(&mut self, sink: &mut dyn FnMut(&PeerRefusal)) -> u64 {
        for r in self.kept.drain(..) {
            sink(&r);
        }
        std::mem::take(&mut self.unkept)
    }
}
