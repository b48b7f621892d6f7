//! The original protocol's bytes: framing (a signed little-endian `i32` length, then one
//! `MsgObject`), the sub-messages as `prost` structs written from the field tables of the
//! specification, and the mapping of what an agent sends onto vrsync's command catalogue.
//!
//! A `MsgObject` is a container of optional sub-messages of which exactly one is set per
//! frame. The host never builds a whole `MsgObject`: it writes the one field's key and the
//! sub-message (the same bytes), and reads a frame by checking that it holds exactly one
//! known top-level field before decoding that field's sub-message. So the two dialects,
//! which differ only in the numbers of fields 25 and up, share every type here.

use core::fmt;
use std::io::{self, ErrorKind, Read};

use glam::Vec3;
use prost::Message;
use prost::encoding::{WireType, decode_varint, encode_key, encode_varint, encoded_len_varint};

use vrsync_protocol::wire::Command;

/// Longest frame an agent may send, bytes. What agents send is small (a command is a few
/// bytes; `AnnarNetwork` display data can be larger): a longer frame is skipped unread,
/// never buffered.
pub const MAX_INCOMING_FRAME: usize = 256 * 1024;

/// The version string both sides exchange.
pub const VERSION: &str = "1.0";

/// Which generation of the protocol a connection speaks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Dialect {
    /// The older (Python 2) clients.
    Vrnew,
    /// The later (Python 3) client: fields from 25 renumbered, a third image.
    Burkhardt,
}

impl Dialect {
    /// `MsgObject` field of `VersionCheck`.
    pub const fn version_check_field(self) -> u32 {
        match self {
            Self::Vrnew => 28,
            Self::Burkhardt => 29,
        }
    }

    /// `MsgObject` field of `HeadMotion`.
    pub const fn head_motion_field(self) -> u32 {
        match self {
            Self::Vrnew => 25,
            Self::Burkhardt => 26,
        }
    }

    /// Highest `MsgObject` field number of this dialect.
    pub const fn max_field(self) -> u32 {
        match self {
            Self::Vrnew => 28,
            Self::Burkhardt => 31,
        }
    }

    /// Lowercase name.
    pub const fn as_str(self) -> &'static str {
        match self {
            Self::Vrnew => "vrnew",
            Self::Burkhardt => "burkhardt",
        }
    }
}

/// `MsgObject` field numbers the two dialects share.
pub mod field {
    /// AgentMovement (A→H).
    pub const AGENT_MOVEMENT: u32 = 1;
    /// AgentEyemovement (A→H).
    pub const AGENT_EYEMOVEMENT: u32 = 2;
    /// AgentEyeFixation (A→H).
    pub const AGENT_EYE_FIXATION: u32 = 3;
    /// Reward (H→A).
    pub const REWARD: u32 = 4;
    /// GridPosition (H→A).
    pub const GRID_POSITION: u32 = 5;
    /// ActionExecutationStatus (H→A).
    pub const ACTION_STATUS: u32 = 6;
    /// Collision (H→A).
    pub const COLLISION: u32 = 7;
    /// Images (H→A).
    pub const IMAGES: u32 = 8;
    /// Menu (H→A; not sent by this host).
    pub const MENU: u32 = 9;
    /// Debug (both): a plain string.
    pub const DEBUG: u32 = 10;
    /// EnvironmentReset (A→H, environment socket).
    pub const ENVIRONMENT_RESET: u32 = 11;
    /// TrialReset (A→H, environment socket).
    pub const TRIAL_RESET: u32 = 12;
    /// GraspPos.
    pub const GRASP_POS: u32 = 13;
    /// GraspID.
    pub const GRASP_ID: u32 = 14;
    /// PointPos.
    pub const POINT_POS: u32 = 15;
    /// PointID.
    pub const POINT_ID: u32 = 16;
    /// InteractionID.
    pub const INTERACTION_ID: u32 = 17;
    /// InteractionPos.
    pub const INTERACTION_POS: u32 = 18;
    /// AnnarNetwork (display data, ignored).
    pub const ANNAR_NETWORK: u32 = 19;
    /// StartSync (H→A).
    pub const START_SYNC: u32 = 20;
    /// StopSync (A→H).
    pub const STOP_SYNC: u32 = 21;
    /// AgentGraspRelease.
    pub const GRASP_RELEASE: u32 = 22;
    /// AgentTurn.
    pub const AGENT_TURN: u32 = 23;
    /// EyePosition (H→A).
    pub const EYE_POSITION: u32 = 24;
}

