//! Channels on the wire: the user-declared float vectors a sensor frame carries beside its
//! images, and the actions an agent sends back (`[[agent.vector]]`, `[[agent.action]]`).
//!
//! - **Vectors** lie in the sensor frame's payload after the images, each `f32` slice
//!   starting at a multiple of [`IMAGE_ALIGN`], described by the header's vector table
//!   ([`SensorHeader::vectors`]): in the same shared-memory sample as the images (zero
//!   copy), and in the same record on the network transports.
//! - **Actions** travel in the motor batch as chunks of at most [`ACTION_CHUNK`] values,
//!   each a [`MotorCommand`] with the tag [`ACTION_KIND`] (see [`action_chunks`]): no new
//!   record type, so every transport carries them as it carries commands, and the late-batch
//!   rules of the stops apply to them unchanged. The host assembles them (they never show
//!   up as commands).
//! - The header's action table ([`SensorHeader::actions`]) tells the agent what the host
//!   expects. Host and agent compare their layouts at connect already
//!   ([`crate::channel_layout`]); the tables let the agent check every frame against its
//!   config too, naming the channel that differs.

use super::*;

/// Maximum number of vectors (`[[agent.vector]]`) per agent.
pub const MAX_VECTORS: usize = 8;
/// Maximum number of actions (`[[agent.action]]`) per agent.
pub const MAX_ACTIONS: usize = 8;
/// Maximum length of a channel name in bytes (UTF-8, zero padded).
pub const CHANNEL_NAME_LEN: usize = 16;
/// Longest vector, in floats.
pub const MAX_VECTOR_LEN: u32 = 4096;
/// Longest continuous action, in floats.
pub const MAX_ACTION_LEN: u32 = 256;
/// Values per action chunk (the four `args` of a [`MotorCommand`]).
pub const ACTION_CHUNK: usize = 4;
/// Tag of an action chunk in a motor batch (not a command of the catalogue): `action_id` is
/// the index of the action in the agent's `[[agent.action]]` list; for a continuous action
/// `object_id` is the index of the first value in `args` (a multiple of [`ACTION_CHUNK`])
/// and `args` holds the next values (unused ones zero); for a discrete action `object_id`
/// is the choice.
pub const ACTION_KIND: u32 = 0x100;

/// Where one vector lies in the payload of a sensor frame.
#[repr(C)]
#[derive(
    Debug,
    Clone,
    Copy,
    Default,
    PartialEq,
    ZeroCopySend,
    IntoBytes,
    FromBytes,
    Immutable,
    KnownLayout,
)]
#[type_name("vrsync::VectorDesc/v1")]
pub struct VectorDesc {
    /// Vector name, UTF-8, zero padded.
    pub name: [u8; CHANNEL_NAME_LEN],
    /// Byte offset of the first value in the payload (a multiple of [`IMAGE_ALIGN`]).
    pub offset: u64,
    /// Number of `f32` values.
    pub len: u32,
    /// Reserved, zero.
    pub reserved: u32,
}

impl VectorDesc {
    /// The name as a string (up to the first zero byte; invalid UTF-8 gives `""`).
    pub fn name(&self) -> &str {
        padded_str(&self.name)
    }

    /// Bytes of the vector.
    pub fn byte_len(&self) -> u64 {
        u64::from(self.len) * 4
    }

    fn range(&self) -> Option<core::ops::Range<usize>> {
        let start = usize::try_from(self.offset).ok()?;
        Some(start..start.checked_add(usize::try_from(self.byte_len()).ok()?)?)
    }

    /// The vector's values in a sensor frame's `payload` (`None` if they do not fit it or
    /// are not 4-byte aligned, which the layout and the transports' buffers rule out).
    pub fn values<'a>(&self, payload: &'a [u8]) -> Option<&'a [f32]> {
        <[f32]>::ref_from_bytes(payload.get(self.range()?)?).ok()
    }

    /// The vector's values in a sensor frame's `payload`, writable (as
    /// [`VectorDesc::values`]).
    pub fn values_mut<'a>(&self, payload: &'a mut [u8]) -> Option<&'a mut [f32]> {
        <[f32]>::mut_from_bytes(payload.get_mut(self.range()?)?).ok()
    }
}

