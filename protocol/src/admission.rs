//! Admission of a network agent's hello, and the typed refusal (the REJECT record) a
//! host sends when it refuses one: one decision for every network host, its reasons as
//! fields (re-exported by `record`, whose codec carries them).

use crate::channel_layout::ChannelLayout;
use crate::record::{Hello, constant_time_eq, le_u32, le_u64, reject};
use crate::wire::{LAYOUT_HASH, PROTOCOL_VERSION};

/// A host's refusal of a hello, as a REJECT record carries it: a code (`reject::*`), the
/// protocol and layout the host speaks, the ids it serves (with
/// [`reject::UNKNOWN_AGENT`]), the host's channel layout for the agent (with
/// [`reject::CHANNELS`]) and a message for people.
///
/// Body: code, host protocol, host layout (16 bytes, little endian), the message (UTF-8),
/// then, when ids are given, a zero byte and one `u32` per id; with
/// [`reject::CHANNELS`], a zero byte and the layout's canonical text instead. Ids and
/// layout travel as fields, never inside the message.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Reject {
    /// One of [`reject`]'s codes.
    pub code: u32,
    /// The host's [`PROTOCOL_VERSION`].
    pub host_protocol: u32,
    /// The host's [`LAYOUT_HASH`].
    pub host_layout: u64,
    /// The agent ids the host serves (filled with [`reject::UNKNOWN_AGENT`]).
    pub served: Vec<u32>,
    /// What the host's config declares of the agent's channels (with
    /// [`reject::CHANNELS`]; `None` otherwise, or if the host sent no readable layout).
    pub host_channels: Option<ChannelLayout>,
    /// What is wrong, for people.
    pub message: String,
}

impl Reject {
    /// A refusal with `code` and `message`, from this host's protocol and layout.
    pub fn new(code: u32, message: impl Into<String>) -> Self {
        Self {
            code,
            host_protocol: PROTOCOL_VERSION,
            host_layout: LAYOUT_HASH,
            served: Vec::new(),
            host_channels: None,
            message: message.into(),
        }
    }

    /// "agent N is already connected".
    pub fn id_in_use(agent: u32) -> Self {
        Self::new(
            reject::ID_IN_USE,
            format!("agent {agent} is already connected"),
        )
    }

    /// "agent N's channels differ from the host's config", carrying `host`'s layout.
    pub fn channels(agent: u32, host: &ChannelLayout) -> Self {
        let text = host.to_text();
        Self {
            host_channels: Some(host.clone()),
            ..Self::new(
                reject::CHANNELS,
                format!(
                    "agent {agent}'s channels differ from the host's config, which declares \
                     {}",
                    if text.is_empty() { "none" } else { &text }
                ),
            )
        }
    }

    /// The record body.
    pub fn encode(&self) -> Vec<u8> {
        let mut b = Vec::with_capacity(17 + self.message.len() + 4 * self.served.len());
        b.extend_from_slice(&self.code.to_le_bytes());
        b.extend_from_slice(&self.host_protocol.to_le_bytes());
        b.extend_from_slice(&self.host_layout.to_le_bytes());
        // A message never holds a zero byte (it would end the message early).
        b.extend(self.message.bytes().filter(|&c| c != 0));
        if self.code == reject::CHANNELS {
            if let Some(layout) = &self.host_channels {
                b.push(0);
                b.extend_from_slice(layout.to_text().as_bytes());
            }
        } else if !self.served.is_empty() {
            b.push(0);
            for id in &self.served {
                b.extend_from_slice(&id.to_le_bytes());
            }
        }
        b
    }

    /// Decodes a record body; `None` if it is shorter than its fixed part or its id list is
    /// cut.
    pub fn decode(body: &[u8]) -> Option<Self> {
        let rest = body.get(16..)?;
        let (message, tail) = match rest.iter().position(|&c| c == 0) {
            Some(at) => (&rest[..at], Some(&rest[at + 1..])),
            None => (rest, None),
        };
        let code = le_u32(body, 0)?;
        let (ids, host_channels) = match tail {
            Some(text) if code == reject::CHANNELS => (
                &[][..],
                core::str::from_utf8(text)
                    .ok()
                    .and_then(ChannelLayout::parse),
            ),
            Some(ids) => (ids, None),
            None => (&[][..], None),
        };
        if ids.len() % 4 != 0 {
            return None;
        }
        Some(Self {
            code,
            host_protocol: le_u32(body, 4)?,
            host_layout: le_u64(body, 8)?,
            served: ids
                .chunks_exact(4)
                .filter_map(|c| <[u8; 4]>::try_from(c).ok().map(u32::from_le_bytes))
                .collect(),
            host_channels,
            message: String::from_utf8_lossy(message).into_owned(),
        })
    }
}