macro_rules! proto {
    ($(#[$m:meta])* $name:ident { $($(#[$fm:meta])* $f:ident : $ty:ident = $tag:literal),* $(,)? }) => {
        $(#[$m])*
        #[derive(Clone, PartialEq, prost::Message)]
        pub struct $name {
            $(
                $(#[$fm])*
                #[prost($ty, optional, tag = $tag)]
                pub $f: Option<proto!(@rust $ty)>,
            )*
        }
    };
    (@rust int32) => { i32 };
    (@rust float) => { f32 };
    (@rust bool) => { bool };
    (@rust string) => { String };
    (@rust bytes) => { Vec<u8> };
}

proto!(
    /// AgentMovement (1): walk `distance` along world heading `degree`.
    AgentMovement { /** Action id. */ action_id: int32 = "1", /** Heading, degrees. */ degree: float = "2", /** Distance. */ distance: float = "3" }
);
proto!(
    /// AgentEyemovement (2).
    AgentEyemovement { /** Action id. */ action_id: int32 = "1", /** Pan left, degrees. */ pan_left: float = "2", /** Pan right, degrees. */ pan_right: float = "3", /** Tilt, degrees. */ tilt: float = "4" }
);
proto!(
    /// A target point: AgentEyeFixation (3).
    Target3 { /** Action id. */ action_id: int32 = "1", /** X. */ x: float = "2", /** Y. */ y: float = "3", /** Z. */ z: float = "4" }
);
proto!(
    /// Reward (4).
    Reward { /** Reward. */ reward: float = "1" }
);
proto!(
    /// GridPosition (5): position (Y up) and Euler rotation in degrees (heading = Y).
    GridPosition {
        /** X. */ x: float = "1", /** Y. */ y: float = "2", /** Z. */ z: float = "3",
        /** Rotation X, degrees. */ rotation_x: float = "4", /** Rotation Y, degrees. */ rotation_y: float = "5", /** Rotation Z, degrees. */ rotation_z: float = "6"
    }
);
proto!(
    /// ActionExecutationStatus (6).
    ActionStatus { /** Action id. */ action_id: int32 = "1", /** 0 InExecution … 5 WalkingRotating. */ status: int32 = "2" }
);
proto!(
    /// Collision (7).
    Collision { /** Action id. */ action_id: int32 = "1", /** Collider id. */ collider_id: int32 = "2" }
);
proto!(
    /// Images (8): PNG bytes; `main` in the burkhardt dialect only.
    Images { /** Left image. */ left: bytes = "1", /** Right image. */ right: bytes = "2", /** Main image (burkhardt). */ main: bytes = "3" }
);
proto!(
    /// EnvironmentReset (11) and TrialReset (12).
    Reset { /** Reset type. */ reset_type: int32 = "1" }
);
proto!(
    /// GraspPos / PointPos / InteractionPos (13 / 15 / 18): a left-image position.
    TargetPos { /** Action id. */ action_id: int32 = "1", /** Column. */ x: float = "2", /** Row. */ y: float = "3" }
);
proto!(
    /// GraspID / PointID / InteractionID (14 / 16 / 17).
    TargetId { /** Action id. */ action_id: int32 = "1", /** Object id. */ object_id: int32 = "2" }
);
proto!(
    /// An empty message: StartSync (20), StopSync (21).
    Empty {}
);
proto!(
    /// A message with only an action id: AgentGraspRelease (22), AgentCancelMovement.
    ActionOnly { /** Action id. */ action_id: int32 = "1" }
);
proto!(
    /// AgentTurn (23): turn `degree` clockwise, relative.
    AgentTurn { /** Action id. */ action_id: int32 = "1", /** Degrees. */ degree: float = "2" }
);
proto!(
    /// EyePosition (24).
    EyePosition {
        /** Rotation X. */ x: float = "1", /** Rotation Y. */ y: float = "2", /** Rotation Z. */ z: float = "3",
        /** Velocity X. */ vx: float = "4", /** Velocity Y. */ vy: float = "5", /** Velocity Z. */ vz: float = "6"
    }
);
proto!(
    /// HeadMotion (vrnew 25, burkhardt 26).
    HeadMotion {
        /** Velocity X. */ vx: float = "1", /** Velocity Y. */ vy: float = "2", /** Velocity Z. */ vz: float = "3",
        /** Acceleration X. */ ax: float = "4", /** Acceleration Y. */ ay: float = "5", /** Acceleration Z. */ az: float = "6",
        /** Rotation velocity X. */ rvx: float = "7", /** Rotation velocity Y. */ rvy: float = "8", /** Rotation velocity Z. */ rvz: float = "9",
        /** Rotation acceleration X. */ rax: float = "10", /** Rotation acceleration Y. */ ray: float = "11", /** Rotation acceleration Z. */ raz: float = "12"
    }
);
proto!(
    /// AgentMoveTo (vrnew 26, burkhardt 27).
    AgentMoveTo { /** Action id. */ action_id: int32 = "1", /** X. */ x: float = "2", /** Y. */ y: float = "3", /** Z. */ z: float = "4", /** Target mode (ignored). */ target_mode: int32 = "5" }
);
proto!(
    /// VersionCheck (vrnew 28, burkhardt 29).
    VersionCheck { /** Version string, "1.0". */ version: string = "1" }
);

/// One frame an agent sent, decoded.
#[derive(Debug, Clone, PartialEq)]
pub enum Incoming {
    /// A zero-length frame (what the unmodified clients send) or a StopSync.
    Stop,
    /// A VersionCheck with this version string.
    VersionCheck(String),
    /// A command of the catalogue with the client's action id.
    Command {
        /// The client's action id.
        action_id: u32,
        /// The command.
        command: Command,
    },
    /// An EnvironmentReset or TrialReset (no action id, no status).
    Reset(Command),
    /// A known message a host has no use for (Debug, AnnarNetwork, host→agent messages).
    Ignored(&'static str),
}

/// Why a frame was refused. Nothing of a refused frame is applied.
#[derive(Debug, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub enum FrameDecodeError {
    /// A top-level field this dialect does not have.
    UnknownField {
        /// The field number.
        field: u32,
    },
    /// More than one message in one frame (the protocol sets exactly one).
    SeveralMessages {
        /// The first field.
        first: u32,
        /// The next one.
        second: u32,
    },
    /// Not a protobuf `MsgObject`.
    Malformed(String),
}

impl fmt::Display for FrameDecodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::UnknownField { field } => write!(f, "unknown MsgObject field {field}"),
            Self::SeveralMessages { first, second } => write!(
                f,
                "several messages in one frame (fields {first} and {second}), the protocol sends one"
            ),
            Self::Malformed(why) => write!(f, "not a MsgObject: {why}"),
        }
    }
}