/// What the host expects of one action.
#[repr(C)]
#[derive(
    Debug,
    Clone,
    Copy,
    Default,
    PartialEq,
    ZeroCopySend,
    IntoBytes,
    FromBytes,
    Immutable,
    KnownLayout,
)]
#[type_name("vrsync::ActionDesc/v1")]
pub struct ActionDesc {
    /// Action name, UTF-8, zero padded.
    pub name: [u8; CHANNEL_NAME_LEN],
    /// Continuous: number of `f32` values; discrete: 0.
    pub len: u32,
    /// Discrete: number of choices; continuous: 0.
    pub n: u32,
    /// Hash of the bounds (`low`, `high`) of a continuous action (0 for discrete).
    pub bounds_hash: u64,
}

impl ActionDesc {
    /// The name as a string (up to the first zero byte; invalid UTF-8 gives `""`).
    pub fn name(&self) -> &str {
        padded_str(&self.name)
    }
}

pub(super) fn padded_str(bytes: &[u8]) -> &str {
    let end = bytes.iter().position(|&b| b == 0).unwrap_or(bytes.len());
    core::str::from_utf8(&bytes[..end]).unwrap_or("")
}

/// `name` as a zero-padded `N`-byte field (cut at `N` bytes), as the name fields of the
/// wire tables hold it.
pub fn padded_name<const N: usize>(name: &str) -> [u8; N] {
    let mut out = [0u8; N];
    let n = name.len().min(N);
    out[..n].copy_from_slice(&name.as_bytes()[..n]);
    out
}

/// The vector table for `vectors`, given as `(name, len)` in config order (at most
/// [`MAX_VECTORS`] are used), packed after `images_end` bytes of images, and the total
/// payload size in bytes (images and vectors).
pub fn vector_layout<'a>(
    images_end: usize,
    vectors: impl IntoIterator<Item = (&'a str, u32)>,
) -> ([VectorDesc; MAX_VECTORS], usize) {
    let mut descs = [VectorDesc::default(); MAX_VECTORS];
    let mut end = images_end;
    for (d, (name, len)) in descs.iter_mut().zip(vectors) {
        let offset = end.next_multiple_of(IMAGE_ALIGN);
        *d = VectorDesc {
            name: padded_name(name),
            offset: offset as u64,
            len,
            reserved: 0,
        };
        end = offset + len as usize * 4;
    }
    (descs, end)
}

/// The hash of a continuous action's bounds, as [`ActionDesc::bounds_hash`] carries it.
pub fn bounds_hash(low: &[f32], high: &[f32]) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325_u64;
    for v in low.iter().chain(high) {
        for b in v.to_bits().to_le_bytes() {
            h ^= u64::from(b);
            h = h.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
    h
}

/// The chunks that carry the value `values` of action number `index` (continuous), in the
/// order to send them.
pub fn action_chunks(index: u32, values: &[f32]) -> impl Iterator<Item = MotorCommand> + '_ {
    values
        .chunks(ACTION_CHUNK)
        .enumerate()
        .map(move |(k, chunk)| {
            let mut args = [0.0f32; ACTION_CHUNK];
            args[..chunk.len()].copy_from_slice(chunk);
            MotorCommand {
                kind: ACTION_KIND,
                action_id: index,
                object_id: (k * ACTION_CHUNK) as u32,
                reserved: 0,
                args,
            }
        })
}

/// The chunk that carries choice `choice` of discrete action number `index`.
pub fn discrete_action_chunk(index: u32, choice: u32) -> MotorCommand {
    MotorCommand {
        kind: ACTION_KIND,
        action_id: index,
        object_id: choice,
        reserved: 0,
        args: [0.0; ACTION_CHUNK],
    }
}

impl MotorCommand {
    /// Whether this is an action chunk ([`ACTION_KIND`]), not a command of the catalogue.
    pub fn is_action_chunk(&self) -> bool {
        self.kind == ACTION_KIND
    }
}

impl SensorHeader {
    /// Valid vector descriptions.
    pub fn vector_descs(&self) -> &[VectorDesc] {
        &self.vectors[..(self.vector_count as usize).min(MAX_VECTORS)]
    }

    /// Valid action descriptions.
    pub fn action_descs(&self) -> &[ActionDesc] {
        &self.actions[..(self.action_count as usize).min(MAX_ACTIONS)]
    }
}