/// Admission of a hello, as every network host decides it: the protocol and layout, then
/// the access token (refused with `token_message`, which names the host's config key),
/// then whether the id is one the host serves (`served`, in slot order), then whether the
/// agent's channels are the ones the host declares for that slot (`layouts`, in slot
/// order; a slot without an entry has no channels). Returns the agent's slot; whether the
/// id is in use is the host's own to decide (its connections are its own).
///
/// # Errors
/// The [`Reject`] to send: [`reject::VERSION`], [`reject::TOKEN`],
/// [`reject::UNKNOWN_AGENT`] (with `served`) or [`reject::CHANNELS`] (with the host's
/// layout).
pub fn admit(
    hello: &Hello,
    token: Option<&[u8]>,
    token_message: &str,
    served: &[u32],
    layouts: &[ChannelLayout],
) -> Result<usize, Reject> {
    if hello.protocol_version != PROTOCOL_VERSION || hello.layout_hash != LAYOUT_HASH {
        return Err(Reject::new(
            reject::VERSION,
            format!(
                "agent speaks protocol {} (layout {:016x}), host speaks protocol \
                 {PROTOCOL_VERSION} (layout {LAYOUT_HASH:016x})",
                hello.protocol_version, hello.layout_hash
            ),
        ));
    }
    if let Some(token) = token
        && !constant_time_eq(token, &hello.token)
    {
        return Err(Reject::new(reject::TOKEN, token_message));
    }
    let slot = served
        .iter()
        .position(|&id| id == hello.agent_id)
        .ok_or_else(|| Reject {
            served: served.to_vec(),
            ..Reject::new(
                reject::UNKNOWN_AGENT,
                format!(
                    "agent {} is not part of this session (it serves agents {served:?})",
                    hello.agent_id
                ),
            )
        })?;
    let none = ChannelLayout::default();
    let layout = layouts.get(slot).unwrap_or(&none);
    if hello.channels != layout.hash() {
        return Err(Reject::channels(hello.agent_id, layout));
    }
    Ok(slot)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_reject_carries_the_served_ids_as_fields() {
        let hello = |id, version| Hello {
            protocol_version: version,
            layout_hash: LAYOUT_HASH,
            agent_id: id,
            channels: ChannelLayout::default().hash(),
            token: b"t".to_vec(),
        };
        let served = [0, 1, 250];
        assert_eq!(
            admit(&hello(1, PROTOCOL_VERSION), Some(b"t"), "x", &served, &[]),
            Ok(1)
        );
        let r = admit(&hello(7, PROTOCOL_VERSION), Some(b"t"), "x", &served, &[]).unwrap_err();
        assert_eq!(
            (r.code, r.served.as_slice()),
            (reject::UNKNOWN_AGENT, &served[..])
        );
        let back = Reject::decode(&r.encode()).unwrap();
        assert_eq!(back, r);
        assert!(back.message.contains("agent 7 is not part of this session"));
        let v = admit(&hello(1, PROTOCOL_VERSION + 1), None, "x", &served, &[]).unwrap_err();
        assert_eq!((v.code, v.served.len()), (reject::VERSION, 0));
        assert_eq!(Reject::decode(&v.encode()), Some(v));
        let t = admit(
            &hello(1, PROTOCOL_VERSION),
            Some(b"other"),
            "wrong key",
            &served,
            &[],
        );
        assert_eq!(t, Err(Reject::new(reject::TOKEN, "wrong key")));
        // A cut id list is not a reject; a body without ids is one with none.
        let mut cut = r.encode();
        cut.pop();
        assert_eq!(Reject::decode(&cut), None);
        assert_eq!(Reject::decode(&[0; 15]), None);
        assert_eq!(Reject::decode(&[0; 16]).map(|r| r.served), Some(Vec::new()));
    }

    #[test]
    fn a_channel_mismatch_is_refused_with_the_hosts_layout() {
        let host = ChannelLayout::parse("v:joints:6;a:torque:6:00000000000000ff").unwrap();
        let theirs = ChannelLayout::parse("v:joints:7;a:torque:6:00000000000000ff").unwrap();
        let layouts = [ChannelLayout::default(), host.clone()];
        let hello = |channels: &ChannelLayout| Hello {
            protocol_version: PROTOCOL_VERSION,
            layout_hash: LAYOUT_HASH,
            agent_id: 5,
            channels: channels.hash(),
            token: Vec::new(),
        };
        assert_eq!(admit(&hello(&host), None, "x", &[4, 5], &layouts), Ok(1));
        let r = admit(&hello(&theirs), None, "x", &[4, 5], &layouts).unwrap_err();
        assert_eq!(
            (r.code, r.host_channels.as_ref()),
            (reject::CHANNELS, Some(&host))
        );
        let back = Reject::decode(&r.encode()).unwrap();
        assert_eq!(back, r);
        let d = back.host_channels.unwrap().difference(&theirs).unwrap();
        assert_eq!((d.table, d.name.as_str()), ("vector", "joints"));
        // A slot without a layout has no channels: an agent declaring some is refused.
        let r = admit(&hello(&theirs), None, "x", &[4, 5], &[]).unwrap_err();
        assert_eq!(r.host_channels, Some(ChannelLayout::default()));
        assert_eq!(
            Reject::decode(&r.encode()).unwrap().host_channels,
            Some(ChannelLayout::default())
        );
    }
}