impl std::error::Error for FrameDecodeError {}

/// The one top-level field of a `MsgObject` body: `(field, payload)`; the payload of a
/// length-delimited field without its length. Refuses unknown fields, several fields,
/// and fields that are not length-delimited (every `MsgObject` field is a message or a
/// string).
///
/// # Errors
/// [`FrameDecodeError`].
pub fn single_field(body: &[u8], dialect: Dialect) -> Result<(u32, &[u8]), FrameDecodeError> {
    let mut buf = body;
    let mut found: Option<(u32, &[u8])> = None;
    while !buf.is_empty() {
        let key =
            decode_varint(&mut buf).map_err(|e| FrameDecodeError::Malformed(e.to_string()))?;
        let field = u32::try_from(key >> 3).unwrap_or(u32::MAX);
        let wire = key & 7;
        if field == 0 {
            return Err(FrameDecodeError::Malformed("field number 0".into()));
        }
        if field > dialect.max_field() {
            return Err(FrameDecodeError::UnknownField { field });
        }
        if wire != WireType::LengthDelimited as u64 {
            return Err(FrameDecodeError::Malformed(format!(
                "field {field} has wire type {wire}, every MsgObject field is a message"
            )));
        }
        let len =
            decode_varint(&mut buf).map_err(|e| FrameDecodeError::Malformed(e.to_string()))?;
        let len = usize::try_from(len).unwrap_or(usize::MAX);
        if len > buf.len() {
            return Err(FrameDecodeError::Malformed(format!(
                "field {field} announces {len} bytes, {} left",
                buf.len()
            )));
        }
        let (payload, rest) = buf.split_at(len);
        buf = rest;
        if let Some((first, _)) = found {
            return Err(FrameDecodeError::SeveralMessages {
                first,
                second: field,
            });
        }
        found = Some((field, payload));
    }
    found.ok_or_else(|| FrameDecodeError::Malformed("no field".into()))
}

/// The dialect whose VersionCheck `body` is, if it is one: a version check is the only
/// message whose field number tells the dialects apart (28 vrnew, 29 burkhardt).
pub fn version_check_dialect(body: &[u8]) -> Option<(Dialect, String)> {
    let (field, payload) = single_field(body, Dialect::Burkhardt).ok()?;
    let dialect = match field {
        28 => Dialect::Vrnew,
        29 => Dialect::Burkhardt,
        _ => return None,
    };
    let v = VersionCheck::decode(payload).ok()?;
    Some((dialect, v.version.unwrap_or_default()))
}

fn sub<M: Message + Default>(payload: &[u8]) -> Result<M, FrameDecodeError> {
    M::decode(payload).map_err(|e| FrameDecodeError::Malformed(e.to_string()))
}

fn id(action_id: Option<i32>) -> u32 {
    // Echoed back as int32: the cast round-trips every value.
    action_id.unwrap_or(0) as u32
}

fn f(v: Option<f32>) -> f32 {
    v.unwrap_or(0.0)
}

/// Decodes one frame body in `dialect`. An empty body is the stop.
///
/// # Errors
/// [`FrameDecodeError`]: nothing of the frame may be applied.
pub fn decode_frame(body: &[u8], dialect: Dialect) -> Result<Incoming, FrameDecodeError> {
    if body.is_empty() {
        return Ok(Incoming::Stop);
    }
    let (fnum, p) = single_field(body, dialect)?;
    let cmd = |action_id, command| Incoming::Command { action_id, command };
    Ok(match (fnum, dialect) {
        (field::AGENT_MOVEMENT, _) => {
            let m: AgentMovement = sub(p)?;
            cmd(
                id(m.action_id),
                Command::Move {
                    heading_deg: f(m.degree),
                    distance: f(m.distance),
                },
            )
        }
        (field::AGENT_EYEMOVEMENT, _) => {
            let m: AgentEyemovement = sub(p)?;
            cmd(
                id(m.action_id),
                Command::EyeMovement {
                    pan_left_deg: f(m.pan_left),
                    pan_right_deg: f(m.pan_right),
                    tilt_deg: f(m.tilt),
                },
            )
        }
        (field::AGENT_EYE_FIXATION, _) => {
            let m: Target3 = sub(p)?;
            cmd(
                id(m.action_id),
                Command::EyeFixation {
                    target: Vec3::new(f(m.x), f(m.y), f(m.z)),
                },
            )
        }
        (field::ENVIRONMENT_RESET, _) => {
            let m: Reset = sub(p)?;
            Incoming::Reset(Command::EnvironmentReset {
                reset_type: m.reset_type.unwrap_or(0) as u32,
            })
        }
        (field::TRIAL_RESET, _) => {
            let m: Reset = sub(p)?;
            Incoming::Reset(Command::TrialReset {
                reset_type: m.reset_type.unwrap_or(0) as u32,
            })
        }
        (field::GRASP_POS | field::POINT_POS | field::INTERACTION_POS, _) => {
            let m: TargetPos = sub(p)?;
            let (x_px, y_px) = (f(m.x), f(m.y));
            let c = match fnum {
                field::GRASP_POS => Command::GraspPos { x_px, y_px },
                field::POINT_POS => Command::PointPos { x_px, y_px },
                _ => Command::InteractPos { x_px, y_px },
            };
            cmd(id(m.action_id), c)
        }
        (field::GRASP_ID | field::POINT_ID | field::INTERACTION_ID, _) => {
            let m: TargetId = sub(p)?;
            let object_id = m.object_id.unwrap_or(0) as u32;
            let c = match fnum {
                field::GRASP_ID => Command::GraspId { object_id },
                field::POINT_ID => Command::PointId { object_id },
                _ => Command::InteractId { object_id },
            };
            cmd(id(m.action_id), c)
        }
        (field::STOP_SYNC, _) => {
            let _: Empty = sub(p)?;
            Incoming::Stop
        }
        (field::GRASP_RELEASE, _) => {
            let m: ActionOnly = sub(p)?;
            cmd(id(m.action_id), Command::GraspRelease)
        }
        (field::AGENT_TURN, _) => {
            let m: AgentTurn = sub(p)?;
            cmd(
                id(m.action_id),
                Command::Turn {
                    angle_deg: f(m.degree),
                },
            )
        }
        (26, Dialect::Vrnew) | (27, Dialect::Burkhardt) => {
            let m: AgentMoveTo = sub(p)?;
            cmd(
                id(m.action_id),
                Command::MoveTo {
                    target: Vec3::new(f(m.x), f(m.y), f(m.z)),
                },
            )
        }
        (27, Dialect::Vrnew) | (28, Dialect::Burkhardt) => {
            let m: ActionOnly = sub(p)?;
            cmd(id(m.action_id), Command::CancelMove)
        }
        (28, Dialect::Vrnew) | (29, Dialect::Burkhardt) => {
            let m: VersionCheck = sub(p)?;
            Incoming::VersionCheck(m.version.unwrap_or_default())
        }
        (field::DEBUG, _) => Incoming::Ignored("Debug"),
        (field::ANNAR_NETWORK, _) => Incoming::Ignored("AnnarNetwork"),
        (25, Dialect::Vrnew) | (26, Dialect::Burkhardt) => Incoming::Ignored("HeadMotion"),
        (25, Dialect::Burkhardt) => Incoming::Ignored("ObjectPosition"),
        (30, Dialect::Burkhardt) => Incoming::Ignored("SaccFlag"),
        (31, Dialect::Burkhardt) => Incoming::Ignored("VideoSync"),
        // 4–9, 20, 24: host→agent messages sent back to the host.
        _ => Incoming::Ignored("a host-to-agent message"),
    })
}

/// Appends one frame holding `MsgObject{field: msg}` to `out`.
pub fn push_message(out: &mut Vec<u8>, field: u32, msg: &impl Message) {
    let inner = msg.encoded_len();
    push_field(out, field, inner, |out| {
        // Encoding into a Vec cannot fail (it grows).
        let _ = msg.encode(out);
    });
}

/// Appends one frame holding `MsgObject{Debug: text}` to `out`.
pub fn push_debug(out: &mut Vec<u8>, text: &str) {
    push_field(out, field::DEBUG, text.len(), |out| {
        out.extend_from_slice(text.as_bytes())
    });
}

/// Appends one frame holding `MsgObject{Images{1: left, 2: right, 3: main}}` (`main` only
/// when given) to `out`, without building the message: the PNG bytes are copied once.
pub fn push_images(out: &mut Vec<u8>, left: &[u8], right: &[u8], main: Option<&[u8]>) {
    let part = |n: usize| 1 + encoded_len_varint(n as u64) + n;
    let inner = part(left.len()) + part(right.len()) + main.map_or(0, |m| part(m.len()));
    push_field(out, field::IMAGES, inner, |out| {
        for (tag, bytes) in [(1, Some(left)), (2, Some(right)), (3, main)] {
            if let Some(b) = bytes {
                encode_key(tag, WireType::LengthDelimited, out);
                encode_varint(b.len() as u64, out);
                out.extend_from_slice(b);
            }
        }
    });
}

fn push_field(out: &mut Vec<u8>, field: u32, inner: usize, body: impl FnOnce(&mut Vec<u8>)) {
    let key_len = encoded_len_varint(u64::from(field << 3));
    let total = key_len + encoded_len_varint(inner as u64) + inner;
    out.reserve(4 + total);
    // Frames this host writes are far below i32::MAX (images are bounded by the config).
    out.extend_from_slice(&(total as i32).to_le_bytes());
    let start = out.len();
    encode_key(field, WireType::LengthDelimited, out);
    encode_varint(inner as u64, out);
    body(out);
    debug_assert_eq!(out.len() - start, total);
}

/// What [`FrameReader::read_from`] found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameProgress {
    /// A whole frame is in [`FrameReader::body`] (empty for a zero-length frame).
    Frame,
    /// A frame longer than the reader's maximum was skipped unread; its length.
    Skipped(usize),
    /// Nothing more to read now.
    Pending,
    /// The peer closed the connection.
    Closed,
}

/// Why [`FrameReader::read_from`] failed: the stream cannot be read on.
#[derive(Debug)]
#[non_exhaustive]
pub enum FrameReadError {
    /// A negative length prefix: the stream has no frame boundary to resume at.
    NegativeLength(i32),
    /// The socket failed.
    Io(io::Error),
}

impl fmt::Display for FrameReadError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::NegativeLength(n) => write!(f, "negative frame length {n}"),
            Self::Io(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for FrameReadError {}

/// Reads length-prefixed frames from a non-blocking stream, one at a time, with a bounded
/// buffer: a frame longer than `max` is skipped (read and discarded in pieces), a negative
/// length is an error.
#[derive(Debug)]
pub struct FrameReader {
    max: usize,
    prefix: [u8; 4],
    prefix_len: usize,
    /// Length of the frame being read; `None` while reading the prefix.
    body_len: Option<usize>,
    body: Vec<u8>,
    /// Bytes of an oversize frame still to skip.
    skip: usize,
    skipped: usize,
    /// The last complete frame was handed out: the next call starts a new one.
    done: bool,
}

impl FrameReader {
    /// A reader for frames of at most `max` bytes.
    pub fn new(max: usize) -> Self {
        Self {
            max,
            prefix: [0; 4],
            prefix_len: 0,
            body_len: None,
            body: Vec::new(),
            skip: 0,
            skipped: 0,
            done: false,
        }
    }

    /// The frame of the last [`FrameProgress::Frame`].
    pub fn body(&self) -> &[u8] {
        &self.body
    }

    /// Whether part of a frame has been read and the rest has not.
    pub fn mid_frame(&self) -> bool {
        !self.done && (self.prefix_len > 0 || self.body_len.is_some() || self.skip > 0)
    }

    /// The announced length of a frame longer than the maximum while it is being skipped.
    pub fn oversize(&self) -> Option<usize> {
        (self.skip > 0).then_some(self.skipped)
    }

    /// Bytes of the current frame read so far and its length, if known (for messages).
    pub fn progress(&self) -> String {
        match self.body_len {
            Some(n) => format!("{} of {n} bytes", self.body.len()),
            None if self.skip > 0 => format!("an oversize frame, {} bytes left", self.skip),
            None => format!("{} of 4 length bytes", self.prefix_len),
        }
    }

    /// Reads until a frame is complete, nothing more is available, or the peer closed.
    ///
    /// # Errors
    /// [`FrameReadError`]: drop the connection.
    pub fn read_from(&mut self, src: &mut impl Read) -> Result<FrameProgress, FrameReadError> {
        if self.done {
            self.done = false;
            self.body.clear();
            self.body_len = None;
            self.prefix_len = 0;
        }
        loop {
            if self.skip > 0 {
                let mut scratch = [0u8; 4096];
                let want = self.skip.min(scratch.len());
                match src.read(&mut scratch[..want]) {
                    Ok(0) => return Ok(FrameProgress::Closed),
                    Ok(n) => {
                        self.skip -= n;
                        if self.skip == 0 {
                            self.done = true;
                            return Ok(FrameProgress::Skipped(self.skipped));
                        }
                    }
                    Err(e) => return Self::io(e),
                }
                continue;
            }
            match self.body_len {
                None => match src.read(&mut self.prefix[self.prefix_len..]) {
                    Ok(0) => return Ok(FrameProgress::Closed),
                    Ok(n) => {
                        self.prefix_len += n;
                        if self.prefix_len < 4 {
                            continue;
                        }
                        let len = i32::from_le_bytes(self.prefix);
                        if len < 0 {
                            return Err(FrameReadError::NegativeLength(len));
                        }
                        let len = len as usize;
                        if len > self.max {
                            self.prefix_len = 0;
                            self.skip = len;
                            self.skipped = len;
                            continue;
                        }
                        if len == 0 {
                            self.done = true;
                            return Ok(FrameProgress::Frame);
                        }
                        self.body_len = Some(len);
                        self.body.clear();
                        self.body.reserve(len);
                    }
                    Err(e) => return Self::io(e),
                },
                Some(len) => {
                    let have = self.body.len();
                    let mut chunk = [0u8; 4096];
                    let want = (len - have).min(chunk.len());
                    match src.read(&mut chunk[..want]) {
                        Ok(0) => return Ok(FrameProgress::Closed),
                        Ok(n) => {
                            self.body.extend_from_slice(&chunk[..n]);
                            if self.body.len() == len {
                                self.done = true;
                                return Ok(FrameProgress::Frame);
                            }
                        }
                        Err(e) => return Self::io(e),
                    }
                }
            }
        }
    }

    fn io(e: io::Error) -> Result<FrameProgress, FrameReadError> {
        match e.kind() {
            ErrorKind::WouldBlock => Ok(FrameProgress::Pending),
            ErrorKind::Interrupted => Ok(FrameProgress::Pending),
            _ => Err(FrameReadError::Io(e)),
        }
    }
}

#[cfg(test)]
mod tests;
